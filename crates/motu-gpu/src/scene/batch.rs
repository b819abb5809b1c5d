//! Build batching: batches planned under the scratch budget, staged one ahead of the GPU and
//! compacted before the next.

use std::time::Instant;

use ash::vk;
use motu_alloc::{plan_build_batches, AllocKind, BatchLimits, BuildSize, MemoryClass};

use super::{AccelStruct, BuildOptions, Pending, ResourceReport, SizeQueries};
use crate::command::{memory_barrier, MemoryScope};
use crate::context::Context;
use crate::error::{GpuError, Result};
use crate::heap::GpuHeap;
use crate::memory::BufferUsage;

/// Build inputs staged one batch ahead: `stage` loads batch k+1's inputs into host-visible
/// staging while batch k builds on the GPU; `record` puts the staged copies into the batch's
/// own command buffer, ahead of its build.
pub(crate) trait BatchStager {
    /// Loads and stages the inputs of builds `builds`; returns the bytes staged and the time
    /// spent blocked on the GPU (a full ring region flushes behind the batch in flight). Runs
    /// while the previous batch may still be on the GPU, so it must not touch its resources.
    fn stage(&mut self, builds: std::ops::Range<usize>) -> Result<(u64, std::time::Duration)>;
    /// Records the staged copies into `cmd`; returns whether anything was recorded.
    ///
    /// # Safety
    /// `cmd` is recording on `device`; the caller waits on its submission before the staged
    /// region is reused and before any destination is freed.
    unsafe fn record(&mut self, device: &ash::Device, cmd: vk::CommandBuffer) -> bool;
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
pub(crate) fn build_batched<'g>(
    ctx: &Context,
    heap: &mut GpuHeap,
    report: &mut ResourceReport,
    sizes: &[BuildSize],
    ty: vk::AccelerationStructureTypeKHR,
    opts: &BuildOptions,
    geometry: impl Fn(usize) -> (Vec<vk::AccelerationStructureGeometryKHR<'g>>, Vec<u32>),
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
pub(crate) fn build_pipelined<'g>(
    ctx: &Context,
    heap: &mut GpuHeap,
    report: &mut ResourceReport,
    sizes: &[BuildSize],
    ty: vk::AccelerationStructureTypeKHR,
    opts: &BuildOptions,
    geometry: impl Fn(usize) -> (Vec<vk::AccelerationStructureGeometryKHR<'g>>, Vec<u32>),
    mut prepare: impl FnMut(&mut GpuHeap, std::ops::Range<usize>) -> Result<()>,
    mut stager: Option<&mut dyn BatchStager>,
    inputs_done: &mut dyn FnMut(&mut GpuHeap),
) -> Result<Vec<(usize, AccelStruct)>> {
    if sizes.is_empty() {
        return Ok(Vec::new());
    }
    let accel = ctx.accel_device()?;
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
            return Err(e);
        }
    };
    // Freed once the last batch is built (before its compaction), else at the end.
    let mut scratch = Some(pool);
    let mut out: Vec<(usize, AccelStruct)> = Vec::with_capacity(sizes.len());
    let mut in_flight: Vec<AccelStruct> = Vec::new();
    let result = (|| -> Result<()> {
        let scratch_base = scratch_address.div_ceil(scratch_align) * scratch_align;
        let (kind, flags) = if ty == vk::AccelerationStructureTypeKHR::TOP_LEVEL {
            (
                "tlas",
                crate::accel::AsBuildFlags::tlas(opts.compact).to_vk(),
            )
        } else {
            ("blas", opts.blas_build.flags().to_vk())
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
                        return Err(e);
                    }
                }
            }
            // From here on a failure releases this batch through `in_flight`.
            let pending_ref = &pending;
            let run = (|| -> Result<Vec<AccelStruct>> {
                let descs: Vec<_> = batch.builds.clone().map(&geometry).collect();
                let ranges: Vec<Vec<vk::AccelerationStructureBuildRangeInfoKHR>> = descs
                    .iter()
                    .map(|(_, counts)| {
                        counts
                            .iter()
                            .map(|&n| {
                                vk::AccelerationStructureBuildRangeInfoKHR::default()
                                    .primitive_count(n)
                            })
                            .collect()
                    })
                    .collect();
                let infos: Vec<_> = descs
                    .iter()
                    .zip(pending_ref)
                    .map(|((g, _), p)| {
                        vk::AccelerationStructureBuildGeometryInfoKHR::default()
                            .ty(ty)
                            // The flags the sizes were queried with.
                            .flags(flags)
                            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
                            .dst_acceleration_structure(p.accel.handle)
                            .geometries(g)
                            .scratch_data(vk::DeviceOrHostAddressKHR {
                                device_address: scratch_base + plan.scratch_offsets_bytes[p.index],
                            })
                    })
                    .collect();
                let range_refs: Vec<&[vk::AccelerationStructureBuildRangeInfoKHR]> =
                    ranges.iter().map(|r| r.as_slice()).collect();
                // Compacted sizes are asked only of structures built to be compacted.
                let queries = if opts.compact {
                    Some(SizeQueries::new(ctx, pending_ref.len() as u32)?)
                } else {
                    None
                };
                let handles: Vec<_> = pending_ref.iter().map(|p| p.accel.handle).collect();
                let rec = ctx.record(&format!("{kind} build batch {bi}"))?;
                let (c, cmd) = rec.raw();
                let device = &c.shared.device;
                // SAFETY: recording state; destinations, scratch slices (disjoint, aligned),
                // inputs, staged copies and the query pool live until the submission below is
                // waited on (also on every error path: `Submitted` waits when dropped).
                unsafe {
                    if let Some(st) = stager.as_deref_mut() {
                        if st.record(device, cmd) {
                            // Staged geometry copies before the builds read them.
                            memory_barrier(device, cmd, TRANSFER_WRITES, BUILD_READS);
                        }
                    }
                    // Coarse: builds are few and large.
                    memory_barrier(device, cmd, MemoryScope::ALL, MemoryScope::ALL);
                    accel.cmd_build_acceleration_structures(cmd, &infos, &range_refs);
                    memory_barrier(device, cmd, MemoryScope::ALL, MemoryScope::ALL);
                    if let Some(q) = &queries {
                        device.cmd_reset_query_pool(cmd, q.pool, 0, q.count);
                        accel.cmd_write_acceleration_structures_properties(
                            cmd,
                            &handles,
                            vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
                            q.pool,
                            0,
                        );
                    }
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
                        Err(GpuError::Budget(msg)) => {
                            // No room for both copies: the uncompacted ones are valid as they
                            // are, and the budget holds.
                            tracing::debug!(%msg, "compaction skipped under the budget");
                            copies.into_iter().for_each(|c| c.release(heap));
                            return Ok(Vec::new());
                        }
                        Err(e) => {
                            copies.into_iter().for_each(|c| c.release(heap));
                            return Err(e);
                        }
                    }
                }
                let rec = match ctx.record(&format!("{kind} compaction batch {bi}")) {
                    Ok(r) => r,
                    Err(e) => {
                        copies.into_iter().for_each(|c| c.release(heap));
                        return Err(e);
                    }
                };
                let (_, cmd) = rec.raw();
                for (p, dst) in pending_ref.iter().zip(&copies) {
                    let info = vk::CopyAccelerationStructureInfoKHR::default()
                        .src(p.accel.handle)
                        .dst(dst.handle)
                        .mode(vk::CopyAccelerationStructureModeKHR::COMPACT);
                    // SAFETY: both structures live until the fenced submission returns; the
                    // source was built with ALLOW_COMPACTION and dst holds its compacted size.
                    unsafe { accel.cmd_copy_acceleration_structure(cmd, &info) };
                }
                if let Err(e) = rec.submit_and_wait() {
                    copies.into_iter().for_each(|c| c.release(heap));
                    return Err(e);
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

const TRANSFER_WRITES: MemoryScope = MemoryScope {
    stages: vk::PipelineStageFlags::TRANSFER,
    access: vk::AccessFlags::TRANSFER_WRITE,
};

const BUILD_READS: MemoryScope = MemoryScope {
    stages: vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR,
    access: vk::AccessFlags::from_raw(
        vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR.as_raw()
            | vk::AccessFlags::SHADER_READ.as_raw(),
    ),
};

#[cfg(test)]
mod tests {
    use motu_alloc::{AllocKind, BuildSize, MemoryClass};

    use super::build_batched;
    use crate::accel::BlasGeometry;
    use crate::context::Requirement;
    use crate::heap::GpuHeap;
    use crate::memory::BufferUsage;
    use crate::scene::{BuildOptions, ResourceReport};
    use crate::testing::{assert_no_validation_errors, context_or_skip, test_heap};
    use ash::vk;

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
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
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
