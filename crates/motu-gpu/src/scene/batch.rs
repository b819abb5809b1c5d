//! Build batching: batches planned under the scratch budget, staged one ahead of the GPU and
//! compacted before the next.

use std::time::Instant;

use motu_alloc::{plan_build_batches, AllocKind, BatchLimits, BatchPlan, BuildSize, MemoryClass};
use motu_vk::{
    AsBuild, AsBuildFlags, AsBuildMode, AsCopyMode, AsGeometry, AsLevel, BudgetRefusal,
    BufferUsage, CommandRecorder, Context, GpuHeap, HeapBuffer, MemoryScope, Submitted,
};

use super::{AccelStruct, BuildOptions, Pending, ResourceReport, SizeQueries};
use crate::error::{GpuError, Result};

/// Build inputs staged one batch ahead: `stage` loads batch k+1's inputs into host-visible
/// staging while batch k builds on the GPU; `record` puts the staged copies into the batch's
/// own command buffer, ahead of its build.
pub(crate) trait BatchStager {
    /// Loads and stages the inputs of builds `builds`; returns the bytes staged and the time
    /// spent blocked on the GPU (a full ring region flushes behind the batch in flight). Runs
    /// while the previous batch may still be on the GPU, so it must not touch its resources.
    fn stage(&mut self, builds: std::ops::Range<usize>) -> Result<(u64, std::time::Duration)>;
    /// Records the staged copies into `rec`; returns whether anything was recorded. The
    /// caller waits on its submission before the staged region is reused and before any
    /// destination is freed.
    fn record(&mut self, rec: &mut CommandRecorder<'_>) -> Result<bool>;
    /// Drops whatever was staged but not recorded (after a failure).
    fn abandon(&mut self);
}

impl BuildOptions {
    /// The flags BLASes are built with: `blas_build`'s, compaction allowed only when they are
    /// compacted (the size query and the build must agree).
    pub(crate) fn blas_flags(&self) -> motu_vk::AsBuildFlags {
        AsBuildFlags {
            allow_compaction: self.compact,
            ..self.blas_build.flags()
        }
    }
}

/// The limits [`build_batched`] plans its batches under: `opts`' scratch budget and batch
/// results, the heap's budget for the pool.
fn batch_limits(ctx: &Context, heap: &GpuHeap, opts: &BuildOptions) -> BatchLimits {
    BatchLimits {
        scratch_budget_bytes: opts.scratch_budget_bytes,
        scratch_alignment_bytes: ctx.limits().scratch_alignment_bytes(),
        scratch_pool_max_bytes: heap.limits().budget_bytes,
        max_batch_result_bytes: Some(opts.max_batch_result_bytes),
    }
}

/// The plan [`build_batched`] would follow for `sizes` when it is one batch (its scratch
/// offsets and pool), else `None` (several batches, or no plan: the caller builds through
/// [`build_batched`], which waits on each batch). A caller recording the builds into its own
/// command buffer (the streamer's TLAS rebuilds: proxies and TLASes in one submission) uses it
/// to stay within the same scratch and batch limits.
pub(crate) fn plan_one_batch(
    ctx: &Context,
    heap: &GpuHeap,
    sizes: &[BuildSize],
    opts: &BuildOptions,
) -> Option<BatchPlan> {
    plan_build_batches(sizes, batch_limits(ctx, heap, opts))
        .ok()
        .filter(|p| p.batches.len() <= 1)
}

/// Builds `sizes.len()` structures in batches under the scratch budget, compacting each
/// batch before the next. `geometry(k)` describes build k (addresses valid once
/// `prepare(heap, batch_range)` ran for its batch). `inputs_done(heap)` runs once, when the
/// last batch is built and before it is compacted: the caller may free build inputs nothing
/// reads after a build (a TLAS's instance buffer), as the scratch pool is freed there, so the
/// compacted copies do not stack on them. Returns (k, structure) pairs. On failure every
/// structure this call created is released before the error returns (a streaming caller
/// evicts and retries).
#[allow(clippy::too_many_arguments)]
pub(crate) fn build_batched(
    ctx: &Context,
    heap: &mut GpuHeap,
    report: &mut ResourceReport,
    sizes: &[BuildSize],
    ty: AsLevel,
    opts: &BuildOptions,
    geometry: impl Fn(usize) -> (Vec<AsGeometry>, Vec<u32>),
    prepare: impl FnMut(&mut GpuHeap, std::ops::Range<usize>) -> Result<()>,
    inputs_done: &mut dyn FnMut(&mut GpuHeap),
) -> Result<Vec<(usize, AccelStruct)>> {
    build_pipelined(
        ctx,
        heap,
        report,
        sizes,
        ty,
        opts,
        geometry,
        prepare,
        None,
        inputs_done,
    )
}

/// [`build_batched`] with inputs staged one batch ahead by `stager`: batch k's copies and build
/// go in one submission that is not waited on until batch k+1 is staged (the wait comes before
/// the compacted-size read, the compaction copies and the next batch's submission).
#[allow(clippy::too_many_arguments)]
pub(crate) fn build_pipelined(
    ctx: &Context,
    heap: &mut GpuHeap,
    report: &mut ResourceReport,
    sizes: &[BuildSize],
    ty: AsLevel,
    opts: &BuildOptions,
    geometry: impl Fn(usize) -> (Vec<AsGeometry>, Vec<u32>),
    prepare: impl FnMut(&mut GpuHeap, std::ops::Range<usize>) -> Result<()>,
    stager: Option<&mut dyn BatchStager>,
    inputs_done: &mut dyn FnMut(&mut GpuHeap),
) -> Result<Vec<(usize, AccelStruct)>> {
    if sizes.is_empty() {
        return Ok(Vec::new());
    }
    let scratch_align = ctx.limits().scratch_alignment_bytes();
    let plan = plan_build_batches(sizes, batch_limits(ctx, heap, opts))
        .map_err(|e| GpuError::Budget(BudgetRefusal::from_cause(e)))?;
    let pool = heap.alloc_buffer(
        "scratch-pool",
        plan.scratch_pool_bytes.max(scratch_align),
        BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
        AllocKind::Scratch,
        MemoryClass::DeviceLocal,
        scratch_align,
    )?;
    report.scratch_peak_bytes = report.scratch_peak_bytes.max(pool.size_bytes());
    let scratch_address = match pool.device_address() {
        Ok(a) => a.0,
        Err(e) => {
            heap.free(pool);
            return Err(e.into());
        }
    };
    let (kind, flags) = match ty {
        AsLevel::Top => ("tlas", opts.tlas_flags()),
        AsLevel::Bottom => ("blas", opts.blas_flags()),
    };
    let mut run = PipelinedBuild {
        ctx,
        heap,
        report,
        sizes,
        ty,
        kind,
        flags,
        compact: opts.compact,
        plan: &plan,
        scratch_base: scratch_address.div_ceil(scratch_align) * scratch_align,
        scratch: Some(pool),
        geometry,
        prepare,
        stager,
        inputs_done,
        out: Vec::with_capacity(sizes.len()),
        in_flight: Vec::new(),
    };
    let result = run.batches();
    run.finish(result)
}

/// [`build_pipelined`]'s state over its batches, one method per phase. Every structure it
/// creates is in `out` (built) or `in_flight` (its batch not finished) until `finish`.
struct PipelinedBuild<'a, 's, 'i, G, P> {
    ctx: &'a Context,
    heap: &'a mut GpuHeap,
    report: &'a mut ResourceReport,
    sizes: &'a [BuildSize],
    ty: AsLevel,
    /// `"tlas"` or `"blas"`, for labels.
    kind: &'static str,
    /// The flags the sizes were queried with.
    flags: AsBuildFlags,
    compact: bool,
    plan: &'a BatchPlan,
    scratch_base: u64,
    /// Freed once the last batch is built (before its compaction), else at the end.
    scratch: Option<HeapBuffer>,
    geometry: G,
    prepare: P,
    stager: Option<&'a mut (dyn BatchStager + 's)>,
    inputs_done: &'a mut (dyn FnMut(&mut GpuHeap) + 'i),
    out: Vec<(usize, AccelStruct)>,
    in_flight: Vec<AccelStruct>,
}

