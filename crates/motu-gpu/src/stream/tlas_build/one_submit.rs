//! A rebuild group's proxy and marks BLASes and TLASes in one submission: the boxes, PI
//! slots, marks records and instance records copied, the proxies built, then (a build→build
//! barrier) the TLASes over them, waited on once. The sequential path
//! ([`TlasBuild::build_proxies`], [`TlasBuild::rebuild`]) waits four times at least: the
//! boxes' flush, the proxies' batch, the records' flush, the TLASes' batch. The TLASes' records
//! need only the proxies' device addresses, known once their structures are allocated.
//!
//! Taken when nothing is compacted (`--stream-tlas-compact off`, the default: a compacted
//! proxy moves), the records are the host's (`--stream-tlas-records host`, the default), no
//! persistent TLAS is updated in the group (updates read the built proxies) and each level is
//! one batch under the scratch limits. Everything is allocated before any
//! copy is queued: a refused allocation releases what this path took and the sequential path
//! runs instead (its peak is lower: the box buffer and the proxies' scratch are gone before
//! the records' buffer is allocated).

use motu_alloc::BuildSize;
use motu_vk::{
    AsBuild, AsBuildMode, AsGeometry, AsLevel, AsTarget, BufferUsage, Context, GpuHeap, HeapBuffer,
    MemoryScope, VkError,
};

use super::storage::tlas_structures;
use super::{
    alloc_box_buffer, alloc_instance_buffer, proxy_geometry, proxy_sizes, queue_proxy_uploads,
    Built, PhaseTimes, Proxies, ProxyPlan, TlasBuild,
};
use crate::error::{GpuError, Result};
use crate::scene::{plan_one_batch, AccelStruct, Uploader};
use crate::stream::buffers::staging_released;

/// What the one submission holds until it is waited on (or released on failure).
#[derive(Default)]
struct Held {
    boxes: Option<HeapBuffer>,
    instances: Option<HeapBuffer>,
    scratch: Option<HeapBuffer>,
    /// The new TLASes, one per rebuilt id, and how many of them are built into the storage
    /// of the structure they replace (`storage.rs`).
    tlases: Vec<AccelStruct>,
    reused: u32,
}

impl Held {
    /// Frees the build inputs and scratch (the builds were waited on, or never submitted).
    fn free_inputs(&mut self, heap: &mut GpuHeap) {
        for b in [
            self.boxes.take(),
            self.instances.take(),
            self.scratch.take(),
        ]
        .into_iter()
        .flatten()
        {
            heap.free(b);
        }
    }

    /// Frees everything (a failure, or falling back to the sequential path).
    fn release(mut self, heap: &mut GpuHeap) {
        self.free_inputs(heap);
        self.tlases.into_iter().for_each(|a| a.release(heap));
    }
}

/// `Ok(None)` for a budget refusal (the caller falls back), the value or other errors as they
/// are.
fn fits<T>(r: std::result::Result<T, VkError>) -> Result<Option<T>> {
    match r {
        Ok(v) => Ok(Some(v)),
        Err(VkError::Budget(_)) => Ok(None),
        Err(e) => Err(e.into()),
    }
}

/// As [`fits`] for the crate's errors.
fn fits_gpu<T>(r: Result<T>) -> Result<Option<T>> {
    match r {
        Ok(v) => Ok(Some(v)),
        Err(GpuError::Budget(_)) => Ok(None),
        Err(e) => Err(e),
    }
}

impl TlasBuild<'_, '_> {
    /// Rebuilds TLASes `ids` with the planned proxies in one submission (see the module docs);
    /// the new pairs go into `proxies`. Returns the built TLASes (indices into `ids`) and the
    /// records written, or `None` when this path does not apply or its allocations are refused
    /// (nothing of it is left: `proxies` as it came, no copy queued).
    pub(super) fn one_submission(
        &mut self,
        ids: &[u32],
        plan: &ProxyPlan,
        proxies: &mut Proxies,
    ) -> Result<Option<(Built, u64)>> {
        // The opt-in GPU-kept records (`--stream-tlas-records gpu`) keep the step-by-step path:
        // their compaction pass writes the records the host would, which this path does not
        // order after it (stream_records.rs: the host wrote more records with it than without).
        if ids.is_empty()
            || self.r.rebuild_opts().compact
            || self.r.opts.tlas_records == crate::stream::TlasRecordsMode::Gpu
        {
            return Ok(None);
        }
        let first = proxies.0.len();
        let mut held = Held::default();
        let result = self.one_submission_held(ids, plan, proxies, &mut held);
        let r = &mut *self.r;
        match result {
            Ok(Some(done)) => {
                PhaseTimes::timed(&mut self.times.free_ms, || held.free_inputs(&mut r.heap));
                self.times.storage_reused += held.reused;
                self.times.storage_allocated += held.tlases.len() as u32 - held.reused;
                let built = held
                    .tlases
                    .into_iter()
                    .enumerate()
                    .map(|(k, a)| (k, a, 0))
                    .collect();
                Ok(Some((built, done)))
            }
            other => {
                // Refused (nothing queued yet) or failed (copies queued for the buffers below
                // must not outlive them): this path's pairs and structures go; on failure the
                // caller releases the kept pairs.
                if other.is_err() {
                    if let Some(up) = r.up.as_mut() {
                        up.abandon();
                    }
                }
                held.release(&mut r.heap);
                proxies
                    .0
                    .drain(first..)
                    .for_each(|(_, p)| p.release(&mut r.heap));
                other.map(|_| None)
            }
        }
    }

