//! motu-view: the interactive viewer behind `motu view`.
//!
//! A winit window whose frames come from a [`FrameSource`] ([`PackageSource`]: a package's
//! full GPU build or the streaming renderer, on a [`motu_gpu::Context`] opened for
//! presentation) and reach the screen through [`motu_gpu::Presenter`] (surface and swapchain
//! live in motu-gpu: no Vulkan here).
//! A fly camera, the scene's cameras on number keys, views, LOD modes and element toggles
//! change the next frame's [`RenderOptions`]; an egui panel ([`panel`]) shows the frame's
//! numbers and offers the same controls as widgets. The presenter draws the panel over the
//! frame after the screenshot's read-back, so neither `--screenshot` nor `--aov` contains it.
//! For tests and scripts, [`ViewOptions::frames`] renders that many frames through the real
//! window and swapchain, reads the last one back from the swapchain image and exits.
//! Files: this root holds the public types; `app.rs` the window's event loop ([`run`]),
//! `controls.rs` the keys, `fly.rs` the camera, `package.rs` the package source, `panel.rs` the
//! panel, `progressive.rs` accumulation and denoising.

mod app;
mod controls;
mod fly;
mod guide;
mod package;
pub mod panel;
pub mod progressive;
mod script;

use motu_abi::camera::{CameraParams, CameraPose};
use motu_gpu::{RenderOptions, RenderOutput};

pub use app::run;
pub use controls::{Controls, Keys};
pub use fly::{FlyCamera, Motion};
pub use package::{
    chain, default_fly_speed, scene_cameras, PackageSource, PackageSourceSettings, SourceError,
    ViewStreamSettings,
};
pub use script::PanelClick;

/// Errors of the viewer; the CLI adds context.
#[derive(Debug, thiserror::Error)]
pub enum ViewError {
    #[error(
        "no display: neither DISPLAY nor WAYLAND_DISPLAY is set, so `motu view` cannot open a \
         window. Render headless with `motu render` instead (same --camera, --view, --aov, \
         --stats; `--camera-path FILE --frames N` replays a recorded flight)"
    )]
    NoDisplay,
    #[error("the window system failed: {0}")]
    Window(String),
    /// A window-system call (winit, its window handles) failed: its error kept as the cause,
    /// `hint` saying what to check.
    #[error("the window system failed: {source}{hint}")]
    WindowSystem {
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
        hint: &'static str,
    },
    #[error(transparent)]
    Gpu(#[from] motu_gpu::GpuError),
    #[error("{0}")]
    Source(String),
    #[error(
        "the last frame is incomplete ({0} pixels unfinished after the streaming pass cap): \
         render more frames (--frames) or raise --vram-budget; a wrong image is not written"
    )]
    Incomplete(u64),
    /// A scripted panel click that could not be played (`--panel-click`).
    #[error("{0}")]
    PanelScript(String),
    #[error(
        "the window is {got_w}×{got_h}, not the requested {want_w}×{want_h} (a window manager \
         resized it?): the screenshot would not show the requested frame"
    )]
    WrongSize {
        got_w: u32,
        got_h: u32,
        want_w: u32,
        want_h: u32,
    },
}

impl ViewError {
    /// A window-system error kept as the cause, with no hint.
    pub(crate) fn window_system(e: impl std::error::Error + Send + Sync + 'static) -> ViewError {
        ViewError::WindowSystem {
            source: Box::new(e),
            hint: "",
        }
    }
}

/// Whether a window system is reachable (`DISPLAY` or `WAYLAND_DISPLAY` set and not empty).
pub fn check_display() -> Result<(), ViewError> {
    let set = |k: &str| std::env::var_os(k).is_some_and(|v| !v.is_empty());
    if set("DISPLAY") || set("WAYLAND_DISPLAY") {
        Ok(())
    } else {
        Err(ViewError::NoDisplay)
    }
}

/// Numbers for the panel that only the source knows.
#[derive(Clone, Debug, Default)]
pub struct SourceStats {
    pub vram_used_bytes: u64,
    pub vram_budget_bytes: u64,
    pub resident_structures: u64,
    pub total_structures: u64,
    /// Streaming: the frame's build–trace passes (1 for a full build).
    pub passes: u32,
    /// Streaming: structures built and evicted this frame; `None` for a full build.
    pub streaming: Option<(u32, u32)>,
    /// Pixels left unfinished by the frame's pass cap (streaming; refined by later frames).
    /// Shown while flying; a scripted run fails if its last frame has any.
    pub incomplete_pixels: u64,
    /// Streaming: TLAS pieces left stale by the frame (`tlas_pieces_stale`: rebuilt by later
    /// frames within their build budget; their new structures' pixels show the fallback).
    pub tlas_pieces_stale: u32,
    /// How LOD ran: `instance`, `traversal` or `none` (no LOD selectors); empty if unknown.
    pub lod_mode: &'static str,
    /// Streaming: whether the budget held the whole scene, so the full build draws it
    /// (`stream_fit` in `--stats`, as `motu render --stream`'s); `None` without streaming or
    /// with `--stream-always`.
    pub stream_fit: Option<motu_render::stats::StreamFitStats>,
}