/// A batch's build submission, not yet waited on, and the compacted-size queries it writes.
struct BatchSubmission<'c> {
    submitted: Submitted<'c>,
    queries: Option<SizeQueries>,
}

impl<G, P> PipelinedBuild<'_, '_, '_, G, P>
where
    G: Fn(usize) -> (Vec<AsGeometry>, Vec<u32>),
    P: FnMut(&mut GpuHeap, std::ops::Range<usize>) -> Result<()>,
{
    /// Every batch in order, the first one's inputs staged ahead.
    fn batches(&mut self) -> Result<()> {
        if let (Some(st), Some(first)) = (self.stager.as_deref_mut(), self.plan.batches.first()) {
            st.stage(first.builds.clone())?;
        }
        for bi in 0..self.plan.batches.len() {
            self.batch(bi)?;
        }
        Ok(())
    }

    /// Batch `bi`: its destinations, then build and compaction; the results go to `out`.
    fn batch(&mut self, bi: usize) -> Result<()> {
        let builds = self.plan.batches[bi].builds.clone();
        self.report.build_batches += 1;
        (self.prepare)(self.heap, builds.clone())?;
        let mut pending: Vec<Pending> = Vec::new();
        for k in builds {
            match AccelStruct::new(
                self.ctx,
                self.heap,
                &format!("{}-{k}", self.kind),
                self.sizes[k].result_bytes,
                self.ty,
            ) {
                Ok(a) => pending.push(Pending { accel: a, index: k }),
                Err(e) => {
                    self.in_flight.extend(pending.into_iter().map(|p| p.accel));
                    return Err(e.into());
                }
            }
        }
        // From here on a failure releases this batch through `in_flight`.
        match self.build_and_compact(bi, &pending) {
            Ok(copies) if copies.is_empty() => {
                self.out
                    .extend(pending.into_iter().map(|p| (p.index, p.accel)));
            }
            Ok(copies) => {
                for (p, dst) in pending.into_iter().zip(copies) {
                    p.accel.release(self.heap);
                    self.out.push((p.index, dst));
                }
            }
            Err(e) => {
                self.in_flight.extend(pending.into_iter().map(|p| p.accel));
                return Err(e);
            }
        }
        Ok(())
    }

    /// Builds batch `bi` into `pending`, staging the next batch meanwhile; returns the
    /// compacted copies (empty: keep the originals).
    fn build_and_compact(&mut self, bi: usize, pending: &[Pending]) -> Result<Vec<AccelStruct>> {
        let ctx = self.ctx;
        let BatchSubmission { submitted, queries } = self.record_build(ctx, bi, pending)?;
        self.stage_next(bi, submitted)?;
        if bi + 1 == self.plan.batches.len() {
            // Built: no batch reads the scratch or the inputs any more, and the compacted
            // copies below need room of their own.
            if let Some(s) = self.scratch.take() {
                self.heap.free(s);
            }
            (self.inputs_done)(self.heap);
        }
        let Some(queries) = queries else {
            return Ok(Vec::new());
        };
        self.compact(bi, pending, &queries)
    }

    /// Records and submits batch `bi`'s staged copies and builds (not waited on).
    fn record_build<'c>(
        &mut self,
        ctx: &'c Context,
        bi: usize,
        pending: &[Pending],
    ) -> Result<BatchSubmission<'c>> {
        let batch = &self.plan.batches[bi];
        let descs: Vec<_> = batch.builds.clone().map(&self.geometry).collect();
        let builds: Vec<AsBuild<'_>> = descs
            .iter()
            .zip(pending)
            .map(|((g, counts), p)| AsBuild {
                level: self.ty,
                flags: self.flags,
                mode: AsBuildMode::Build,
                dst: p.accel.target(),
                geometries: g,
                primitive_counts: counts,
                scratch_address: self.scratch_base + self.plan.scratch_offsets_bytes[p.index],
            })
            .collect();
        // Compacted sizes are asked only of structures built to be compacted.
        let queries = if self.compact {
            Some(SizeQueries::new(ctx, pending.len() as u32)?)
        } else {
            None
        };
        let targets: Vec<_> = pending.iter().map(|p| p.accel.target()).collect();
        // Destinations, scratch slices (disjoint, aligned), inputs, staged copies and the
        // query pool live until the submission is waited on (also on every error path:
        // `Submitted` waits when dropped).
        let mut rec = ctx.record(&format!("{} build batch {bi}", self.kind))?;
        if let Some(st) = self.stager.as_deref_mut() {
            if st.record(&mut rec)? {
                // Staged geometry copies before the builds read them.
                rec.memory_barrier(MemoryScope::TransferWrites, MemoryScope::BuildReads);
            }
        }
        // Coarse: builds are few and large.
        rec.barrier();
        rec.build_acceleration_structures(&builds)?;
        rec.barrier();
        if let Some(q) = &queries {
            rec.write_compacted_sizes(&targets, q)?;
        }
        Ok(BatchSubmission {
            submitted: rec.submit()?,
            queries,
        })
    }

    /// While the GPU builds batch `bi`, loads and stages the next one; then waits on `bi`.
    fn stage_next(&mut self, bi: usize, submitted: Submitted<'_>) -> Result<()> {
        if let (Some(st), Some(next)) = (self.stager.as_deref_mut(), self.plan.batches.get(bi + 1))
        {
            let t = Instant::now();
            match st.stage(next.builds.clone()) {
                Ok((bytes, stalled)) => {
                    let report = &mut *self.report;
                    report.upload_build_overlap_batches += 1;
                    report.upload_overlap_bytes += bytes;
                    report.upload_overlap_ms +=
                        t.elapsed().saturating_sub(stalled).as_secs_f64() * 1e3;
                    report.upload_stall_ms += stalled.as_secs_f64() * 1e3;
                }
                Err(e) => {
                    st.abandon();
                    // This batch's resources are released by the caller: wait first.
                    let _ = submitted.wait();
                    return Err(e);
                }
            }
        }
        submitted.wait()?;
        Ok(())
    }

    /// Copies batch `bi`'s structures to their compacted sizes; empty when nothing is gained
    /// or the budget has no room for both copies.
    fn compact(
        &mut self,
        bi: usize,
        pending: &[Pending],
        queries: &SizeQueries,
    ) -> Result<Vec<AccelStruct>> {
        let (ctx, kind) = (self.ctx, self.kind);
        let compacted = queries.read(pending.len() as u32)?;
        // Nothing to gain (lavapipe reports the built size): keep the originals and skip the
        // copies' second allocation, which would double the peak.
        if pending
            .iter()
            .zip(&compacted)
            .all(|(p, &size)| size.max(1) >= p.accel.size_bytes)
        {
            return Ok(Vec::new());
        }
        let mut copies = Vec::with_capacity(pending.len());
        for (p, &size) in pending.iter().zip(&compacted) {
            let size = size.max(1).min(p.accel.size_bytes);
            let label = format!("{kind}-{}-compact", p.index);
            match AccelStruct::new(ctx, self.heap, &label, size, self.ty) {
                Ok(a) => copies.push(a),
                Err(motu_vk::VkError::Budget(msg)) => {
                    // No room for both copies: the uncompacted ones are valid as they are,
                    // and the budget holds.
                    tracing::debug!(%msg, "compaction skipped under the budget");
                    copies.into_iter().for_each(|c| c.release(self.heap));
                    return Ok(Vec::new());
                }
                Err(e) => {
                    copies.into_iter().for_each(|c| c.release(self.heap));
                    return Err(e.into());
                }
            }
        }
        let mut rec = match ctx.record(&format!("{kind} compaction batch {bi}")) {
            Ok(r) => r,
            Err(e) => {
                copies.into_iter().for_each(|c| c.release(self.heap));
                return Err(e.into());
            }
        };
        // Both structures live until the fenced submission returns; the source was built
        // with compaction allowed and dst holds its compacted size.
        let copied = pending.iter().zip(&copies).try_for_each(|(p, dst)| {
            rec.copy_acceleration_structure(p.accel.target(), dst.target(), AsCopyMode::Compact)
        });
        if let Err(e) = copied.and_then(|()| rec.submit_and_wait()) {
            copies.into_iter().for_each(|c| c.release(self.heap));
            return Err(e.into());
        }
        Ok(copies)
    }

    /// Frees the scratch pool if still held; on failure releases every structure created.
    fn finish(self, result: Result<()>) -> Result<Vec<(usize, AccelStruct)>> {
        if let Some(s) = self.scratch {
            self.heap.free(s);
        }
        match result {
            Ok(()) => Ok(self.out),
            Err(e) => {
                for a in self.in_flight {
                    a.release(self.heap);
                }
                for (_, a) in self.out {
                    a.release(self.heap);
                }
                Err(e)
            }
        }
    }
}

#[cfg(test)]
mod tests;
