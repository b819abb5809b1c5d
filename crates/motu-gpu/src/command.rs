//! One-shot command recording and fenced submission.
//!
//! A [`CommandRecorder<'a>`] borrows every resource it records for `'a` and executes only in
//! [`CommandRecorder::submit_and_wait`], which blocks on a fence: so no resource can be dropped
//! while the GPU uses it, without reference counting. (Overlapping asynchronous submissions are
//! for the upload/build layer to add on top: they need owned resources.)

use std::marker::PhantomData;

use ash::vk;

use crate::context::Context;
use crate::error::{GpuError, Result};
use crate::memory::{Buffer, BufferUsage};
use crate::pipeline::{BindingSet, ComputePipeline};
use crate::query::TimestampQueries;

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
            .map_err(GpuError::vk("vkCreateCommandPool"))?;
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
            .map_err(GpuError::vk("vkAllocateCommandBuffers"))?[0];
        self.shared.set_name(rec.cmd, label);
        // SAFETY: valid default fence create info.
        rec.fence = unsafe { device.create_fence(&vk::FenceCreateInfo::default(), None) }
            .map_err(GpuError::vk("vkCreateFence"))?;
        let begin = vk::CommandBufferBeginInfo::default()
            .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT);
        // SAFETY: the command buffer is in the initial state and owned by `rec`.
        unsafe { device.begin_command_buffer(rec.cmd, &begin) }
            .map_err(GpuError::vk("vkBeginCommandBuffer"))?;
        Ok(rec)
    }
}

impl<'a> CommandRecorder<'a> {
    fn device(&self) -> &ash::Device {
        &self.ctx.shared.device
    }

    /// The raw command buffer, for recording commands this module has no safe wrapper for.
    /// Callers must keep every resource they record alive until `submit_and_wait` returns.
    pub(crate) fn raw(&self) -> (&'a Context, vk::CommandBuffer) {
        (self.ctx, self.cmd)
    }

    /// The phase label given to [`Context::record`].
    pub fn label(&self) -> &str {
        &self.label
    }

    fn check_buffer(&self, buffer: &Buffer, usage: BufferUsage, what: &str) -> Result<()> {
        if !buffer.same_device(&self.ctx.shared) {
            return Err(GpuError::InvalidRequest(format!(
                "{}: buffer {:?} belongs to another device",
                self.label,
                buffer.label()
            )));
        }
        buffer.check_bound()?;
        if !buffer.usage().contains(usage) {
            return Err(GpuError::InvalidRequest(format!(
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
            return Err(GpuError::InvalidRequest(format!(
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
            return Err(GpuError::InvalidRequest(format!(
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
        unsafe { memory_barrier(self.device(), self.cmd, MemoryScope::ALL, MemoryScope::ALL) };
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
            return Err(GpuError::InvalidRequest(format!(
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
    pub(crate) fn submit(mut self) -> Result<Submitted<'a>> {
        let span = tracing::debug_span!("submit", label = %self.label);
        let _g = span.enter();
        let device = &self.ctx.shared.device;
        // SAFETY: the command buffer is in the recording state.
        unsafe { device.end_command_buffer(self.cmd) }
            .map_err(GpuError::vk("vkEndCommandBuffer"))?;
        let cmds = [self.cmd];
        let submit = vk::SubmitInfo::default().command_buffers(&cmds);
        {
            let queue = self.ctx.shared.queue();
            // SAFETY: the queue is externally synchronised by its lock; the command buffer is
            // executable and every resource it references outlives 'a (borrowed by self).
            unsafe { device.queue_submit(*queue, &[submit], self.fence) }.map_err(|result| {
                tracing::error!(label = %self.label, ?result, "submission failed");
                GpuError::Vulkan {
                    call: "vkQueueSubmit",
                    result,
                }
            })?;
        }
        self.submitted = true;
        Ok(Submitted { rec: self })
    }
}

/// A submitted command buffer whose fence has not been waited on yet.
#[derive(Debug)]
pub(crate) struct Submitted<'a> {
    rec: CommandRecorder<'a>,
}

impl Submitted<'_> {
    /// Waits on the submission's fence (not on the queue).
    pub(crate) fn wait(self) -> Result<()> {
        let device = &self.rec.ctx.shared.device;
        // SAFETY: the fence was submitted by `CommandRecorder::submit`.
        unsafe { device.wait_for_fences(&[self.rec.fence], true, u64::MAX) }.map_err(|result| {
            // Name the phase, not just the code (VK_ERROR_DEVICE_LOST otherwise says nothing).
            tracing::error!(label = %self.rec.label, ?result, "waiting for the submission failed");
            GpuError::from_submit("vkWaitForFences", result, &self.rec.label)
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

/// One side of a global memory barrier: the pipeline stages and the accesses it orders.
#[derive(Clone, Copy, Debug)]
pub(crate) struct MemoryScope {
    pub stages: vk::PipelineStageFlags,
    pub access: vk::AccessFlags,
}

impl MemoryScope {
    /// Every stage, every write before / every read and write after.
    pub const ALL: Self = Self {
        stages: vk::PipelineStageFlags::ALL_COMMANDS,
        access: vk::AccessFlags::from_raw(
            vk::AccessFlags::MEMORY_WRITE.as_raw() | vk::AccessFlags::MEMORY_READ.as_raw(),
        ),
    };
}

/// Records one global memory barrier from `src` to `dst` (the one place every barrier of the
/// crate is written; global barriers name no resource, so they cannot outlive one).
///
/// # Safety
/// `cmd` must be in the recording state on `device`.
pub(crate) unsafe fn memory_barrier(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    src: MemoryScope,
    dst: MemoryScope,
) {
    // A write-only source mask: reads need no availability operation.
    let src_access = src.access & !(vk::AccessFlags::MEMORY_READ);
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(src_access)
        .dst_access_mask(dst.access);
    // SAFETY: per the function contract; a global memory barrier has no resource references.
    unsafe {
        device.cmd_pipeline_barrier(
            cmd,
            src.stages,
            dst.stages,
            vk::DependencyFlags::empty(),
            &[barrier],
            &[],
            &[],
        )
    };
}
