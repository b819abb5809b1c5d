//! The viewer's panel drawn over a presented frame: egui's tessellated meshes rasterised by
//! egui-ash-renderer into the swapchain image, after the frame was copied in and (for
//! `--screenshot`) read back, so a screenshot never contains the panel.
//!
//! One render pass loads the image (the copied frame stays underneath), draws the meshes with
//! premultiplied-alpha blending and leaves the image ready for presentation. The renderer and
//! its textures (egui's font atlas) live as long as the [`crate::Presenter`]; the image views
//! and framebuffers follow the swapchain.

use ash::vk;

use crate::error::{Result, VkError};

/// What the panel draws this frame: egui's output for one [`crate::Presenter::present`].
#[derive(Clone, Copy, Debug)]
pub struct PanelPaint<'a> {
    /// `egui::Context::tessellate`'s output.
    pub primitives: &'a [egui::ClippedPrimitive],
    /// Textures egui created or changed since the last painted frame (applied before drawing;
    /// the frees after it).
    pub textures: &'a egui::TexturesDelta,
    /// Physical pixels per egui point.
    pub pixels_per_point: f32,
}

fn renderer_error(e: egui_ash_renderer::RendererError) -> VkError {
    match e {
        egui_ash_renderer::RendererError::Vulkan(result) => VkError::Vulkan {
            call: "the panel's egui renderer",
            result,
        },
        other => VkError::InvalidRequest(format!("the viewer's panel: {other}")),
    }
}

/// Render pass, per-image views and framebuffers, and the egui renderer.
pub(crate) struct PanelPainter {
    device: ash::Device,
    format: vk::Format,
    render_pass: vk::RenderPass,
    views: Vec<vk::ImageView>,
    framebuffers: Vec<vk::Framebuffer>,
    extent: [u32; 2],
    renderer: Option<egui_ash_renderer::Renderer>,
}

impl PanelPainter {
    pub(crate) fn new(device: &ash::Device) -> PanelPainter {
        PanelPainter {
            device: device.clone(),
            format: vk::Format::UNDEFINED,
            render_pass: vk::RenderPass::null(),
            views: Vec::new(),
            framebuffers: Vec::new(),
            extent: [0, 0],
            renderer: None,
        }
    }

    /// Forgets the swapchain's views and framebuffers (the device must be idle).
    pub(crate) fn drop_targets(&mut self) {
        for f in self.framebuffers.drain(..) {
            // SAFETY: the caller waited for the device to be idle; each is destroyed once.
            unsafe { self.device.destroy_framebuffer(f, None) };
        }
        for v in self.views.drain(..) {
            // SAFETY: as above; the framebuffers using it are gone.
            unsafe { self.device.destroy_image_view(v, None) };
        }
    }

    /// Views and framebuffers for a new swapchain's `images` (the device must be idle).
    pub(crate) fn set_targets(
        &mut self,
        images: &[vk::Image],
        format: vk::Format,
        extent: [u32; 2],
    ) -> Result<()> {
        self.drop_targets();
        if format != self.format {
            self.make_render_pass(format)?;
        }
        self.extent = extent;
        for &image in images {
            let info = vk::ImageViewCreateInfo::default()
                .image(image)
                .view_type(vk::ImageViewType::TYPE_2D)
                .format(format)
                .subresource_range(
                    vk::ImageSubresourceRange::default()
                        .aspect_mask(vk::ImageAspectFlags::COLOR)
                        .level_count(1)
                        .layer_count(1),
                );
            // SAFETY: the image belongs to the live swapchain (created with COLOR_ATTACHMENT
            // usage); the view is destroyed in drop_targets before the swapchain.
            let view = unsafe { self.device.create_image_view(&info, None) }
                .map_err(VkError::vk("vkCreateImageView"))?;
            self.views.push(view);
            let attachments = [view];
            let fb = vk::FramebufferCreateInfo::default()
                .render_pass(self.render_pass)
                .attachments(&attachments)
                .width(extent[0])
                .height(extent[1])
                .layers(1);
            // SAFETY: the render pass and view are live and compatible (same format).
            let fb = unsafe { self.device.create_framebuffer(&fb, None) }
                .map_err(VkError::vk("vkCreateFramebuffer"))?;
            self.framebuffers.push(fb);
        }
        Ok(())
    }

