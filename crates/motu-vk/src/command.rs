//! One-shot command recording and fenced submission.
//!
//! A [`CommandRecorder<'a>`] borrows every resource it records by reference for `'a` and
//! executes only in [`CommandRecorder::submit_and_wait`] (or [`CommandRecorder::submit`] and
//! [`Submitted::wait`]), which block on a fence: so no such resource can be dropped while the
//! GPU uses it, without reference counting.
//!
//! The build layer's commands name some resources by token instead ([`BufferTarget`],
//! [`AsTarget`]: staged copies, acceleration-structure builds and copies, compacted-size
//! queries), because the structures and buffers they touch belong to tables the caller keeps
//! mutating between batches. Those tokens do not borrow: the caller keeps what they name alive
//! until the submission was waited on (the scene and the streamer free structures and buffers
//! only after fenced submissions). Every command is typed: the layers above never see a
//! command buffer.

use std::marker::PhantomData;
use std::sync::atomic::Ordering;

use ash::vk;

use crate::accel::{AsBuild, AsBuildMode, AsCopyMode, AsGeometry, AsLevel, AsTarget};
use crate::barrier::MemoryScope;
use crate::context::Context;
use crate::conv;
use crate::error::{Result, VkError};
use crate::memory::{Buffer, BufferUsage};
use crate::pipeline::{BindingSet, ComputePipeline};
use crate::query::TimestampQueries;
use crate::rt_pipeline::{rt_stages, RtPipeline};
use crate::structure::SizeQueries;

/// Records one command buffer; see the module docs for the lifetime contract.
pub struct CommandRecorder<'a> {
    ctx: &'a Context,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    label: String,
    submitted: bool,
    _resources: PhantomData<&'a ()>,
}

impl std::fmt::Debug for CommandRecorder<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CommandRecorder")
            .field("label", &self.label)
            .finish()
    }
}

impl Context {
    /// Starts recording a one-shot command buffer. `label` names the phase in logs and errors.
    pub fn record(&self, label: &str) -> Result<CommandRecorder<'_>> {
        let device = &self.shared.device;
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(self.shared.queue_family_index)
            .flags(vk::CommandPoolCreateFlags::TRANSIENT);
        // A transient pool per recorder: pools are externally synchronised, so one per
        // recorder lets threads record concurrently without locks.
        // SAFETY: valid create info for this device's queue family.
        let pool = unsafe { device.create_command_pool(&pool_info, None) }
            .map_err(VkError::vk("vkCreateCommandPool"))?;
        let mut rec = CommandRecorder {
            ctx: self,
            pool,
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            label: label.to_string(),
            submitted: false,
            _resources: PhantomData,
        };
        let alloc = vk::CommandBufferAllocateInfo::default()
            .command_pool(pool)
            .level(vk::CommandBufferLevel::PRIMARY)
            .command_buffer_count(1);
        // SAFETY: the pool was just created and is owned by `rec` (freed in its Drop).
        rec.cmd = unsafe { device.allocate_command_buffers(&alloc) }
            .map_err(VkError::vk("vkAllocateCommandBuffers"))?[0];
        self.shared.set_name(rec.cmd, label);
        // SAFETY: valid default fence create info.
        rec.fence = unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) }
            .map_err(VkError::vk("vkCreateFence"))?;
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the command buffer is in the initial state and owned by `rec`.
        unsafe { device.begin_command_buffer(rec.cmd, &begin) }
            .map_err(VkError::vk("vkBeginCommandBuffer"))?;
        Ok(rec)
    }
}

impl<'a> CommandRecorder<'a> {
    fn device(&self) -> &ash::Device {
        &self.ctx.shared.device
    }

    /// The phase label given to [`Context::record`].
    pub fn label(&self) -> &str {
        &self.label
    }

