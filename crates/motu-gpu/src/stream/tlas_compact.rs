//! Streamed TLAS records kept on the GPU ([`KeptRecords`], `--stream-tlas-records gpu`): each
//! rebuilt TLAS (each piece of a split root) keeps every instance's record in device memory,
//! encoded once through the staging ring when the TLAS is first rebuilt, with the BLAS id where
//! the address goes. A rebuild then writes its resident records with a compute pass
//! (`shaders/tlas_compact.comp`, the rule in [`motu_abi::tlas_compact`]): the host counts each
//! chunk's resident instances (as the host path does), uploads the chunks' first slots and the
//! BLAS address table, and writes only the tail (proxy and marks) records. The records are
//! the host path's, byte for byte and in the same order, so the TLAS and the image are too.
//!
//! Kept records live in room no structure wants: they yield to structures. Whenever room is
//! made for a BLAS (a build, a restore, a texture) or a TLAS rebuild, kept records are
//! released first, one TLAS at a time, least recently rebuilt first
//! ([`StreamingRenderer::release_kept_records_for_room`], counted in
//! `tlas_records_released`), before any structure is evicted or a block drained; and the
//! room the streamer sizes non-evicting work by counts them as free. So a frame's structures
//! see the room they see with `host` records, and the passes are the same.
//!
//! Invariants: a kept buffer holds TLAS `t`'s `instance_count` records in instance order and
//! is never written after its encode; the kept bytes (records, BLAS address table, chunk
//! table) count against the budget as part of the skeleton (`Tlases::size_bytes`) but not in
//! a frame's `room_bytes`; kept records are made only by
//! [`StreamingRenderer::prepare_kept_records`], in free budget beyond the rebuild's own room
//! (never evicting a structure for them), at a TLAS's second rebuild or later (a piece rebuilt
//! once never pays back its encode), and never in a frame in which records were
//! released for room (they would be made and released round after round), nor for a few
//! frames after records made again were released again (a back-off); making them never
//! fails a rebuild for want of room (the TLAS is then written from the host).

use motu_abi::tlas_compact::{chunk_firsts, TlasCompactPush, TLAS_COMPACT_CHUNK};
use motu_alloc::{AllocKind, MemoryClass};
use motu_vk::{BufferUsage, ComputePipeline, ComputePipelineDesc, GpuHeap, HeapBuffer};
use rayon::prelude::*;

use super::buffers::staging_released;
use super::tlas_encode::{kept_record, RECORD_BYTES};
use super::{StreamingRenderer, TlasRecordsMode};
use crate::error::{GpuError, Result};

/// Instances one worker encodes into the ring when kept records are made.
const ENCODE_CHUNK: usize = 1 << 12;

/// The tables every compaction reads beside the kept records.
struct CompactTables {
    /// Per BLAS: its device address, 0 where not resident (rewritten before each pass).
    blas_addresses: HeapBuffer,
    /// Per chunk of every TLAS: its first record in the instance buffer (rewritten per pass).
    chunk_firsts: HeapBuffer,
    /// Per TLAS: the index of its first chunk in `chunk_firsts`.
    chunk_base: Vec<u32>,
}

/// The kept records of the rebuilt TLASes (see the module docs).
#[derive(Default)]
pub(super) struct KeptRecords {
    /// Per TLAS: its records, once made.
    kept: Vec<Option<HeapBuffer>>,
    /// Per TLAS: the rebuild stamp of its last rebuild with kept records (the release order:
    /// least recently rebuilt first).
    used_at: Vec<u64>,
    /// Per TLAS: whether it was rebuilt before (records are made only at a second rebuild: a
    /// TLAS rebuilt once never pays back the encode).
    rebuilt_before: Vec<bool>,
    /// Counts rebuilds (the stamps of `used_at`).
    stamp: u64,
    tables: Option<CompactTables>,
    pipeline: Option<ComputePipeline>,
    /// Bytes of the kept records and the tables.
    bytes: u64,
    /// The frame in which some were last released for room, and the first frame in which
    /// records are made again: none is made in the frame of a release (a refused build retried
    /// would otherwise make and release them round after round), and records released again
    /// soon after they were made wait twice as long each time (up to 16 frames): re-encoding
    /// them every frame would write more records than the host path.
    released_in_frame: Option<u64>,
    make_from_frame: u64,
    backoff_frames: u64,
}