    fn make_render_pass(&mut self, format: vk::Format) -> Result<()> {
        let attachment = [vk::AttachmentDescription::default()
            .format(format)
            .samples(vk::SampleCountFlags::TYPE_1)
            .load_op(vk::AttachmentLoadOp::LOAD)
            .store_op(vk::AttachmentStoreOp::STORE)
            .stencil_load_op(vk::AttachmentLoadOp::DONT_CARE)
            .stencil_store_op(vk::AttachmentStoreOp::DONT_CARE)
            .initial_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .final_layout(vk::ImageLayout::PRESENT_SRC_KHR)];
        let color = [vk::AttachmentReference::default()
            .attachment(0)
            .layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)];
        let subpass = [vk::SubpassDescription::default()
            .pipeline_bind_point(vk::PipelineBindPoint::GRAPHICS)
            .color_attachments(&color)];
        let info = vk::RenderPassCreateInfo::default()
            .attachments(&attachment)
            .subpasses(&subpass);
        // SAFETY: a valid create info; destroyed in Drop (or replaced below after the old one's
        // pipeline moved to the new pass).
        let pass = unsafe { self.device.create_render_pass(&info, None) }
            .map_err(VkError::vk("vkCreateRenderPass"))?;
        if let Some(r) = self.renderer.as_mut() {
            r.set_render_pass(pass).map_err(renderer_error)?;
        }
        if self.render_pass != vk::RenderPass::null() {
            // SAFETY: the device is idle (set_targets' contract); the renderer's pipeline now
            // uses the new pass.
            unsafe { self.device.destroy_render_pass(self.render_pass, None) };
        }
        self.render_pass = pass;
        self.format = format;
        Ok(())
    }

    /// Uploads `paint`'s new textures (egui's font atlas on the first frame) through `queue`,
    /// creating the renderer on first use.
    pub(crate) fn upload(
        &mut self,
        instance: &ash::Instance,
        physical: vk::PhysicalDevice,
        queue: vk::Queue,
        pool: vk::CommandPool,
        paint: &PanelPaint<'_>,
    ) -> Result<()> {
        if self.renderer.is_none() {
            let srgb = matches!(
                self.format,
                vk::Format::B8G8R8A8_SRGB | vk::Format::R8G8B8A8_SRGB
            );
            let options = egui_ash_renderer::Options {
                // `present` waits for each frame's fence: one set of mesh buffers suffices.
                in_flight_frames: 1,
                enable_depth_test: false,
                enable_depth_write: false,
                srgb_framebuffer: srgb,
            };
            self.renderer = Some(
                egui_ash_renderer::Renderer::with_default_allocator(
                    instance,
                    physical,
                    self.device.clone(),
                    self.render_pass,
                    options,
                )
                .map_err(renderer_error)?,
            );
        }
        if let Some(r) = self.renderer.as_mut() {
            if !paint.textures.set.is_empty() {
                r.set_textures(queue, pool, &paint.textures.set)
                    .map_err(renderer_error)?;
            }
        }
        Ok(())
    }

    /// Records the panel's draw into swapchain image `index` (in TRANSFER_SRC or TRANSFER_DST
    /// layout `from`, last written by a transfer); leaves it in PRESENT_SRC layout.
    pub(crate) fn record(
        &mut self,
        cmd: vk::CommandBuffer,
        image: vk::Image,
        index: usize,
        from: vk::ImageLayout,
        paint: &PanelPaint<'_>,
    ) -> Result<()> {
        let (Some(renderer), Some(&framebuffer)) =
            (self.renderer.as_mut(), self.framebuffers.get(index))
        else {
            return Err(VkError::InvalidRequest(
                "the viewer's panel has no target for this swapchain image".into(),
            ));
        };
        let to_attachment = vk::ImageMemoryBarrier::default()
            .old_layout(from)
            .new_layout(vk::ImageLayout::COLOR_ATTACHMENT_OPTIMAL)
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE | vk::AccessFlags::TRANSFER_READ)
            .dst_access_mask(
                vk::AccessFlags::COLOR_ATTACHMENT_READ | vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
            )
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .image(image)
            .subresource_range(
                vk::ImageSubresourceRange::default()
                    .aspect_mask(vk::ImageAspectFlags::COLOR)
                    .level_count(1)
                    .layer_count(1),
            );
        let extent = vk::Extent2D {
            width: self.extent[0],
            height: self.extent[1],
        };
        let begin = vk::RenderPassBeginInfo::default()
            .render_pass(self.render_pass)
            .framebuffer(framebuffer)
            .render_area(vk::Rect2D {
                offset: vk::Offset2D::default(),
                extent,
            });
        // SAFETY: `cmd` is recording (the caller began it and ends it); the image is the
        // framebuffer's attachment, written before by transfers that the barrier orders.
        unsafe {
            self.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[to_attachment],
            );
            self.device
                .cmd_begin_render_pass(cmd, &begin, vk::SubpassContents::INLINE);
        }
        let drawn = renderer
            .cmd_draw(cmd, extent, paint.pixels_per_point, paint.primitives)
            .map_err(renderer_error);
        // SAFETY: the render pass begun above.
        unsafe { self.device.cmd_end_render_pass(cmd) };
        drawn
    }

    /// Copies the presented image (panel included; in PRESENT_SRC layout after [`Self::record`])
    /// into `buffer` by `copy`, for tests that the panel reached the window; back to
    /// PRESENT_SRC afterwards.
    pub(crate) fn copy_shown(
        &self,
        cmd: vk::CommandBuffer,
        image: vk::Image,
        buffer: vk::Buffer,
        copy: vk::BufferImageCopy,
    ) {
        let barrier = |old, new, src, dst| {
            vk::ImageMemoryBarrier::default()
                .old_layout(old)
                .new_layout(new)
                .src_access_mask(src)
                .dst_access_mask(dst)
                .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
                .image(image)
                .subresource_range(
                    vk::ImageSubresourceRange::default()
                        .aspect_mask(vk::ImageAspectFlags::COLOR)
                        .level_count(1)
                        .layer_count(1),
                )
        };
        let host = vk::BufferMemoryBarrier::default()
            .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
            .dst_access_mask(vk::AccessFlags::HOST_READ)
            .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
            .buffer(buffer)
            .size(vk::WHOLE_SIZE);
        // SAFETY: `cmd` is recording outside a render pass; the image (TRANSFER_SRC usage)
        // and the buffer (TRANSFER_DST, large enough: the caller sized it) are live until the
        // submission's fence.
        unsafe {
            self.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::COLOR_ATTACHMENT_OUTPUT,
                vk::PipelineStageFlags::TRANSFER,
                vk::DependencyFlags::empty(),
                &[],
                &[],
                &[barrier(
                    vk::ImageLayout::PRESENT_SRC_KHR,
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    vk::AccessFlags::COLOR_ATTACHMENT_WRITE,
                    vk::AccessFlags::TRANSFER_READ,
                )],
            );
            self.device.cmd_copy_image_to_buffer(
                cmd,
                image,
                vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                buffer,
                &[copy],
            );
            self.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::HOST | vk::PipelineStageFlags::BOTTOM_OF_PIPE,
                vk::DependencyFlags::empty(),
                &[],
                &[host],
                &[barrier(
                    vk::ImageLayout::TRANSFER_SRC_OPTIMAL,
                    vk::ImageLayout::PRESENT_SRC_KHR,
                    vk::AccessFlags::TRANSFER_READ,
                    vk::AccessFlags::empty(),
                )],
            );
        }
    }

    /// Frees the textures egui released (after the frame's fence was waited on).
    pub(crate) fn free(&mut self, paint: &PanelPaint<'_>) -> Result<()> {
        match self.renderer.as_mut() {
            Some(r) if !paint.textures.free.is_empty() => r
                .free_textures(&paint.textures.free)
                .map_err(renderer_error),
            _ => Ok(()),
        }
    }
}

impl Drop for PanelPainter {
    fn drop(&mut self) {
        // The owner (Presenter) waited for the device to be idle.
        self.renderer = None;
        self.drop_targets();
        if self.render_pass != vk::RenderPass::null() {
            // SAFETY: the device is idle; the renderer's pipeline using it is gone.
            unsafe { self.device.destroy_render_pass(self.render_pass, None) };
        }
    }
}