    fn check_buffer(&self, buffer: &Buffer, usage: BufferUsage, what: &str) -> Result<()> {
        if !buffer.same_device(&self.ctx.shared) {
            return Err(VkError::InvalidRequest(format!(
                "{}: buffer {:?} belongs to another device",
                self.label,
                buffer.label()
            )));
        }
        buffer.check_bound()?;
        if !buffer.usage().contains(usage) {
            return Err(VkError::InvalidRequest(format!(
                "{}: buffer {:?} lacks the usage {what} needs",
                self.label,
                buffer.label()
            )));
        }
        Ok(())
    }

    /// Copies `size_bytes` from `src` at `src_offset` to `dst` at `dst_offset`.
    pub fn copy_buffer(
        &mut self,
        src: &'a Buffer,
        src_offset: u64,
        dst: &'a Buffer,
        dst_offset: u64,
        size_bytes: u64,
    ) -> Result<()> {
        self.check_buffer(src, BufferUsage::TRANSFER_SRC, "a copy source")?;
        self.check_buffer(dst, BufferUsage::TRANSFER_DST, "a copy destination")?;
        let fits = |off: u64, b: &Buffer| {
            off.checked_add(size_bytes)
                .is_some_and(|e| e <= b.size_bytes())
        };
        if size_bytes == 0 || !fits(src_offset, src) || !fits(dst_offset, dst) {
            return Err(VkError::InvalidRequest(format!(
                "{}: copy of {size_bytes} bytes from {:?}+{src_offset} to {:?}+{dst_offset} is out of range",
                self.label,
                src.label(),
                dst.label()
            )));
        }
        let region = vk::BufferCopy {
            src_offset,
            dst_offset,
            size: size_bytes,
        };
        // SAFETY: recording state; both buffers are bound, have transfer usages and the
        // ranges are in bounds (checked above); they outlive the submission ('a).
        unsafe {
            self.device()
                .cmd_copy_buffer(self.cmd, src.handle(), dst.handle(), &[region])
        };
        Ok(())
    }

    /// Fills `size_bytes` (a multiple of 4) at `offset` with the 32-bit `value`.
    pub fn fill_buffer(
        &mut self,
        dst: &'a Buffer,
        offset: u64,
        size_bytes: u64,
        value: u32,
    ) -> Result<()> {
        self.check_buffer(dst, BufferUsage::TRANSFER_DST, "a fill")?;
        if offset % 4 != 0
            || size_bytes % 4 != 0
            || size_bytes == 0
            || offset
                .checked_add(size_bytes)
                .is_none_or(|e| e > dst.size_bytes())
        {
            return Err(VkError::InvalidRequest(format!(
                "{}: fill of {size_bytes} bytes at {offset} in {:?} is misaligned or out of range",
                self.label,
                dst.label()
            )));
        }
        // SAFETY: recording state; bound buffer with TRANSFER_DST; range checked above.
        unsafe {
            self.device()
                .cmd_fill_buffer(self.cmd, dst.handle(), offset, size_bytes, value)
        };
        Ok(())
    }

    /// A full memory barrier between everything before and after it. Coarse but always
    /// correct; fine-grained barriers come with the build/render passes that need them.
    pub fn barrier(&mut self) {
        // SAFETY: recording state (a recorder only exists while its buffer records).
        unsafe { memory_barrier(self.device(), self.cmd, MemoryScope::All, MemoryScope::All) };
    }

    /// A global memory barrier ordering the `dst` work after the `src` work.
    pub fn memory_barrier(&mut self, src: MemoryScope, dst: MemoryScope) {
        // SAFETY: recording state (a recorder only exists while its buffer records).
        unsafe { memory_barrier(self.device(), self.cmd, src, dst) };
    }