impl KeptRecords {
    /// Nothing kept yet for `tlases` TLASes.
    pub fn new(tlases: usize) -> KeptRecords {
        KeptRecords {
            kept: (0..tlases).map(|_| None).collect(),
            used_at: vec![0; tlases],
            rebuilt_before: vec![false; tlases],
            ..Default::default()
        }
    }

    /// Bytes kept (records and tables), counted against the budget.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Of [`Self::bytes`]: the records alone (instance buffers; the rest are tables).
    pub fn record_bytes(&self) -> u64 {
        self.kept.iter().flatten().map(|b| b.size_bytes()).sum()
    }

    /// Whether TLAS `t` has kept records.
    pub fn has(&self, t: u32) -> bool {
        self.kept.get(t as usize).is_some_and(Option::is_some)
    }

    fn has_tables(&self) -> bool {
        self.tables.is_some()
    }

    /// Releases kept records, least recently rebuilt TLAS first, until at least `bytes` are
    /// released or none is left (the tables go with the last records); `frame`: the frame
    /// that needed the room (none is made again in it). Returns the bytes released and the
    /// TLASes whose records went.
    pub fn release_for_room(&mut self, bytes: u64, frame: u64, heap: &mut GpuHeap) -> (u64, u32) {
        let mut order: Vec<usize> = (0..self.kept.len())
            .filter(|&t| self.kept[t].is_some())
            .collect();
        order.sort_by_key(|&t| (self.used_at[t], t));
        let (mut freed, mut tlases) = (0u64, 0u32);
        for t in order {
            if freed >= bytes {
                break;
            }
            if let Some(b) = self.kept[t].take() {
                freed += b.size_bytes();
                tlases += 1;
                heap.free(b);
            }
        }
        if freed < bytes || self.kept.iter().all(Option::is_none) {
            if let Some(t) = self.tables.take() {
                freed += t.blas_addresses.size_bytes() + t.chunk_firsts.size_bytes();
                heap.free(t.blas_addresses);
                heap.free(t.chunk_firsts);
            }
        }
        if freed > 0 && self.released_in_frame != Some(frame) {
            let soon = self
                .released_in_frame
                .is_some_and(|p| frame <= p + self.backoff_frames + 1);
            self.backoff_frames = if soon {
                (self.backoff_frames * 2).clamp(1, 16)
            } else {
                1
            };
            self.released_in_frame = Some(frame);
            self.make_from_frame = frame + self.backoff_frames;
        }
        self.bytes = self.bytes.saturating_sub(freed);
        (freed, tlases)
    }
}

/// One TLAS's compaction in a rebuild.
pub(super) struct CompactJob<'c> {
    pub tlas: u32,
    /// Its first record in the instance buffer.
    pub first_record: u32,
    /// Resident instances per chunk of [`TLAS_COMPACT_CHUNK`].
    pub per_chunk: &'c [u32],
}

fn storage_usage() -> BufferUsage {
    BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS | BufferUsage::TRANSFER_DST
}

