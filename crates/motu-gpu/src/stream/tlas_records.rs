//! The instance records of a streamed TLAS rebuild: one per instance of a resident BLAS, in
//! the TLAS's record order, encoded in parallel straight into the staging ring.
//!
//! At a quarter of island 0.3 a rebuild writes 2–8M records (130–550 MB) several times a
//! frame. Encoding them into per-chunk vectors, joining those and copying the result into the
//! ring took 330–390 ms of a 6M-record rebuild on the H200 (most of it first touches of fresh
//! host pages and single-threaded copies); counting first and encoding each chunk in place in
//! the mapped ring writes every byte once.

use motu_abi::{HierarchyView, InstanceRecord};
use motu_vk::{Context, HeapBuffer};
use rayon::prelude::*;

use super::tlas_compact::CompactJob;
use crate::error::{GpuError, Result};
use crate::scene::{encode_instance, Uploader};
use motu_abi::tlas_compact::TLAS_COMPACT_CHUNK;

pub(super) use super::tlas_encode::{instance_record, tail_record, RECORD_BYTES};

/// The largest chunk of instances one worker encodes (also the unit of the ring windows).
const MAX_CHUNK_INSTANCES: usize = 1 << 14;

/// What a rebuild of some TLASes writes: per TLAS, the resident records of each chunk of its
/// instance range, then its tail (proxy and marks records, or one inactive record when the
/// TLAS would otherwise be empty). The resident records of a TLAS marked `gpu` are written by
/// the compaction pass from its kept records (`tlas_compact.rs`, chunks of
/// [`TLAS_COMPACT_CHUNK`]); the host writes only its tail.
pub(super) struct TlasRecords<'r> {
    view: HierarchyView<'r>,
    /// BLAS device addresses, 0 where not resident.
    addrs: &'r [u64],
    chunk_instances: usize,
    /// Per TLAS of the rebuild, in the order of the ids.
    tlases: Vec<TlasRecordCounts>,
}

/// One TLAS's records in a rebuild.
struct TlasRecordCounts {
    tlas: u32,
    /// Its resident records are compacted on the GPU (chunks of [`TLAS_COMPACT_CHUNK`]),
    /// else encoded by the host (chunks of `TlasRecords::chunk_instances`).
    gpu: bool,
    /// Resident records per chunk of its instance range.
    per_chunk: Vec<u32>,
    /// The records after its own (proxy and marks, or one inactive record).
    tail: Vec<[u8; RECORD_BYTES]>,
}

impl<'r> TlasRecords<'r> {
    /// Counts the resident records of TLASes `ids` (in parallel); `gpu[k]`: those of
    /// `ids[k]` are compacted on the GPU; `tail(t)` gives the records that follow TLAS `t`'s
    /// own. `ring_region_bytes` bounds a host chunk's bytes.
    pub(super) fn count(
        view: HierarchyView<'r>,
        addrs: &'r [u64],
        ids: &[u32],
        gpu: &[bool],
        ring_region_bytes: u64,
        mut tail: impl FnMut(u32) -> Vec<[u8; RECORD_BYTES]>,
    ) -> Self {
        let chunk_instances =
            ((ring_region_bytes / RECORD_BYTES as u64) as usize).clamp(1, MAX_CHUNK_INSTANCES);
        let tlases = ids
            .iter()
            .enumerate()
            .map(|(k, &t)| {
                let gpu = gpu.get(k).copied().unwrap_or(false);
                let chunk = if gpu {
                    TLAS_COMPACT_CHUNK as usize
                } else {
                    chunk_instances
                };
                let counts: Vec<u32> = instances_of(&view, t)
                    .par_chunks(chunk)
                    .map(|c| c.iter().filter(|i| addrs[i.blas as usize] != 0).count() as u32)
                    .collect();
                let mut tail = tail(t);
                if tail.is_empty() && counts.iter().all(|&n| n == 0) {
                    // Nothing resident: one inactive instance keeps the TLAS valid.
                    tail.push(encode_instance(&super::IDENTITY, false, false, 0, 0));
                }
                TlasRecordCounts {
                    tlas: t,
                    gpu,
                    per_chunk: counts,
                    tail,
                }
            })
            .collect();
        TlasRecords {
            view,
            addrs,
            chunk_instances,
            tlases,
        }
    }

    /// Records per TLAS, in the order of `ids`.
    pub(super) fn record_counts(&self) -> Vec<u32> {
        self.tlases
            .iter()
            .map(|r| r.per_chunk.iter().sum::<u32>() + r.tail.len() as u32)
            .collect()
    }

