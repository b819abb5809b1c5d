//! Build batching: batches planned under the scratch budget, staged one ahead of the GPU and
//! compacted before the next.

use std::time::Instant;

use motu_alloc::{plan_build_batches, AllocKind, BatchLimits, BuildSize, MemoryClass};
use motu_vk::{
    AsBuild, AsBuildFlags, AsBuildMode, AsCopyMode, AsGeometry, AsLevel, BufferUsage,
    CommandRecorder, Context, GpuHeap, MemoryScope,
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
    mut prepare: impl FnMut(&mut GpuHeap, std::ops::Range<usize>) -> Result<()>,
    mut stager: Option<&mut dyn BatchStager>,
    inputs_done: &mut dyn FnMut(&mut GpuHeap),
) -> Result<Vec<(usize, AccelStruct)>> {
    if sizes.is_empty() {
        return Ok(Vec::new());
    }
    let scratch_align = ctx.limits().scratch_alignment_bytes();
    let plan = plan_build_batches(
        sizes,
        BatchLimits {
            scratch_budget_bytes: opts.scratch_budget_bytes,
            scratch_alignment_bytes: scratch_align,
            scratch_pool_max_bytes: heap.limits().budget_bytes,
            max_batch_result_bytes: Some(opts.max_batch_result_bytes),
        },
    )
    .map_err(|e| GpuError::Budget(e.to_string()))?;
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
    // Freed once the last batch is built (before its compaction), else at the end.
    let mut scratch = Some(pool);
    let mut out: Vec<(usize, AccelStruct)> = Vec::with_capacity(sizes.len());
    let mut in_flight: Vec<AccelStruct> = Vec::new();
    let result = (|| -> Result<()> {
        let scratch_base = scratch_address.div_ceil(scratch_align) * scratch_align;
        let (kind, flags) = match ty {
            AsLevel::Top => ("tlas", AsBuildFlags::tlas(opts.compact)),
            AsLevel::Bottom => ("blas", opts.blas_build.flags()),
        };
        if let (Some(st), Some(first)) = (stager.as_deref_mut(), plan.batches.first()) {
            st.stage(first.builds.clone())?;
        }
        for (bi, batch) in plan.batches.iter().enumerate() {
            report.build_batches += 1;
            prepare(heap, batch.builds.clone())?;
            let mut pending: Vec<Pending> = Vec::new();
            for k in batch.builds.clone() {
                match AccelStruct::new(ctx, heap, &format!("{kind}-{k}"), sizes[k].result_bytes, ty)
                {
                    Ok(a) => pending.push(Pending { accel: a, index: k }),
                    Err(e) => {
                        in_flight.extend(pending.into_iter().map(|p| p.accel));
                        return Err(e.into());
                    }
                }
            }
            // From here on a failure releases this batch through `in_flight`.
            let pending_ref = &pending;
            let run = (|| -> Result<Vec<AccelStruct>> {
                let descs: Vec<_> = batch.builds.clone().map(&geometry).collect();
                let builds: Vec<AsBuild<'_>> = descs
                    .iter()
                    .zip(pending_ref)
                    .map(|((g, counts), p)| AsBuild {
                        level: ty,
                        // The flags the sizes were queried with.
                        flags,
                        mode: AsBuildMode::Build,
                        dst: p.accel.target(),
                        geometries: g,
                        primitive_counts: counts,
                        scratch_address: scratch_base + plan.scratch_offsets_bytes[p.index],
                    })
                    .collect();
                // Compacted sizes are asked only of structures built to be compacted.
                let queries = if opts.compact {
                    Some(SizeQueries::new(ctx, pending_ref.len() as u32)?)
                } else {
                    None
                };
                let targets: Vec<_> = pending_ref.iter().map(|p| p.accel.target()).collect();
                // Destinations, scratch slices (disjoint, aligned), inputs, staged copies and
                // the query pool live until the submission below is waited on (also on every
                // error path: `Submitted` waits when dropped).
                let mut rec = ctx.record(&format!("{kind} build batch {bi}"))?;
                if let Some(st) = stager.as_deref_mut() {
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
                let submitted = rec.submit()?;
                // While the GPU builds this batch, load and stage the next one.
                if let (Some(st), Some(next)) = (stager.as_deref_mut(), plan.batches.get(bi + 1)) {
                    let t = Instant::now();
                    match st.stage(next.builds.clone()) {
                        Ok((bytes, stalled)) => {
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
                if bi + 1 == plan.batches.len() {
                    // Built: no batch reads the scratch or the inputs any more, and the
                    // compacted copies below need room of their own.
                    if let Some(s) = scratch.take() {
                        heap.free(s);
                    }
                    inputs_done(heap);
                }
                let Some(queries) = queries else {
                    return Ok(Vec::new());
                };
                let compacted = queries.read(pending_ref.len() as u32)?;
                // Nothing to gain (lavapipe reports the built size): keep the originals and
                // skip the copies' second allocation, which would double the peak.
                if pending_ref
                    .iter()
                    .zip(&compacted)
                    .all(|(p, &size)| size.max(1) >= p.accel.size_bytes)
                {
                    return Ok(Vec::new());
                }
                let mut copies = Vec::with_capacity(pending_ref.len());
                for (p, &size) in pending_ref.iter().zip(&compacted) {
                    let size = size.max(1).min(p.accel.size_bytes);
                    match AccelStruct::new(
                        ctx,
                        heap,
                        &format!("{kind}-{}-compact", p.index),
                        size,
                        ty,
                    ) {
                        Ok(a) => copies.push(a),
                        Err(motu_vk::VkError::Budget(msg)) => {
                            // No room for both copies: the uncompacted ones are valid as they
                            // are, and the budget holds.
                            tracing::debug!(%msg, "compaction skipped under the budget");
                            copies.into_iter().for_each(|c| c.release(heap));
                            return Ok(Vec::new());
                        }
                        Err(e) => {
                            copies.into_iter().for_each(|c| c.release(heap));
                            return Err(e.into());
                        }
                    }
                }
                let mut rec = match ctx.record(&format!("{kind} compaction batch {bi}")) {
                    Ok(r) => r,
                    Err(e) => {
                        copies.into_iter().for_each(|c| c.release(heap));
                        return Err(e.into());
                    }
                };
                // Both structures live until the fenced submission returns; the source was
                // built with compaction allowed and dst holds its compacted size.
                let copied = pending_ref.iter().zip(&copies).try_for_each(|(p, dst)| {
                    rec.copy_acceleration_structure(
                        p.accel.target(),
                        dst.target(),
                        AsCopyMode::Compact,
                    )
                });
                if let Err(e) = copied.and_then(|()| rec.submit_and_wait()) {
                    copies.into_iter().for_each(|c| c.release(heap));
                    return Err(e.into());
                }
                Ok(copies)
            })();
            match run {
                Ok(copies) if copies.is_empty() => {
                    out.extend(pending.into_iter().map(|p| (p.index, p.accel)));
                }
                Ok(copies) => {
                    for (p, dst) in pending.into_iter().zip(copies) {
                        p.accel.release(heap);
                        out.push((p.index, dst));
                    }
                }
                Err(e) => {
                    in_flight.extend(pending.into_iter().map(|p| p.accel));
                    return Err(e);
                }
            }
        }
        Ok(())
    })();
    if let Some(s) = scratch {
        heap.free(s);
    }
    match result {
        Ok(()) => Ok(out),
        Err(e) => {
            for a in in_flight {
                a.release(heap);
            }
            for (_, a) in out {
                a.release(heap);
            }
            Err(e)
        }
    }
}

#[cfg(test)]
mod tests {
    use motu_alloc::{AllocKind, BuildSize, MemoryClass};

    use super::build_batched;
    use crate::scene::{BuildOptions, ResourceReport};
    use crate::testing::{assert_no_validation_errors, context_or_skip, test_heap};
    use motu_vk::AsLevel;
    use motu_vk::BlasGeometry;
    use motu_vk::BufferUsage;
    use motu_vk::GpuHeap;
    use motu_vk::Requirement;

    fn scratch_bytes(heap: &GpuHeap) -> u64 {
        heap.report()
            .kinds
            .get(&AllocKind::Scratch)
            .map_or(0, |k| k.bytes)
    }

    /// `inputs_done` runs once, after the last batch is built, with the scratch pool already
    /// freed: the inputs it frees and the scratch never stack on the compacted copies.
    #[test]
    fn inputs_are_released_once_the_last_batch_is_built() {
        let Some(ctx) = context_or_skip("inputs_done", Requirement::RayTracing) else {
            return;
        };
        let mut heap = test_heap(&ctx, 64 << 20);
        // Three BLASes of 8 boxes each, one batch each.
        let boxes: Vec<[f32; 6]> = (0..24)
            .map(|i| {
                let x = i as f32;
                [x, 0.0, 0.0, x + 0.5, 1.0, 1.0]
            })
            .collect();
        let input = heap
            .alloc_buffer(
                "aabbs",
                (boxes.len() * 24) as u64,
                BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT,
                AllocKind::Geometry,
                MemoryClass::HostVisible,
                16,
            )
            .expect("input");
        input.write(0, &boxes).expect("write boxes");
        let base = input.device_address().expect("address").0;
        let shape = [BlasGeometry::Aabbs {
            aabb_count: 8,
            opaque: true,
        }];
        let opts = BuildOptions {
            max_batch_result_bytes: 1,
            ..Default::default()
        };
        let sz = ctx
            .blas_build_sizes(&shape, opts.blas_build.flags())
            .expect("sizes");
        let sizes = vec![
            BuildSize {
                result_bytes: sz.acceleration_structure_size_bytes,
                scratch_bytes: sz.build_scratch_size_bytes,
            };
            3
        ];
        let mut input = Some(input);
        let prepared = std::cell::Cell::new(0u32);
        let mut done_calls = 0u32;
        let mut scratch_while_preparing = 0u64;
        let mut scratch_when_done = u64::MAX;
        let mut report = ResourceReport::default();
        let built = build_batched(
            &ctx,
            &mut heap,
            &mut report,
            &sizes,
            AsLevel::Bottom,
            &opts,
            |k| {
                (
                    vec![crate::scene::aabbs_geometry(base + k as u64 * 8 * 24, true)],
                    vec![8],
                )
            },
            |heap, _| {
                prepared.set(prepared.get() + 1);
                scratch_while_preparing = scratch_while_preparing.max(scratch_bytes(heap));
                Ok(())
            },
            &mut |heap| {
                done_calls += 1;
                assert_eq!(
                    prepared.get(),
                    3,
                    "every batch prepared before the inputs go"
                );
                scratch_when_done = scratch_bytes(heap);
                if let Some(b) = input.take() {
                    heap.free(b);
                }
            },
        )
        .expect("build");
        assert_eq!(report.build_batches, 3);
        assert_eq!(done_calls, 1);
        assert!(input.is_none(), "the inputs were released by the callback");
        assert!(
            scratch_while_preparing > 0,
            "the scratch pool lives while batches build"
        );
        assert_eq!(
            scratch_when_done, 0,
            "the scratch pool is freed before the inputs"
        );
        assert_eq!(built.len(), 3);
        for (_, a) in built {
            a.release(&mut heap);
        }
        assert_eq!(
            heap.report().budget_in_use_bytes,
            0,
            "nothing left allocated"
        );
        assert_no_validation_errors(&ctx);
    }
}