    /// Copies `copies` from `src` (tokens, kept alive by the caller until the submission was
    /// waited on: see the module docs). Ranges and usages are checked against both buffers.
    pub fn copy_regions(&mut self, src: BufferTarget, copies: &[BufferCopy]) -> Result<()> {
        if !src.usage.contains(BufferUsage::TRANSFER_SRC) {
            return Err(VkError::InvalidRequest(format!(
                "{}: a copy source lacks TRANSFER_SRC",
                self.label
            )));
        }
        for c in copies {
            let in_range =
                |off: u64, size: u64| off.checked_add(c.size_bytes).is_some_and(|e| e <= size);
            if c.size_bytes == 0
                || !c.dst.usage.contains(BufferUsage::TRANSFER_DST)
                || !in_range(c.src_offset, src.size_bytes)
                || !in_range(c.dst_offset, c.dst.size_bytes)
            {
                return Err(VkError::InvalidRequest(format!(
                    "{}: copy of {} bytes from a buffer of {} bytes at {} to a buffer of {} bytes \
                     at {} is out of range or lacks TRANSFER_DST",
                    self.label,
                    c.size_bytes,
                    src.size_bytes,
                    c.src_offset,
                    c.dst.size_bytes,
                    c.dst_offset
                )));
            }
        }
        let device = self.device();
        for c in copies {
            let region = vk::BufferCopy {
                src_offset: c.src_offset,
                dst_offset: c.dst_offset,
                size: c.size_bytes,
            };
            // SAFETY: recording state; the tokens name live, bound buffers of this device (the
            // caller's contract, module docs) with the transfer usages; ranges checked above.
            unsafe { device.cmd_copy_buffer(self.cmd, src.handle, c.dst.handle, &[region]) };
        }
        Ok(())
    }