    /// Records the host writes (a host TLAS's all, a GPU one's tail).
    pub(super) fn host_written(&self) -> u64 {
        self.tlases
            .iter()
            .map(|r| {
                let own = if r.gpu {
                    0
                } else {
                    r.per_chunk.iter().map(|&n| u64::from(n)).sum()
                };
                own + r.tail.len() as u64
            })
            .sum()
    }

    /// Records the compaction writes (the GPU TLASes' resident ones).
    pub(super) fn compacted(&self) -> u64 {
        self.tlases
            .iter()
            .filter(|r| r.gpu)
            .flat_map(|r| &r.per_chunk)
            .map(|&n| u64::from(n))
            .sum()
    }

    /// The compaction's jobs: each GPU TLAS with resident records, placed at `offsets`
    /// (bytes, in the order of `ids`).
    pub(super) fn gpu_jobs(&self, offsets: &[u64]) -> Vec<CompactJob<'_>> {
        self.tlases
            .iter()
            .zip(offsets)
            .filter(|(r, _)| r.gpu && r.per_chunk.iter().any(|&n| n > 0))
            .map(|(r, &at)| CompactJob {
                tlas: r.tlas,
                first_record: (at / RECORD_BYTES as u64) as u32,
                per_chunk: &r.per_chunk,
            })
            .collect()
    }

    /// Encodes every host TLAS's records into `dst` at `offsets` (bytes, in the order of
    /// `ids`) through the ring, a window of whole chunks at a time, the chunks of a window in
    /// parallel, and every TLAS's tail after its own records (a GPU TLAS's own are the
    /// compaction's). Leaves the copies queued (the caller flushes).
    pub(super) fn upload(
        &self,
        ctx: &Context,
        up: &mut Uploader,
        dst: &HeapBuffer,
        offsets: &[u64],
    ) -> Result<()> {
        let window_bytes = up.region_bytes();
        for (r, &base) in self.tlases.iter().zip(offsets) {
            let (counts, tail) = (&r.per_chunk, &r.tail);
            let range = instances_of(&self.view, r.tlas);
            let mut at = base;
            let mut c = 0;
            if r.gpu {
                at += counts.iter().map(|&n| u64::from(n)).sum::<u64>() * RECORD_BYTES as u64;
                c = counts.len();
            }
            while c < counts.len() {
                // Whole chunks up to the ring's region.
                let first = c;
                let mut bytes = 0u64;
                while c < counts.len()
                    && bytes + u64::from(counts[c]) * RECORD_BYTES as u64 <= window_bytes
                {
                    bytes += u64::from(counts[c]) * RECORD_BYTES as u64;
                    c += 1;
                }
                if c == first {
                    // Not reached: a chunk's records fit the region by construction.
                    return Err(GpuError::InvalidRequest(format!(
                        "streaming: {} instance records do not fit the staging ring's {window_bytes} bytes",
                        counts[c]
                    )));
                }
                if bytes == 0 {
                    continue;
                }
                up.upload_in_place(ctx, dst, at, bytes as usize, |out| {
                    let mut parts = Vec::with_capacity(c - first);
                    let mut rest = out;
                    for (k, &n) in counts.iter().enumerate().take(c).skip(first) {
                        let (head, tail) = rest.split_at_mut(n as usize * RECORD_BYTES);
                        parts.push((k, head));
                        rest = tail;
                    }
                    parts.into_par_iter().for_each(|(k, out)| {
                        let start = k * self.chunk_instances;
                        let end = (start + self.chunk_instances).min(range.len());
                        self.encode_chunk(&range[start..end], start, out);
                    });
                })?;
                at += bytes;
            }
            for rec in tail {
                up.upload(ctx, dst, at, rec)?;
                at += RECORD_BYTES as u64;
            }
        }
        Ok(())
    }

    /// Encodes the resident instances of `chunk` (whose first instance has index `first` in
    /// its TLAS: the custom index the shaders read) into `out`, exactly filled.
    fn encode_chunk(&self, chunk: &[InstanceRecord], first: usize, out: &mut [u8]) {
        let mut records = out.chunks_exact_mut(RECORD_BYTES);
        for (j, inst) in chunk.iter().enumerate() {
            let b = inst.blas as usize;
            let addr = self.addrs[b];
            if addr == 0 {
                continue;
            }
            let enc = instance_record(&self.view, inst, (first + j) as u32, addr);
            // The count pass saw the same residency, so `out` holds exactly these records.
            if let Some(slot) = records.next() {
                slot.copy_from_slice(&enc);
            }
        }
        debug_assert!(records.next().is_none(), "fewer records than counted");
    }
}

/// TLAS `t`'s instance range.
fn instances_of<'v>(view: &HierarchyView<'v>, t: u32) -> &'v [InstanceRecord] {
    let rec = &view.tlases[t as usize];
    &view.instances[rec.instance_range()]
}

#[cfg(test)]
mod tests;