    /// [`Self::one_submission`]'s work, everything it allocates in `held` (or `proxies`).
    /// Returns the records written.
    fn one_submission_held(
        &mut self,
        ids: &[u32],
        plan: &ProxyPlan,
        proxies: &mut Proxies,
        held: &mut Held,
    ) -> Result<Option<u64>> {
        let ctx = self.ctx.clone();
        let r = &mut *self.r;
        let rb = r.rebuild_opts();
        // Proxies: sizes, one batch, their box buffer and structures (addresses known).
        let proxy_sizes = proxy_sizes(&ctx, plan, &rb)?;
        let proxy_plan = if proxy_sizes.is_empty() {
            None
        } else {
            match plan_one_batch(&ctx, &r.heap, &proxy_sizes, &rb) {
                Some(p) => Some(p),
                None => return Ok(None),
            }
        };
        let proxy_scratch = proxy_plan.as_ref().map_or(0, |p| p.scratch_pool_bytes);
        if plan.box_count > 0 {
            let boxes = PhaseTimes::timed(&mut self.times.alloc_ms, || {
                alloc_box_buffer(&mut r.heap, plan)
            });
            let Some(b) = fits_gpu(boxes)? else {
                return Ok(None);
            };
            held.boxes = Some(b);
        }
        let built = PhaseTimes::timed(&mut self.times.alloc_ms, || {
            alloc_structures(&ctx, &mut r.heap, &proxy_sizes, AsLevel::Bottom)
        });
        let Some(built) = built? else {
            return Ok(None);
        };
        let proxy_targets: Vec<_> = built.iter().map(|(_, a, _)| a.target()).collect();
        proxies.install(plan, built);
        // TLASes: records counted over the new proxies, one batch, their buffers.
        let rr = PhaseTimes::timed(&mut self.times.count_ms, || {
            Self::count_records(r, &ctx, &self.addrs, ids, &self.gpu, proxies)
        })?;
        self.times.encode_ms = self.times.lap();
        let Some(tlas_plan) = plan_one_batch(&ctx, &r.heap, &rr.sizes, &rb) else {
            return Ok(None);
        };
        let t_alloc = std::time::Instant::now();
        let Some(inst) = fits_gpu(alloc_instance_buffer(&mut r.heap, rr.total_bytes))? else {
            return Ok(None);
        };
        let inst = &*held.instances.insert(inst);
        let align = ctx.limits().scratch_alignment_bytes();
        let pool_bytes = proxy_scratch.max(tlas_plan.scratch_pool_bytes).max(align);
        let scratch = r.heap.alloc_buffer(
            "scratch-pool",
            pool_bytes,
            BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
            motu_alloc::AllocKind::Scratch,
            motu_alloc::MemoryClass::DeviceLocal,
            align,
        );
        let Some(scratch) = fits(scratch)? else {
            return Ok(None);
        };
        let scratch = &*held.scratch.insert(scratch);
        let old = &mut self.old_storage;
        let Some((tlases, reused)) =
            tlas_structures(&ctx, &mut r.heap, old, ids, &rr.sizes, r.opts.tlas_headroom)?
        else {
            return Ok(None);
        };
        self.times.alloc_ms += t_alloc.elapsed().as_secs_f64() * 1e3;
        (held.tlases, held.reused) = (tlases, reused);
        // Committed: no fallback from here (a failure releases all and returns the error).
        rr.note(r.frame.stats_mut());
        self.times.proxies_built += proxy_targets.len() as u32;
        self.times.proxy_build_ms = self.times.lap();
        if let Some(b) = &held.boxes {
            PhaseTimes::timed(&mut self.times.proxy_upload_ms, || {
                queue_proxy_uploads(&ctx, r, plan, b)
            })?;
        }
        {
            let up = r.up.as_mut().ok_or_else(staging_released)?;
            rr.records.upload(&ctx, up, inst, &rr.offsets)?;
        }
        let inst_addr = inst.device_address()?.0;
        // The GPU TLASes' own records, between the host's (its tables' flush takes the copies
        // queued so far along).
        let ms = r.compact_records(&rr.records.gpu_jobs(&rr.offsets), &self.addrs, inst_addr)?;
        r.frame.stats_mut().tlas_compact_ms += ms;
        self.times.upload_ms = self.times.lap();
        let scratch_base = scratch.device_address()?.0.div_ceil(align) * align;
        let boxes_addr = match &held.boxes {
            Some(b) => b.device_address()?.0,
            None => 0,
        };
        let proxy_geoms: Vec<_> = plan
            .items
            .iter()
            .map(|item| proxy_geometry(boxes_addr, item))
            .collect();
        let proxy_offsets = proxy_plan.as_ref().map(|p| &p.scratch_offsets_bytes[..]);
        let proxy_builds = level_builds(
            (AsLevel::Bottom, rb.blas_flags()),
            &proxy_geoms,
            &proxy_targets,
            scratch_base,
            proxy_offsets.unwrap_or(&[]),
        );
        let tlas_geoms: Vec<(Vec<AsGeometry>, Vec<u32>)> = rr
            .offsets
            .iter()
            .zip(&rr.counts)
            .map(|(&at, &n)| {
                (
                    vec![AsGeometry::Instances {
                        address: inst_addr + at,
                    }],
                    vec![n],
                )
            })
            .collect();
        let tlas_targets: Vec<_> = held.tlases.iter().map(AccelStruct::target).collect();
        let tlas_builds = level_builds(
            (AsLevel::Top, rb.tlas_flags()),
            &tlas_geoms,
            &tlas_targets,
            scratch_base,
            &tlas_plan.scratch_offsets_bytes,
        );
        // Every buffer and structure named lives in `held` or `proxies` until the wait.
        let up = r.up.as_mut().ok_or_else(staging_released)?;
        submit_levels(&ctx, up, &proxy_builds, &tlas_builds)?;
        self.times.build_ms = self.times.lap();
        Ok(Some(rr.total_bytes / super::RECORD_BYTES as u64))
    }
}