/// One rendered frame.
#[derive(Debug)]
pub struct SourceFrame {
    pub output: RenderOutput,
    pub stats: SourceStats,
    /// The renderer's detail for `--stats` (a full build's resources, a streamed frame's
    /// statistics).
    pub detail: Option<motu_render::stats::ViewDetail>,
}

/// What the viewer draws from; [`PackageSource`] implements it over a package.
pub trait FrameSource {
    /// The device (opened with [`motu_gpu::ContextOptions::presentation`]).
    fn context(&self) -> &motu_gpu::Context;
    /// Renders `camera` with `opts`, showing only the elements whose entry in `elements_on` is
    /// true (a change of the set may rebuild structures). `lod_instance`: instance-level LOD
    /// where the rule allows it (the source falls back to the traversal shader otherwise and
    /// says so in [`SourceStats::lod_mode`]); a change may rebuild structures.
    fn render(
        &mut self,
        camera: &CameraParams,
        opts: &RenderOptions,
        elements_on: &[bool],
        lod_instance: bool,
    ) -> Result<SourceFrame, String>;
    /// A source mesh's base colour (the denoiser's material guide).
    fn base_colour(&self, _mesh: u32) -> [f32; 3] {
        [0.5; 3]
    }
    /// Whether a material has a base-colour texture (the denoiser's guide then renders the
    /// albedo view).
    fn textured(&self) -> bool {
        false
    }
}

/// How the viewer starts.
#[derive(Clone, Debug)]
pub struct ViewOptions {
    pub title: String,
    /// Initial window (and, with `frames`, exact image) size.
    pub width: u32,
    pub height: u32,
    pub start: CameraPose,
    /// The scene's cameras (number keys 1–9).
    pub cameras: Vec<(String, CameraPose)>,
    pub render: RenderOptions,
    /// Instance-level LOD at the start (M toggles it with the traversal shader's LOD).
    pub lod_instance: bool,
    /// Element names and which are on at the start (Shift+1–9 toggle).
    pub elements: Vec<String>,
    pub elements_on: Vec<bool>,
    /// Fly speed in world units per second.
    pub speed: f32,
    /// Render this many frames, read the last back from the swapchain, exit.
    pub frames: Option<u32>,
    /// Poses to play, one per frame (a replayed camera path); the fly camera otherwise.
    pub replay: Option<Vec<CameraPose>>,
    /// Show the panel at the start (Tab toggles it).
    pub panel: bool,
    pub vsync: bool,
    /// Accumulate samples while the camera rests (P toggles; [`progressive`]).
    pub accumulate: bool,
    /// Filter the shown image (N toggles; `motu render --denoise`'s filter, never the AOV).
    pub denoise: bool,
    /// Scripted clicks on the panel (`--panel-click`; [`PanelClick`]).
    pub panel_clicks: Vec<PanelClick>,
    /// Open the window (and create the device) for this display; set by [`run`].
    pub display: Option<motu_gpu::RawDisplayHandle>,
}

/// What a run leaves behind.
#[derive(Debug, Default)]
pub struct ViewResult {
    /// Frames rendered and shown.
    pub frames_shown: u64,
    /// The last frame as shown (accumulated and denoised as the window showed it, the AOV the
    /// run's first frame's), without the panel.
    pub last: Option<SourceFrame>,
    /// The last frame as read back from the swapchain image (automation mode).
    pub screenshot_rgba8: Option<Vec<u8>>,
    pub last_size: [u32; 2],
    /// The pose of every frame shown (for `--record`).
    pub poses: Vec<CameraPose>,
    /// Wall-clock milliseconds per shown frame (render + present).
    pub frame_ms: Vec<f64>,
    /// Frames shown with pixels still refining (streaming pass cap or frame build budget).
    pub incomplete_frames: u64,
    /// Per shown frame: its pixels still refining (unfinished, or the streaming fallback).
    pub incomplete_pixels_per_frame: Vec<u64>,
    /// Samples per pixel in the last frame shown (accumulated while the camera rested).
    pub accumulated_samples: u32,
    /// Whether the last frame shown was denoised.
    pub denoised: bool,
    /// Frames presented with the panel drawn over them (after the read-back).
    pub panel_frames: u64,
    /// Pixels of the last frame that the panel changed on the window (read back again after
    /// drawing it; 0 without a panel or a screenshot).
    pub panel_pixels: u64,
}

#[cfg(test)]
mod testutil;
