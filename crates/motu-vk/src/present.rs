//! Presenting finished frames to a window (`motu view`): a Vulkan surface and its swapchain.
//!
//! The renderers write RGBA8 into buffers that are read back anyway (the AOV, the heatmap
//! colouring and the statistics are computed from them), so the presenter takes a finished
//! RGBA8 frame, uploads it into a host-visible buffer and copies it into the acquired swapchain
//! image: a raw texel copy, since the bytes are already sRGB-encoded (UNORM and SRGB formats
//! both show them exactly as the headless PNG has them). With `read_back`, the presented image
//! is copied out again before presentation: that is how `--screenshot` proves the window shows
//! the same pixels as `motu render`. The viewer's panel ([`PanelPaint`]) is drawn over the
//! image after that read-back, so a screenshot never contains it.
//!
//! One frame in flight: `present` waits for its own submission, which keeps buffer reuse
//! trivially safe; the renderer's own fence already serialises the frame.

use std::sync::atomic::Ordering;
use std::sync::Arc;

use ash::vk;
pub use raw_window_handle::{RawDisplayHandle, RawWindowHandle};

use crate::context::Context;
use crate::error::{Result, VkError};
use crate::memory::{Buffer, BufferDesc, BufferUsage, MemoryLocation};
use crate::panel::{PanelPaint, PanelPainter};

mod record;

/// What [`Presenter::present`] did.
#[derive(Debug)]
pub enum Presented {
    /// The frame is on screen; with `read_back`, the swapchain image's pixels as RGBA8 (`None`
    /// when the image could not be read: its size differs from the frame's, or the surface does
    /// not allow reading swapchain images).
    /// `panel`: whether a panel was drawn over the frame (after the read-back); `shown`: with
    /// `read_back` and a panel, the image as presented, panel included (for tests that the
    /// panel reached the window; never a screenshot).
    Shown {
        readback: Option<Vec<u8>>,
        panel: bool,
        shown: Option<Vec<u8>>,
    },
    /// The surface is out of date or has zero size (minimised): nothing was shown; the
    /// swapchain is recreated on the next call.
    Skipped,
}

/// A window surface and its swapchain. Drop it before the window.
pub struct Presenter {
    /// First: dropped (its Vulkan objects destroyed) while `ctx` still holds the device.
    panel: PanelPainter,
    /// Whether swapchain images can be colour attachments (the panel is drawn only then).
    panel_ok: bool,
    ctx: Context,
    surface_fn: ash::khr::surface::Instance,
    swapchain_fn: ash::khr::swapchain::Device,
    surface: vk::SurfaceKHR,
    swapchain: vk::SwapchainKHR,
    images: Vec<vk::Image>,
    format: vk::Format,
    extent: [u32; 2],
    readable: bool,
    pool: vk::CommandPool,
    cmd: vk::CommandBuffer,
    fence: vk::Fence,
    acquired: vk::Semaphore,
    /// Per swapchain image: signalled by the copy, waited on by presentation.
    rendered: Vec<vk::Semaphore>,
    upload: Option<Buffer>,
    readback: Option<Buffer>,
    vsync: bool,
    wanted: [u32; 2],
    stale: bool,
}

impl std::fmt::Debug for Presenter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Presenter")
            .field("format", &self.format)
            .field("extent", &self.extent)
            .field("images", &self.images.len())
            .finish()
    }
}

fn is_bgra(format: vk::Format) -> bool {
    matches!(
        format,
        vk::Format::B8G8R8A8_UNORM | vk::Format::B8G8R8A8_SRGB
    )
}