    /// Builds (or updates in place) every structure of `builds` in one command. Geometry
    /// kinds are checked against each build's level; the inputs at the geometries' addresses,
    /// the destinations and the scratch ranges are the caller's to keep alive and disjoint
    /// until the submission was waited on (module docs).
    pub fn build_acceleration_structures(&mut self, builds: &[AsBuild<'_>]) -> Result<()> {
        if builds.is_empty() {
            return Ok(());
        }
        let accel = self.ctx.accel_device()?;
        for (i, b) in builds.iter().enumerate() {
            let kinds_ok = match b.level {
                AsLevel::Top => {
                    b.geometries.len() == 1
                        && matches!(b.geometries[0], AsGeometry::Instances { .. })
                }
                AsLevel::Bottom => {
                    let tri = |g: &AsGeometry| matches!(g, AsGeometry::Triangles { .. });
                    !b.geometries.is_empty()
                        && b.geometries.iter().all(|g| {
                            !matches!(g, AsGeometry::Instances { .. })
                                && tri(g) == tri(&b.geometries[0])
                        })
                }
            };
            if !kinds_ok || b.geometries.len() != b.primitive_counts.len() {
                return Err(VkError::InvalidRequest(format!(
                    "{}: build {i} ({:?}) has {} geometries of the wrong kinds or {} counts",
                    self.label,
                    b.level,
                    b.geometries.len(),
                    b.primitive_counts.len()
                )));
            }
        }
        let geometries: Vec<Vec<vk::AccelerationStructureGeometryKHR<'static>>> = builds
            .iter()
            .map(|b| b.geometries.iter().map(conv::geometry).collect())
            .collect();
        let ranges: Vec<Vec<vk::AccelerationStructureBuildRangeInfoKHR>> = builds
            .iter()
            .map(|b| {
                b.primitive_counts
                    .iter()
                    .map(|&n| {
                        vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(n)
                    })
                    .collect()
            })
            .collect();
        let infos: Vec<vk::AccelerationStructureBuildGeometryInfoKHR<'_>> = builds
            .iter()
            .zip(&geometries)
            .map(|(b, g)| {
                let info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
                    .ty(conv::as_level(b.level))
                    .flags(conv::build_flags(b.flags))
                    .dst_acceleration_structure(b.dst.0)
                    .geometries(g)
                    .scratch_data(vk::DeviceOrHostAddressKHR {
                        device_address: b.scratch_address,
                    });
                match b.mode {
                    AsBuildMode::Build => info.mode(vk::BuildAccelerationStructureModeKHR::BUILD),
                    AsBuildMode::UpdateInPlace => info
                        .mode(vk::BuildAccelerationStructureModeKHR::UPDATE)
                        .src_acceleration_structure(b.dst.0),
                }
            })
            .collect();
        let range_refs: Vec<&[vk::AccelerationStructureBuildRangeInfoKHR]> =
            ranges.iter().map(|r| r.as_slice()).collect();
        // SAFETY: recording state; one range list per build with one entry per geometry
        // (checked above); destinations, inputs and scratch are live and disjoint until the
        // submission was waited on (the caller's contract, module docs); an in-place update
        // reads and writes the same structure, which the spec allows.
        unsafe { accel.cmd_build_acceleration_structures(self.cmd, &infos, &range_refs) };
        Ok(())
    }

    /// Resets `queries` and writes the compacted sizes of `structures` (built with
    /// `allow_compaction`, and complete: record a barrier after their builds) into its first
    /// queries, in order.
    pub fn write_compacted_sizes(
        &mut self,
        structures: &[AsTarget],
        queries: &SizeQueries,
    ) -> Result<()> {
        self.write_structure_properties(
            structures,
            queries,
            vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
        )
    }

    /// Resets `queries` (of `kind`) and writes that property of `structures` into its first
    /// queries.
    pub(crate) fn write_structure_properties(
        &mut self,
        structures: &[AsTarget],
        queries: &SizeQueries,
        kind: vk::QueryType,
    ) -> Result<()> {
        if structures.len() as u64 > u64::from(queries.count) || queries.kind != kind {
            return Err(VkError::InvalidRequest(format!(
                "{}: {} sizes ({kind:?}) asked of {} queries of {:?}",
                self.label,
                structures.len(),
                queries.count,
                queries.kind
            )));
        }
        let accel = self.ctx.accel_device()?;
        let handles: Vec<vk::AccelerationStructureKHR> = structures.iter().map(|t| t.0).collect();
        // SAFETY: recording state; the pool belongs to this device, is of `kind` and holds
        // enough queries (checked above); it and the structures live until the submission was
        // waited on (the caller's contract, module docs).
        unsafe {
            self.device()
                .cmd_reset_query_pool(self.cmd, queries.pool, 0, queries.count);
            accel.cmd_write_acceleration_structures_properties(
                self.cmd,
                &handles,
                kind,
                queries.pool,
                0,
            );
        }
        Ok(())
    }

    pub(crate) fn ctx(&self) -> &Context {
        self.ctx
    }

    pub(crate) fn raw_cmd(&self) -> vk::CommandBuffer {
        self.cmd
    }

    /// Copies structure `src` into `dst` (`dst` sized for `mode`: the compacted size a query
    /// reported, or the source's size for a clone).
    pub fn copy_acceleration_structure(
        &mut self,
        src: AsTarget,
        dst: AsTarget,
        mode: AsCopyMode,
    ) -> Result<()> {
        let accel = self.ctx.accel_device()?;
        let info = vk::CopyAccelerationStructureInfoKHR::default()
            .src(src.0)
            .dst(dst.0)
            .mode(conv::copy_mode(mode));
        // SAFETY: recording state; both structures live until the submission was waited on
        // (the caller's contract, module docs); dst holds what `mode` needs.
        unsafe { accel.cmd_copy_acceleration_structure(self.cmd, &info) };
        Ok(())
    }

    /// Binds `pipeline`, pushes `push_constants` (at most its push-constant size) and traces
    /// a `dims` launch through its shader binding table.
    pub fn trace_rays(
        &mut self,
        pipeline: &'a RtPipeline,
        push_constants: &[u8],
        dims: [u32; 2],
    ) -> Result<()> {
        if push_constants.len() > crate::rt_pipeline::PUSH_CONSTANT_BYTES as usize {
            return Err(VkError::InvalidRequest(format!(
                "{}: {} bytes of push constants exceed the pipeline's {}",
                self.label,
                push_constants.len(),
                crate::rt_pipeline::PUSH_CONSTANT_BYTES
            )));
        }
        let device = self.device();
        let p = pipeline;
        // SAFETY: recording state; the pipeline, its layout and SBT outlive the submission
        // ('a); the push-constant range is within the layout's (checked above). The buffers
        // behind the pushed addresses are the caller's to keep alive (module docs).
        unsafe {
            device.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::RAY_TRACING_KHR, p.pipeline);
            device.cmd_push_constants(self.cmd, p.layout, rt_stages(), 0, push_constants);
            p.rt.cmd_trace_rays(
                self.cmd,
                &p.regions[0],
                &p.regions[1],
                &p.regions[2],
                &p.regions[3],
                dims[0],
                dims[1],
                1,
            );
        }
        Ok(())
    }

