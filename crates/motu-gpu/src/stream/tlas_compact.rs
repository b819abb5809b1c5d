//! Streamed TLAS records kept on the GPU ([`KeptRecords`], `--stream-tlas-records gpu`): each
//! rebuilt TLAS (each piece of a split root) keeps every instance's record in device memory,
//! encoded once through the staging ring when the TLAS is first rebuilt, with the BLAS id where
//! the address goes. A rebuild then writes its resident records with a compute pass
//! (`shaders/tlas_compact.comp`, the rule in [`motu_abi::tlas_compact`]): the host counts each
//! chunk's resident instances (as the host path does), uploads the chunks' first slots and the
//! BLAS address table, and writes only the tail (proxy and marks) records. The records are
//! the host path's, byte for byte and in the same order, so the TLAS and the image are too.
//!
//! Invariants: a kept buffer holds TLAS `t`'s `instance_count` records in instance order and
//! is never written after its encode; the kept bytes (records, BLAS address table, chunk
//! table) count against the budget as part of the skeleton (`Tlases::size_bytes`); kept
//! records are made only by [`StreamingRenderer::prepare_kept_records`], in free budget
//! (never evicting a structure for them), which never fails a rebuild for want of room (the
//! TLAS is then written from the host); they are all released when a refused allocation finds
//! nothing else to evict ([`KeptRecords::give_up`]) and made again where room is free.

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
    tables: Option<CompactTables>,
    pipeline: Option<ComputePipeline>,
    /// Bytes of the kept records and the tables.
    bytes: u64,
    /// The frame in which they were last released: none is made again in that frame (a
    /// refused build retried would otherwise make and release them round after round).
    released_in_frame: Option<u64>,
}

impl KeptRecords {
    /// Nothing kept yet for `tlases` TLASes.
    pub fn new(tlases: usize) -> KeptRecords {
        KeptRecords {
            kept: (0..tlases).map(|_| None).collect(),
            ..Default::default()
        }
    }

    /// Bytes kept (records and tables), counted against the budget.
    pub fn bytes(&self) -> u64 {
        self.bytes
    }

    /// Whether TLAS `t` has kept records.
    pub fn has(&self, t: u32) -> bool {
        self.kept.get(t as usize).is_some_and(Option::is_some)
    }

    fn has_tables(&self) -> bool {
        self.tables.is_some()
    }

    /// Releases every kept record and table (a refused allocation found nothing else to
    /// evict). Returns whether anything was released.
    pub fn give_up(&mut self, heap: &mut GpuHeap) -> bool {
        let mut any = false;
        for b in self.kept.iter_mut().filter_map(Option::take) {
            heap.free(b);
            any = true;
        }
        if let Some(t) = self.tables.take() {
            heap.free(t.blas_addresses);
            heap.free(t.chunk_firsts);
            any = true;
        }
        self.bytes = 0;
        any
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
    /// GPU this rebuild. Kept records are made where missing, in free budget (they never evict
    /// a structure); where they do not fit, the TLAS is written from the host
    /// (`tlas_records_host_fallbacks`).
    pub(super) fn prepare_kept_records(&mut self, ids: &[u32]) -> Result<Vec<bool>> {
        let mut gpu = vec![false; ids.len()];
        if self.opts.tlas_records != TlasRecordsMode::Gpu {
            return Ok(gpu);
        }
        let frame = self.frame.stats().frame;
        let may_make = self.tlases.records().released_in_frame != Some(frame);
        for (k, &t) in ids.iter().enumerate() {
            let n = self.view.tlases[t as usize].instance_count;
            if n == 0 {
                continue;
            }
            gpu[k] = self.tlases.records().has(t) || (may_make && self.make_kept(t)?);
            if !gpu[k] {
                self.frame.stats_mut().tlas_records_host_fallbacks += 1;
            }
        }
        let bytes = self.tlases.records().bytes();
        self.frame.stats_mut().tlas_records_kept_bytes = bytes;
        self.totals.tlas_records_kept_bytes = self.totals.tlas_records_kept_bytes.max(bytes);
        Ok(gpu)
    }

    /// A refused allocation found nothing else to evict: the kept records go (rebuilds write
    /// from the host until room is free for them again). Returns whether any bytes were
    /// released.
    pub(super) fn give_up_kept_records(&mut self) -> bool {
        let bytes = self.tlases.records().bytes();
        let any = self.tlases.records_mut().give_up(&mut self.heap);
        if any {
            tracing::debug!(
                kept_bytes = bytes,
                "the budget refused an allocation with nothing else to evict: kept TLAS records \
                 released"
            );
            self.totals.tlas_records_released += 1;
            let frame = self.frame.stats().frame;
            self.tlases.records_mut().released_in_frame = Some(frame);
        }
        any
    }

    /// Makes TLAS `t`'s kept records (and the tables and pipeline, the first time) in free
    /// budget: they never evict a structure. Returns false where the budget refuses them.
    fn make_kept(&mut self, t: u32) -> Result<bool> {
        if !self.tlases.records().has_tables() {
            match self.make_tables() {
                Ok(()) => {}
                Err(GpuError::Budget(_)) => return Ok(false),
                Err(e) => return Err(e),
            }
        }
        let n = u64::from(self.view.tlases[t as usize].instance_count);
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