/// The first 8-bit RGBA/BGRA format the surface offers, UNORM before SRGB.
fn surface_format(formats: &[vk::SurfaceFormatKHR]) -> Result<vk::SurfaceFormatKHR> {
    let preference = [
        vk::Format::B8G8R8A8_UNORM,
        vk::Format::R8G8B8A8_UNORM,
        vk::Format::B8G8R8A8_SRGB,
        vk::Format::R8G8B8A8_SRGB,
    ];
    preference
        .iter()
        .find_map(|f| formats.iter().find(|s| s.format == *f))
        .copied()
        .ok_or_else(|| {
            VkError::InvalidRequest(format!(
                "the window surface offers no 8-bit RGBA/BGRA format (it offers {:?})",
                formats.iter().map(|f| f.format).collect::<Vec<_>>()
            ))
        })
}

/// The surface's extent, or the window's `wanted` size within the surface's limits where the
/// surface leaves it to the swapchain.
fn swapchain_extent(caps: &vk::SurfaceCapabilitiesKHR, wanted: [u32; 2]) -> vk::Extent2D {
    if caps.current_extent.width != u32::MAX {
        caps.current_extent
    } else {
        vk::Extent2D {
            width: wanted[0].clamp(
                caps.min_image_extent.width,
                caps.max_image_extent.width.max(1),
            ),
            height: wanted[1].clamp(
                caps.min_image_extent.height,
                caps.max_image_extent.height.max(1),
            ),
        }
    }
}

impl Presenter {
    /// Creates a surface for `window` and a swapchain of `size` (the window's inner size in
    /// pixels). `ctx` must have been opened with [`crate::ContextOptions::presentation`] set to
    /// this window's display. `vsync` picks FIFO presentation, else MAILBOX/IMMEDIATE where
    /// available.
    ///
    /// # Safety
    /// `display` and `window` must be valid handles of a live window that outlives the
    /// returned `Presenter`.
    pub unsafe fn new(
        ctx: &Context,
        display: RawDisplayHandle,
        window: RawWindowHandle,
        size: [u32; 2],
        vsync: bool,
    ) -> Result<Presenter> {
        let shared = &ctx.shared;
        let inst = &shared.instance;
        // SAFETY: the caller guarantees live handles outliving the surface (and so this
        // Presenter, which destroys the surface); the instance enabled the surface extensions
        // for this display (Context::new with `presentation`).
        let surface = unsafe {
            ash_window::create_surface(&inst.entry, &inst.instance, display, window, None)
        }
        .map_err(VkError::vk("vkCreate*SurfaceKHR"))?;
        let surface_fn = ash::khr::surface::Instance::new(&inst.entry, &inst.instance);
        let swapchain_fn = ash::khr::swapchain::Device::new(&inst.instance, &shared.device);
        let mut p = Presenter {
            panel: PanelPainter::new(&shared.device),
            panel_ok: false,
            ctx: ctx.clone(),
            surface_fn,
            swapchain_fn,
            surface,
            swapchain: vk::SwapchainKHR::null(),
            images: Vec::new(),
            format: vk::Format::UNDEFINED,
            extent: [0, 0],
            readable: false,
            pool: vk::CommandPool::null(),
            cmd: vk::CommandBuffer::null(),
            fence: vk::Fence::null(),
            acquired: vk::Semaphore::null(),
            rendered: Vec::new(),
            upload: None,
            readback: None,
            vsync,
            wanted: size,
            stale: true,
        };
        // SAFETY: the surface and the physical device belong to this instance.
        let supported = unsafe {
            p.surface_fn.get_physical_device_surface_support(
                shared.info.handle,
                shared.queue_family_index,
                surface,
            )
        }
        .map_err(VkError::vk("vkGetPhysicalDeviceSurfaceSupportKHR"))?;
        if !supported {
            return Err(VkError::DeviceUnsuitable {
                index: shared.info.index,
                name: shared.info.name.clone(),
                reason: "its compute queue cannot present to this window".into(),
            });
        }
        let device = &shared.device;
        let pool_info = vk::CommandPoolCreateInfo::default()
            .queue_family_index(shared.queue_family_index)
            .flags(vk::CommandPoolCreateFlags::RESET_COMMAND_BUFFER);
        // SAFETY: valid create infos for this device; every object is owned by `p` (Drop).
        unsafe {
            p.pool = device
                .create_command_pool(&pool_info, None)
                .map_err(VkError::vk("vkCreateCommandPool"))?;
            p.cmd = device
                .allocate_command_buffers(
                    &vk::CommandBufferAllocateInfo::default()
                        .command_pool(p.pool)
                        .level(vk::CommandBufferLevel::PRIMARY)
                        .command_buffer_count(1),
                )
                .map_err(VkError::vk("vkAllocateCommandBuffers"))?[0];
            p.fence = device
                .create_fence(&vk::FenceCreateInfo::default(), None)
                .map_err(VkError::vk("vkCreateFence"))?;
            p.acquired = device
                .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
                .map_err(VkError::vk("vkCreateSemaphore"))?;
        }
        p.recreate()?;
        Ok(p)
    }

