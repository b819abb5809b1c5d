//! Recording a presented frame: the copy into the swapchain image, its read-back and the
//! transition to presentation (or the panel's pass).

use ash::vk;

use super::{FrameCopy, Presenter};
use crate::error::{Result, VkError};
use crate::panel::PanelPaint;

impl Presenter {
    /// Records the frame's copy into swapchain image `index`, its read-back, the panel and the
    /// transition to presentation.
    pub(super) fn record(
        &mut self,
        frame: &FrameCopy,
        index: u32,
        panel: Option<&PanelPaint<'_>>,
    ) -> Result<()> {
        let ctx = self.ctx.clone();
        let device = &ctx.shared.device;
        let [ew, eh] = self.extent;
        let image = self.images[index as usize];
        let cmd = self.cmd;
        let upload = self
            .upload
            .as_ref()
            .ok_or_else(|| VkError::InvalidRequest("present: no upload buffer".into()))?;
        let layers = vk::ImageSubresourceLayers::default()
            .aspect_mask(vk::ImageAspectFlags::COLOR)
            .layer_count(1);
        let copy = vk::BufferImageCopy::default()
            .buffer_row_length(frame.width)
            .buffer_image_height(frame.height)
            .image_subresource(layers)
            .image_extent(vk::Extent3D {
                width: frame.width.min(ew),
                height: frame.height.min(eh),
                depth: 1,
            });
        // SAFETY: the command buffer is not pending (the last submission was fenced); the image
        // was acquired (its semaphore is waited on by the submission); the buffers live in
        // `self` until the fence wait in `submit_and_present`.
        unsafe {
            device
                .reset_command_buffer(cmd, vk::CommandBufferResetFlags::empty())
                .map_err(VkError::vk("vkResetCommandBuffer"))?;
            device
                .begin_command_buffer(
                    cmd,
                    &vk::CommandBufferBeginInfo::default()
                        .flags(vk::CommandBufferUsageFlags::ONE_TIME_SUBMIT),
                )
                .map_err(VkError::vk("vkBeginCommandBuffer"))?;
            image_barrier(
                device,
                cmd,
                vk::PipelineStageFlags::TRANSFER,
                layout_change(
                    image,
                    vk::ImageLayout::UNDEFINED,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    vk::AccessFlags::empty(),
                    vk::AccessFlags::TRANSFER_WRITE,
                ),
            );
            if frame.width < ew || frame.height < eh {
                device.cmd_clear_color_image(
                    cmd,
                    image,
                    vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                    &vk::ClearColorValue {
                        float32: [0.05, 0.05, 0.05, 1.0],
                    },
                    &[COLOR_RANGE],
                );
                image_barrier(
                    device,
                    cmd,
                    vk::PipelineStageFlags::TRANSFER,
                    layout_change(
                        image,
                        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                        vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                        vk::AccessFlags::TRANSFER_WRITE,
                        vk::AccessFlags::TRANSFER_WRITE,
                    ),
                );
            }
            device.cmd_copy_buffer_to_image(
                cmd,
                upload.handle(),
                image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                &[copy],
            );
            let mut last = vk::ImageLayout::TRANSFER_DST_OPTIMAL;
            if let (true, Some(rb)) = (frame.readable, self.readback.as_ref()) {
                record_read_back(device, cmd, image, rb.handle(), copy);
                last = vk::ImageLayout::TRANSFER_SRC_OPTIMAL;
            }
            if let Some(paint) = panel {
                // After the read-back: the screenshot is the frame alone.
                self.panel.record(cmd, image, index as usize, last, paint)?;
                if let (true, Some(rb)) = (frame.readable, self.readback.as_ref()) {
                    let after = vk::BufferImageCopy {
                        buffer_offset: frame.pixels * 4,
                        ..copy
                    };
                    self.panel.copy_shown(cmd, image, rb.handle(), after);
                }
            } else {
                image_barrier(
                    device,
                    cmd,
                    vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                    layout_change(
                        image,
                        last,
                        vk::ImageLayout::PRESENT_SRC_KHR,
                        vk::AccessFlags::TRANSFER_WRITE,
                        vk::AccessFlags::empty(),
                    ),
                );
            }
            device
                .end_command_buffer(cmd)
                .map_err(VkError::vk("vkEndCommandBuffer"))?;
        }
        Ok(())
    }
}

/// A swapchain image's one colour level and layer.
const COLOR_RANGE: vk::ImageSubresourceRange = vk::ImageSubresourceRange {
    aspect_mask: vk::ImageAspectFlags::COLOR,
    base_mip_level: 0,
    level_count: 1,
    base_array_layer: 0,
    layer_count: 1,
};

/// A layout change of `image` (the whole colour range) on one queue.
fn layout_change(
    image: vk::Image,
    old: vk::ImageLayout,
    new: vk::ImageLayout,
    src_access: vk::AccessFlags,
    dst_access: vk::AccessFlags,
) -> vk::ImageMemoryBarrier<'static> {
    vk::ImageMemoryBarrier::default()
        .old_layout(old)
        .new_layout(new)
        .src_access_mask(src_access)
        .dst_access_mask(dst_access)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .image(image)
        .subresource_range(COLOR_RANGE)
}

/// Records `barrier` after the transfer stage, before `dst_stage`.
///
/// # Safety
/// `cmd` is recording and `barrier`'s image is live until the submission completes.
unsafe fn image_barrier(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    dst_stage: vk::PipelineStageFlags,
    barrier: vk::ImageMemoryBarrier<'_>,
) {
    // SAFETY: the caller's contract.
    unsafe {
        device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::TRANSFER,
            dst_stage,
            vk::DependencyFlags::empty(),
            &[],
            &[],
            &[barrier],
        )
    };
}

/// Records the copy of `image` (just written by transfer) into `readback` for the host, the
/// image left in `TRANSFER_SRC_OPTIMAL`.
///
/// # Safety
/// `cmd` is recording; `image` and `readback` live until the submission completes.
unsafe fn record_read_back(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    image: vk::Image,
    readback: vk::Buffer,
    copy: vk::BufferImageCopy,
) {
    let host = vk::BufferMemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(vk::AccessFlags::HOST_READ)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .buffer(readback)
        .size(vk::WHOLE_SIZE);
    // SAFETY: the caller's contract.
    unsafe {
        image_barrier(
            device,
            cmd,
            vk::PipelineStageFlags::TRANSFER,
            layout_change(
                image,
                vk::ImageLayout::TRANSFER_DST_OPTIMAL,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                vk::AccessFlags::TRANSFER_WRITE,
                vk::AccessFlags::TRANSFER_READ,
            ),
        );
        device.cmd_copy_image_to_buffer(
            cmd,
            image,
            vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
            readback,
            &[copy],
        );
        device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::HOST,
            vk::DependencyFlags::empty(),
            &[],
            &[host],
            &[],
        );
    }
}