    /// Dispatches `group_count` workgroups of `pipeline` with `bindings` (its storage buffers,
    /// if the pipeline has any) and `push_constants` (exactly the pipeline's push-constant size).
    pub fn dispatch(
        &mut self,
        pipeline: &'a ComputePipeline,
        bindings: Option<&'a BindingSet<'a>>,
        push_constants: &[u8],
        group_count: [u32; 3],
    ) -> Result<()> {
        pipeline.check_dispatch(&self.ctx.shared, bindings, push_constants, group_count)?;
        let device = self.device();
        // SAFETY: recording state; pipeline, layout and descriptor set belong to this device and
        // match (checked by check_dispatch); the push-constant range matches the layout.
        unsafe {
            device.cmd_bind_pipeline(self.cmd, vk::PipelineBindPoint::COMPUTE, pipeline.handle());
            if let Some(set) = bindings {
                device.cmd_bind_descriptor_sets(
                    self.cmd,
                    vk::PipelineBindPoint::COMPUTE,
                    pipeline.layout(),
                    0,
                    &[set.handle()],
                    &[],
                );
            }
            if !push_constants.is_empty() {
                device.cmd_push_constants(
                    self.cmd,
                    pipeline.layout(),
                    vk::ShaderStageFlags::COMPUTE,
                    0,
                    push_constants,
                );
            }
            device.cmd_dispatch(self.cmd, group_count[0], group_count[1], group_count[2]);
        }
        Ok(())
    }

    /// Resets all queries of `pool` (record before writing timestamps into it).
    pub fn reset_queries(&mut self, pool: &'a TimestampQueries) {
        // SAFETY: recording state; the pool belongs to this device; full range.
        unsafe {
            self.device()
                .cmd_reset_query_pool(self.cmd, pool.handle(), 0, pool.count())
        };
    }

    /// Writes a timestamp into query `index` once all prior commands completed.
    pub fn write_timestamp(&mut self, pool: &'a TimestampQueries, index: u32) -> Result<()> {
        if index >= pool.count() {
            return Err(VkError::InvalidRequest(format!(
                "{}: timestamp index {index} out of range ({} queries)",
                self.label,
                pool.count()
            )));
        }
        // SAFETY: recording state; index in range; the queue supports timestamps (checked
        // when the pool was created).
        unsafe {
            self.device().cmd_write_timestamp(
                self.cmd,
                vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                pool.handle(),
                index,
            )
        };
        Ok(())
    }

    /// Ends recording, submits, and waits on the fence (not on the queue).
    pub fn submit_and_wait(self) -> Result<()> {
        self.submit()?.wait()
    }

    /// Ends recording and submits without waiting: the CPU goes on (e.g. stages the next build
    /// batch) while the GPU runs it. Callers keep every resource recorded alive until
    /// [`Submitted::wait`] returns; dropping a [`Submitted`] unwaited waits for the device.
    pub fn submit(mut self) -> Result<Submitted<'a>> {
        let span = tracing::debug_span!("submit", label = %self.label);
        let _g = span.enter();
        let device = &self.ctx.shared.device;
        // SAFETY: the command buffer is in the recording state.
        unsafe { device.end_command_buffer(self.cmd) }
            .map_err(VkError::vk("vkEndCommandBuffer"))?;
        let cmds = [self.cmd];
        let submit = vk::SubmitInfo::default().command_buffers(&cmds);
        {
            let queue = self.ctx.shared.queue();
            // SAFETY: the queue is externally synchronised by its lock; the command buffer is
            // executable and every resource it references outlives 'a (borrowed by self).
            unsafe { device.queue_submit(*queue, &[submit], self.fence) }.map_err(|result| {
                tracing::error!(label = %self.label, ?result, "submission failed");
                VkError::Vulkan {
                    call: "vkQueueSubmit",
                    result,
                }
            })?;
        }
        self.ctx.shared.submits.fetch_add(1, Ordering::Relaxed);
        self.submitted = true;
        Ok(Submitted { rec: self })
    }
}