    /// The swapchain's size in pixels (`[0, 0]` while minimised): render frames of this size.
    pub fn extent(&self) -> [u32; 2] {
        self.extent
    }

    /// The window's new inner size: the swapchain is recreated before the next frame.
    pub fn resize(&mut self, size: [u32; 2]) {
        self.wanted = size;
        self.stale = true;
    }

    /// Recreates the swapchain if it is out of date; returns the extent to render at.
    pub fn prepare(&mut self) -> Result<[u32; 2]> {
        if self.stale {
            self.recreate()?;
        }
        Ok(self.extent)
    }

    fn recreate(&mut self) -> Result<()> {
        let shared = Arc::clone(&self.ctx.shared);
        let phys = shared.info.handle;
        // SAFETY: surface and physical device belong to this instance.
        let caps = unsafe {
            self.surface_fn
                .get_physical_device_surface_capabilities(phys, self.surface)
        }
        .map_err(VkError::vk("vkGetPhysicalDeviceSurfaceCapabilitiesKHR"))?;
        // SAFETY: as above.
        let formats = unsafe {
            self.surface_fn
                .get_physical_device_surface_formats(phys, self.surface)
        }
        .map_err(VkError::vk("vkGetPhysicalDeviceSurfaceFormatsKHR"))?;
        // SAFETY: as above.
        let modes = unsafe {
            self.surface_fn
                .get_physical_device_surface_present_modes(phys, self.surface)
        }
        .map_err(VkError::vk("vkGetPhysicalDeviceSurfacePresentModesKHR"))?;
        let format = surface_format(&formats)?;
        if !caps
            .supported_usage_flags
            .contains(vk::ImageUsageFlags::TRANSFER_DST)
        {
            return Err(VkError::InvalidRequest(
                "the window surface does not allow copying into swapchain images".into(),
            ));
        }
        let readable = caps
            .supported_usage_flags
            .contains(vk::ImageUsageFlags::TRANSFER_SRC);
        let extent = swapchain_extent(&caps, self.wanted);
        // SAFETY: nothing of ours is pending (every present waited for its fence), but the
        // presentation engine may still hold old images: wait before destroying them.
        unsafe { shared.device.device_wait_idle() }.map_err(VkError::vk("vkDeviceWaitIdle"))?;
        self.destroy_swapchain();
        self.extent = [0, 0];
        self.stale = false;
        if extent.width == 0 || extent.height == 0 {
            // Minimised: no swapchain until the window has a size again.
            self.stale = true;
            return Ok(());
        }
        let mode = if self.vsync {
            vk::PresentModeKHR::FIFO
        } else {
            [vk::PresentModeKHR::MAILBOX, vk::PresentModeKHR::IMMEDIATE]
                .into_iter()
                .find(|m| modes.contains(m))
                .unwrap_or(vk::PresentModeKHR::FIFO)
        };
        let mut count = caps.min_image_count + 1;
        if caps.max_image_count > 0 {
            count = count.min(caps.max_image_count);
        }
        let alpha = [
            vk::CompositeAlphaFlagsKHR::OPAQUE,
            vk::CompositeAlphaFlagsKHR::INHERIT,
            vk::CompositeAlphaFlagsKHR::PRE_MULTIPLIED,
            vk::CompositeAlphaFlagsKHR::POST_MULTIPLIED,
        ]
        .into_iter()
        .find(|a| caps.supported_composite_alpha.contains(*a))
        .unwrap_or(vk::CompositeAlphaFlagsKHR::OPAQUE);
        let mut usage = vk::ImageUsageFlags::TRANSFER_DST;
        if readable {
            usage |= vk::ImageUsageFlags::TRANSFER_SRC;
        }
        let panel_ok = caps
            .supported_usage_flags
            .contains(vk::ImageUsageFlags::COLOR_ATTACHMENT);
        if panel_ok {
            usage |= vk::ImageUsageFlags::COLOR_ATTACHMENT;
        }
        let info = vk::SwapchainCreateInfoKHR::default()
            .surface(self.surface)
            .min_image_count(count)
            .image_format(format.format)
            .image_color_space(format.color_space)
            .image_extent(extent)
            .image_array_layers(1)
            .image_usage(usage)
            .image_sharing_mode(vk::SharingMode::EXCLUSIVE)
            .pre_transform(caps.current_transform)
            .composite_alpha(alpha)
            .present_mode(mode)
            .clipped(true);
        // SAFETY: the surface is live and supported by this queue family; the info uses only
        // supported values (queried above); the old swapchain was destroyed.
        self.swapchain = unsafe { self.swapchain_fn.create_swapchain(&info, None) }
            .map_err(VkError::vk("vkCreateSwapchainKHR"))?;
        // SAFETY: the swapchain was just created.
        self.images = unsafe { self.swapchain_fn.get_swapchain_images(self.swapchain) }
            .map_err(VkError::vk("vkGetSwapchainImagesKHR"))?;
        for _ in 0..self.images.len() {
            // SAFETY: valid create info; destroyed with the swapchain.
            let s = unsafe {
                shared
                    .device
                    .create_semaphore(&vk::SemaphoreCreateInfo::default(), None)
            }
            .map_err(VkError::vk("vkCreateSemaphore"))?;
            self.rendered.push(s);
        }
        if panel_ok {
            self.panel
                .set_targets(&self.images, format.format, [extent.width, extent.height])?;
        }
        self.panel_ok = panel_ok;
        self.format = format.format;
        self.readable = readable;
        self.extent = [extent.width, extent.height];
        tracing::info!(
            width = extent.width,
            height = extent.height,
            format = ?format.format,
            mode = ?mode,
            images = self.images.len(),
            "swapchain created"
        );
        Ok(())
    }