/// Structures of `level` of `sizes` (build index, structure, 0 saved), or `None` when the
/// budget refuses one (those made are released).
fn alloc_structures(
    ctx: &Context,
    heap: &mut GpuHeap,
    sizes: &[BuildSize],
    level: AsLevel,
) -> Result<Option<Built>> {
    let kind = match level {
        AsLevel::Top => "tlas",
        AsLevel::Bottom => "blas",
    };
    let mut made: Built = Vec::with_capacity(sizes.len());
    for (k, size) in sizes.iter().enumerate() {
        let label = format!("{kind}-{k}");
        match fits(AccelStruct::new(
            ctx,
            heap,
            &label,
            size.result_bytes,
            level,
        )) {
            Ok(Some(a)) => made.push((k, a, 0)),
            other => {
                made.into_iter().for_each(|(_, a, _)| a.release(heap));
                return other.map(|_| None);
            }
        }
    }
    Ok(Some(made))
}

/// One level's builds: `geoms[k]` into `dsts[k]` with scratch at `scratch_base +
/// offsets[k]`, built with `level`'s `flags` (those its sizes were queried with).
fn level_builds<'g>(
    (level, flags): (AsLevel, motu_vk::AsBuildFlags),
    geoms: &'g [(Vec<AsGeometry>, Vec<u32>)],
    dsts: &[AsTarget],
    scratch_base: u64,
    offsets: &[u64],
) -> Vec<AsBuild<'g>> {
    geoms
        .iter()
        .zip(dsts)
        .enumerate()
        .map(|(k, ((g, counts), &dst))| AsBuild {
            level,
            flags,
            mode: AsBuildMode::Build,
            dst,
            geometries: g,
            primitive_counts: counts,
            scratch_address: scratch_base + offsets.get(k).copied().unwrap_or(0),
        })
        .collect()
}

/// The ring's queued copies, then the proxies' builds, then the TLASes' over them (the scratch
/// reused after a barrier), in one command buffer, waited on. The caller keeps every
/// destination, input and the scratch alive until this returns.
fn submit_levels(
    ctx: &Context,
    up: &mut Uploader,
    proxies: &[AsBuild<'_>],
    tlases: &[AsBuild<'_>],
) -> Result<()> {
    let mut rec = ctx.record("stream TLAS rebuild")?;
    if up.record_pending(&mut rec)? {
        rec.memory_barrier(MemoryScope::TransferWrites, MemoryScope::BuildReads);
    }
    rec.barrier();
    rec.build_acceleration_structures(proxies)?;
    // The TLAS builds read the proxies and reuse the scratch.
    rec.barrier();
    rec.build_acceleration_structures(tlases)?;
    rec.barrier();
    rec.submit_and_wait()?;
    Ok(())
}