/// A submitted command buffer whose fence has not been waited on yet.
#[derive(Debug)]
pub struct Submitted<'a> {
    rec: CommandRecorder<'a>,
}

impl Submitted<'_> {
    /// Waits on the submission's fence (not on the queue).
    pub fn wait(self) -> Result<()> {
        let device = &self.rec.ctx.shared.device;
        self.rec
            .ctx
            .shared
            .fence_waits
            .fetch_add(1, Ordering::Relaxed);
        // SAFETY: the fence was submitted by `CommandRecorder::submit`.
        unsafe { device.wait_for_fences(&[self.rec.fence], true, u64::MAX) }.map_err(|result| {
            // Name the phase, not just the code (VK_ERROR_DEVICE_LOST otherwise says nothing).
            tracing::error!(label = %self.rec.label, ?result, "waiting for the submission failed");
            VkError::from_submit("vkWaitForFences", result, &self.rec.label)
        })?;
        Ok(())
    }
}

impl Drop for CommandRecorder<'_> {
    fn drop(&mut self) {
        let device = &self.ctx.shared.device;
        // SAFETY: the command buffer must not be pending when its pool is destroyed: it was
        // either never submitted or its fence signalled; if waiting failed (device lost), wait
        // for the device before freeing.
        unsafe {
            if self.submitted && device.get_fence_status(self.fence) != Ok(true) {
                let _ = device.device_wait_idle();
            }
            if self.fence != vk::Fence::null() {
                device.destroy_fence(self.fence, None);
            }
            // Destroying the pool frees its command buffer.
            device.destroy_command_pool(self.pool, None);
        }
    }
}

/// A buffer named by a copy without borrowing it (see the module docs), with what the copy
/// checks: its size and usages.
#[derive(Clone, Copy, Debug)]
pub struct BufferTarget {
    handle: vk::Buffer,
    size_bytes: u64,
    usage: BufferUsage,
}

impl Buffer {
    /// The buffer as a copy token ([`CommandRecorder::copy_regions`]).
    pub fn target(&self) -> BufferTarget {
        BufferTarget {
            handle: self.handle(),
            size_bytes: self.size_bytes(),
            usage: self.usage(),
        }
    }
}

/// One region of [`CommandRecorder::copy_regions`].
#[derive(Clone, Copy, Debug)]
pub struct BufferCopy {
    pub dst: BufferTarget,
    pub src_offset: u64,
    pub dst_offset: u64,
    pub size_bytes: u64,
}

/// Records one global memory barrier from `src` to `dst` (the one place every barrier of the
/// crate is written; global barriers name no resource, so they cannot outlive one).
///
/// # Safety
/// `cmd` must be in the recording state on `device`.
unsafe fn memory_barrier(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    src: MemoryScope,
    dst: MemoryScope,
) {
    let (src_stages, src_access) = conv::memory_scope(src);
    let (dst_stages, dst_access) = conv::memory_scope(dst);
    // A write-only source mask: reads need no availability operation.
    let src_access = src_access & !(vk::AccessFlags::MEMORY_READ);
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(src_access)
        .dst_access_mask(dst_access);
    // SAFETY: per the function contract; a global memory barrier has no resource references.
    unsafe {
        device.cmd_pipeline_barrier(
            cmd,
            src_stages,
            dst_stages,
            vk::DependencyFlags::empty(),
            &[barrier],
            &[],
            &[],
        )
    };
}