    fn destroy_swapchain(&mut self) {
        let device = &self.ctx.shared.device;
        // The device is idle (callers wait).
        self.panel.drop_targets();
        for s in self.rendered.drain(..) {
            // SAFETY: the device is idle (callers wait), so no pending wait uses it.
            unsafe { device.destroy_semaphore(s, None) };
        }
        if self.swapchain != vk::SwapchainKHR::null() {
            // SAFETY: the device is idle; the images go with the swapchain.
            unsafe { self.swapchain_fn.destroy_swapchain(self.swapchain, None) };
            self.swapchain = vk::SwapchainKHR::null();
        }
        self.images.clear();
    }

    fn host_buffer(
        ctx: &Context,
        slot: &mut Option<Buffer>,
        label: &str,
        size: u64,
        usage: BufferUsage,
        location: MemoryLocation,
    ) -> Result<()> {
        if slot.as_ref().is_none_or(|b| b.size_bytes() < size) {
            *slot = None;
            *slot = Some(Buffer::new_dedicated(
                ctx,
                label,
                &BufferDesc {
                    size_bytes: size,
                    usage,
                },
                location,
            )?);
        }
        Ok(())
    }

    /// Shows `rgba8` (`width × height`, row 0 at the top): copied into the next swapchain image
    /// at the top-left (a frame smaller than the swapchain leaves the rest dark, a larger one
    /// is cut), read back if asked, `panel` drawn over it (where the surface allows drawing),
    /// then presented. See [`Presented`].
    pub fn present(
        &mut self,
        rgba8: &[u8],
        width: u32,
        height: u32,
        read_back: bool,
        panel: Option<&PanelPaint<'_>>,
    ) -> Result<Presented> {
        let pixels = u64::from(width) * u64::from(height);
        if width == 0 || height == 0 || rgba8.len() as u64 != pixels * 4 {
            return Err(VkError::InvalidRequest(format!(
                "present: {} bytes for a {width}×{height} frame",
                rgba8.len()
            )));
        }
        if self.stale {
            self.recreate()?;
        }
        if self.swapchain == vk::SwapchainKHR::null() {
            return Ok(Presented::Skipped);
        }
        let panel = panel.filter(|_| self.panel_ok);
        let readable = read_back && self.readable && [width, height] == self.extent;
        let frame = FrameCopy {
            width,
            height,
            pixels,
            readable,
            // The frame, then (with a panel) the image as shown.
            copies: if panel.is_some() { 2 } else { 1 },
        };
        self.stage(rgba8, &frame, panel)?;
        let Some(index) = self.acquire()? else {
            return Ok(Presented::Skipped);
        };
        self.record(&frame, index, panel)?;
        let presented = self.submit_and_present(index)?;
        if let Some(paint) = panel {
            self.panel.free(paint)?;
        }
        match presented {
            Ok(false) => {}
            Ok(true) | Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => self.stale = true,
            Err(e) => {
                return Err(VkError::Vulkan {
                    call: "vkQueuePresentKHR",
                    result: e,
                })
            }
        }
        Ok(Presented::Shown {
            readback: self.read(&frame, 0)?,
            panel: panel.is_some(),
            shown: self.read(&frame, 1)?,
        })
    }