impl StreamingRenderer<'_> {
    /// Per TLAS of `ids` (rebuilt, not persistent): whether its records are compacted on the
    /// GPU this rebuild. Kept records are made where missing for a TLAS rebuilt before, in
    /// free budget beyond `room_bytes` (what the rebuild itself needs): they
    /// never evict a structure, nor take the rebuild's room. A TLAS without them is written
    /// from the host (`tlas_records_host_fallbacks`).
    pub(super) fn prepare_kept_records(
        &mut self,
        ids: &[u32],
        room_bytes: u64,
    ) -> Result<Vec<bool>> {
        let mut gpu = vec![false; ids.len()];
        if self.opts.tlas_records != TlasRecordsMode::Gpu {
            return Ok(gpu);
        }
        let frame = self.frame.stats().frame;
        let may_make = frame >= self.tlases.records().make_from_frame;
        for (k, &t) in ids.iter().enumerate() {
            let n = self.view.tlases[t as usize].instance_count;
            let kept = self.tlases.records_mut();
            let earlier = std::mem::replace(&mut kept.rebuilt_before[t as usize], true);
            if n == 0 {
                continue;
            }
            gpu[k] = kept.has(t) || (may_make && earlier && self.make_kept(t, room_bytes)?);
            let kept = self.tlases.records_mut();
            if gpu[k] {
                kept.stamp += 1;
                kept.used_at[t as usize] = kept.stamp;
            } else {
                self.frame.stats_mut().tlas_records_host_fallbacks += 1;
            }
        }
        let bytes = self.tlases.records().bytes();
        self.frame.stats_mut().tlas_records_kept_bytes = bytes;
        self.totals.tlas_records_kept_bytes = self.totals.tlas_records_kept_bytes.max(bytes);
        Ok(gpu)
    }

    /// Room of at least `bytes` is wanted for a structure: kept records go first, least
    /// recently rebuilt TLAS first (see the module docs). Returns the bytes released.
    pub(super) fn release_kept_records_for_room(&mut self, bytes: u64) -> u64 {
        if bytes == 0 || self.tlases.records().bytes() == 0 {
            return 0;
        }
        let frame = self.frame.stats().frame;
        let (freed, tlases) =
            self.tlases
                .records_mut()
                .release_for_room(bytes, frame, &mut self.heap);
        if freed > 0 {
            tracing::debug!(
                wanted_bytes = bytes,
                freed_bytes = freed,
                tlases,
                "kept TLAS records released for a structure's room"
            );
            self.totals.tlas_records_released += tlases;
            self.frame.stats_mut().tlas_records_released += tlases;
        }
        freed
    }

    /// Makes TLAS `t`'s kept records (and the tables and pipeline, the first time) in free
    /// budget beyond `room_bytes`: they never evict a structure. Returns false where they do
    /// not fit.
    fn make_kept(&mut self, t: u32, room_bytes: u64) -> Result<bool> {
        let n = u64::from(self.view.tlases[t as usize].instance_count);
        if self.free_budget_bytes() < room_bytes + n * RECORD_BYTES as u64 {
            return Ok(false);
        }
        if !self.tlases.records().has_tables() {
            match self.make_tables() {
                Ok(()) => {}
                Err(GpuError::Budget(_)) => return Ok(false),
                Err(e) => return Err(e),
            }
        }
        let alloc = self.heap.alloc_buffer(
            "stream-tlas-kept-records",
            n * RECORD_BYTES as u64,
            storage_usage(),
            AllocKind::InstanceBuffer,
            MemoryClass::DeviceLocal,
            16,
        );
        let buf = match alloc {
            Ok(b) => b,
            Err(motu_vk::VkError::Budget(_)) => return Ok(false),
            Err(e) => return Err(e.into()),
        };
        if let Err(e) = self.encode_kept(t, &buf) {
            self.heap.free(buf);
            return Err(e);
        }
        self.frame.stats_mut().tlas_records_kept_written += n;
        let kept = self.tlases.records_mut();
        kept.bytes += buf.size_bytes();
        kept.kept[t as usize] = Some(buf);
        Ok(true)
    }

    /// The compaction's pipeline and its tables: the BLAS address table and the chunk table
    /// (a slot per chunk of every TLAS).
    fn make_tables(&mut self) -> Result<()> {
        if self.tlases.records().pipeline.is_none() {
            let pipeline = ComputePipeline::new(
                &self.ctx,
                &ComputePipelineDesc {
                    label: "stream TLAS records",
                    spirv: crate::shaders::TLAS_COMPACT_COMP,
                    storage_buffer_count: 0,
                    push_constant_size_bytes: std::mem::size_of::<TlasCompactPush>() as u32,
                    specialization: &[],
                },
            )?;
            self.tlases.records_mut().pipeline = Some(pipeline);
        }
        let mut chunk_base = Vec::with_capacity(self.view.tlases.len());
        let mut chunks = 0u32;
        for rec in self.view.tlases {
            chunk_base.push(chunks);
            chunks += rec.instance_count.div_ceil(TLAS_COMPACT_CHUNK);
        }
        let nb = self.view.blases.len().max(1) as u64;
        let blas_addresses = self.heap.alloc_buffer(
            "stream-tlas-blas-addresses",
            nb * 8,
            storage_usage(),
            AllocKind::NodeTable,
            MemoryClass::DeviceLocal,
            16,
        )?;
        let chunk_table = self.heap.alloc_buffer(
            "stream-tlas-chunk-firsts",
            u64::from(chunks.max(1)) * 4,
            storage_usage(),
            AllocKind::NodeTable,
            MemoryClass::DeviceLocal,
            16,
        );
        let chunk_table = match chunk_table {
            Ok(b) => b,
            Err(e) => {
                self.heap.free(blas_addresses);
                return Err(e.into());
            }
        };
        let kept = self.tlases.records_mut();
        kept.bytes += blas_addresses.size_bytes() + chunk_table.size_bytes();
        kept.tables = Some(CompactTables {
            blas_addresses,
            chunk_firsts: chunk_table,
            chunk_base,
        });
        Ok(())
    }

    /// Encodes every instance of TLAS `t` into `buf` through the ring, a region at a time.
    fn encode_kept(&mut self, t: u32, buf: &HeapBuffer) -> Result<()> {
        let ctx = self.ctx.clone();
        let view = self.view;
        let rec = &view.tlases[t as usize];
        let instances = &view.instances[rec.instance_range()];
        let up = self.up.as_mut().ok_or_else(staging_released)?;
        let window = ((up.region_bytes() / RECORD_BYTES as u64) as usize).max(1);
        let r = (|| -> Result<()> {
            for (w, part) in instances.chunks(window).enumerate() {
                let first = w * window;
                let at = (first * RECORD_BYTES) as u64;
                up.upload_in_place(&ctx, buf, at, part.len() * RECORD_BYTES, |out| {
                    out.par_chunks_mut(ENCODE_CHUNK * RECORD_BYTES)
                        .zip(part.par_chunks(ENCODE_CHUNK))
                        .enumerate()
                        .for_each(|(c, (out, insts))| {
                            for (j, (slot, inst)) in
                                out.chunks_exact_mut(RECORD_BYTES).zip(insts).enumerate()
                            {
                                let index = (first + c * ENCODE_CHUNK + j) as u32;
                                slot.copy_from_slice(&kept_record(&view, inst, index));
                            }
                        });
                })?;
            }
            up.flush(&ctx)
        })();
        if r.is_err() {
            // Copies queued for the buffer must not outlive it.
            up.abandon();
        }
        r
    }

    /// Writes the `jobs`' records into the instance buffer at device address `dst` from their
    /// kept records and the residency `addrs` (per BLAS, 0: not resident). Returns the pass's
    /// milliseconds (tables' upload, dispatch and wait).
    pub(super) fn compact_records(
        &mut self,
        jobs: &[CompactJob<'_>],
        addrs: &[u64],
        dst: u64,
    ) -> Result<f64> {
        if jobs.is_empty() {
            return Ok(0.0);
        }
        let t0 = std::time::Instant::now();
        let ctx = self.ctx.clone();
        let kept = self.tlases.records();
        let (tables, pipeline) = match (&kept.tables, &kept.pipeline) {
            (Some(t), Some(p)) => (t, p),
            _ => {
                return Err(GpuError::InvalidRequest(
                    "streaming: TLAS records compacted without their tables".into(),
                ))
            }
        };
        let up = self.up.as_mut().ok_or_else(staging_released)?;
        let uploaded = (|| -> Result<()> {
            up.upload(&ctx, &tables.blas_addresses, 0, bytemuck::cast_slice(addrs))?;
            for job in jobs {
                let (firsts, _) = chunk_firsts(job.per_chunk);
                let firsts: Vec<u32> = firsts.iter().map(|f| f + job.first_record).collect();
                let at = u64::from(tables.chunk_base[job.tlas as usize]) * 4;
                up.upload(
                    &ctx,
                    &tables.chunk_firsts,
                    at,
                    bytemuck::cast_slice(&firsts),
                )?;
            }
            up.flush(&ctx)
        })();
        if let Err(e) = uploaded {
            up.abandon();
            return Err(e);
        }
        let addresses = tables.blas_addresses.device_address()?.0;
        let chunk_table = tables.chunk_firsts.device_address()?.0;
        let mut rec = ctx.record("stream TLAS records")?;
        rec.barrier();
        for job in jobs {
            let t = job.tlas as usize;
            let buf = kept.kept[t].as_ref().ok_or_else(|| {
                GpuError::InvalidRequest(format!("streaming: TLAS {t} has no kept records"))
            })?;
            let push = TlasCompactPush {
                kept: buf.device_address()?.0,
                dst,
                chunk_first: chunk_table + u64::from(tables.chunk_base[t]) * 4,
                blas_addresses: addresses,
                instance_count: self.view.tlases[t].instance_count,
                _pad: [0; 3],
            };
            let groups = job.per_chunk.len() as u32;
            rec.dispatch(pipeline, None, bytemuck::bytes_of(&push), [groups, 1, 1])?;
        }
        rec.barrier();
        rec.submit_and_wait()?;
        Ok(t0.elapsed().as_secs_f64() * 1e3)
    }
}