    /// Writes the frame into the upload buffer (swizzled for a BGRA swapchain), sizes the
    /// read-back buffer and uploads the panel's paint.
    fn stage(
        &mut self,
        rgba8: &[u8],
        frame: &FrameCopy,
        panel: Option<&PanelPaint<'_>>,
    ) -> Result<()> {
        let ctx = self.ctx.clone();
        Self::host_buffer(
            &ctx,
            &mut self.upload,
            "present-upload",
            frame.pixels * 4,
            BufferUsage::TRANSFER_SRC,
            MemoryLocation::Upload,
        )?;
        let upload = self
            .upload
            .as_ref()
            .ok_or_else(|| VkError::InvalidRequest("present: no upload buffer".into()))?;
        if is_bgra(self.format) {
            let mut bgra = rgba8.to_vec();
            bgra.chunks_exact_mut(4).for_each(|p| p.swap(0, 2));
            upload.write_bytes(0, &bgra)?;
        } else {
            upload.write_bytes(0, rgba8)?;
        }
        if frame.readable {
            Self::host_buffer(
                &ctx,
                &mut self.readback,
                "present-readback",
                frame.copies * frame.pixels * 4,
                BufferUsage::TRANSFER_DST,
                MemoryLocation::Readback,
            )?;
        }
        if let Some(paint) = panel {
            let shared = &ctx.shared;
            let queue = shared.queue();
            self.panel.upload(
                &shared.instance.instance,
                shared.info.handle,
                *queue,
                self.pool,
                paint,
            )?;
        }
        Ok(())
    }

    /// The next swapchain image's index; `None` when the swapchain is out of date.
    fn acquire(&mut self) -> Result<Option<u32>> {
        // SAFETY: the swapchain is live; `acquired` is unsignalled (its last wait completed:
        // the submission that waited on it was fenced).
        let acquired = unsafe {
            self.swapchain_fn.acquire_next_image(
                self.swapchain,
                u64::MAX,
                self.acquired,
                vk::Fence::null(),
            )
        };
        match acquired {
            Ok((i, suboptimal)) => {
                if suboptimal {
                    self.stale = true;
                }
                Ok(Some(i))
            }
            Err(vk::Result::ERROR_OUT_OF_DATE_KHR) => {
                self.stale = true;
                Ok(None)
            }
            Err(e) => Err(VkError::Vulkan {
                call: "vkAcquireNextImageKHR",
                result: e,
            }),
        }
    }

    /// Submits the recorded copy, presents image `index` and waits for the submission; the
    /// presentation's own result is returned for the caller to judge (out of date: recreate).
    fn submit_and_present(&mut self, index: u32) -> Result<ash::prelude::VkResult<bool>> {
        let shared = Arc::clone(&self.ctx.shared);
        let device = &shared.device;
        let waits = [self.acquired];
        let stages = [vk::PipelineStageFlags::TRANSFER];
        let cmds = [self.cmd];
        let signals = [self.rendered[index as usize]];
        let submit = vk::SubmitInfo::default()
            .wait_semaphores(&waits)
            .wait_dst_stage_mask(&stages)
            .command_buffers(&cmds)
            .signal_semaphores(&signals);
        let swapchains = [self.swapchain];
        let indices = [index];
        let present = vk::PresentInfoKHR::default()
            .wait_semaphores(&signals)
            .swapchains(&swapchains)
            .image_indices(&indices);
        let presented = {
            let queue = shared.queue();
            // SAFETY: the queue is externally synchronised by its lock; the fence is unsignalled
            // (reset after each wait); every handle recorded lives in `self`.
            unsafe { device.queue_submit(*queue, &[submit], self.fence) }
                .map_err(VkError::vk("vkQueueSubmit"))?;
            shared.submits.fetch_add(1, Ordering::Relaxed);
            shared.fence_waits.fetch_add(1, Ordering::Relaxed);
            // SAFETY: as above; the image was acquired from this swapchain.
            unsafe { self.swapchain_fn.queue_present(*queue, &present) }
        };
        // SAFETY: the fence was submitted just above.
        unsafe {
            device
                .wait_for_fences(&[self.fence], true, u64::MAX)
                .map_err(|r| VkError::from_submit("vkWaitForFences", r, "present"))?;
            device
                .reset_fences(&[self.fence])
                .map_err(VkError::vk("vkResetFences"))?;
        }
        Ok(presented)
    }

    /// Read-back copy `copy` (0: the frame, 1: the image as shown) as RGBA8, if it was read.
    fn read(&self, frame: &FrameCopy, copy: u64) -> Result<Option<Vec<u8>>> {
        let (true, Some(rb)) = (
            frame.readable && copy < frame.copies,
            self.readback.as_ref(),
        ) else {
            return Ok(None);
        };
        let mut px = vec![0u8; (frame.pixels * 4) as usize];
        rb.read_bytes(copy * frame.pixels * 4, &mut px)?;
        if is_bgra(self.format) {
            px.chunks_exact_mut(4).for_each(|p| p.swap(0, 2));
        }
        Ok(Some(px))
    }
}

/// One [`Presenter::present`] call's frame: its size and what is read back.
struct FrameCopy {
    width: u32,
    height: u32,
    pixels: u64,
    /// Whether the presented image is copied back (asked, allowed, and the frame's size is the
    /// swapchain's).
    readable: bool,
    /// Images read back: the frame, then (with a panel) the image as shown.
    copies: u64,
}

impl Drop for Presenter {
    fn drop(&mut self) {
        let shared = Arc::clone(&self.ctx.shared);
        let device = &shared.device;
        // SAFETY: waiting idle first makes every object unused; each is destroyed once, the
        // swapchain before its surface.
        unsafe {
            let _ = device.device_wait_idle();
            self.destroy_swapchain();
            device.destroy_semaphore(self.acquired, None);
            device.destroy_fence(self.fence, None);
            device.destroy_command_pool(self.pool, None);
            self.surface_fn.destroy_surface(self.surface, None);
        }
    }
}
