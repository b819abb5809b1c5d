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

mod controls;
mod fly;
mod guide;
mod package;
pub mod panel;
pub mod progressive;
mod script;

use std::time::Instant;

use motu_abi::camera::{CameraParams, CameraPose};
use motu_gpu::{PanelPaint, Presented, Presenter, RenderOptions, RenderOutput, View};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, ModifiersState, PhysicalKey};
use winit::raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use winit::window::{Window, WindowId};

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
    /// How LOD ran: `instance`, `traversal` or `none` (no LOD selectors); empty if unknown.
    pub lod_mode: &'static str,
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

/// Opens the window and runs until it is closed (or `opts.frames` frames were shown).
/// `make_source` gets the options with [`ViewOptions::display`] set and opens the device and
/// the scene on it.
pub fn run<S, F>(mut opts: ViewOptions, make_source: F) -> Result<ViewResult, ViewError>
where
    S: FrameSource,
    F: FnOnce(&ViewOptions) -> Result<S, String>,
{
    check_display()?;
    let event_loop = EventLoop::new().map_err(|e| {
        ViewError::Window(format!(
            "{e} (motu view opens X11 and Wayland windows: check DISPLAY / WAYLAND_DISPLAY, or \
             render headless with `motu render`)"
        ))
    })?;
    let display = event_loop
        .display_handle()
        .map_err(|e| ViewError::Window(e.to_string()))?
        .as_raw();
    opts.display = Some(display);
    let source = make_source(&opts).map_err(ViewError::Source)?;
    let ctl = Controls::new(&opts);
    let script = script::PanelScript::new(&opts.panel_clicks);
    let mut app = App {
        source,
        ctl,
        window: None,
        presenter: None,
        result: ViewResult::default(),
        error: None,
        modifiers: ModifiersState::empty(),
        dragging: false,
        cursor: None,
        last_tick: Instant::now(),
        last_frame_ms: 0.0,
        skips: 0,
        accum: progressive::Accumulator::default(),
        egui: egui::Context::default(),
        egui_input: None,
        history: panel::History::default(),
        textures: egui::TexturesDelta::default(),
        script,
        opts,
    };
    event_loop.set_control_flow(ControlFlow::Poll);
    event_loop
        .run_app(&mut app)
        .map_err(|e| ViewError::Window(e.to_string()))?;
    // Destroy the swapchain and surface before the window.
    app.presenter = None;
    app.egui_input = None;
    app.window = None;
    if let Some(e) = app.error {
        return Err(e);
    }
    if let Some(e) = app.script.unplayed() {
        return Err(ViewError::PanelScript(e));
    }
    Ok(app.result)
}

struct App<S: FrameSource> {
    source: S,
    ctl: Controls,
    window: Option<Window>,
    presenter: Option<Presenter>,
    result: ViewResult,
    error: Option<ViewError>,
    modifiers: ModifiersState,
    dragging: bool,
    cursor: Option<(f64, f64)>,
    last_tick: Instant,
    last_frame_ms: f64,
    skips: u32,
    accum: progressive::Accumulator,
    /// The panel's UI state and its window input (created with the window).
    egui: egui::Context,
    egui_input: Option<egui_winit::State>,
    history: panel::History,
    /// Texture changes egui made that no presented panel has uploaded yet.
    textures: egui::TexturesDelta,
    script: script::PanelScript,
    opts: ViewOptions,
}

const VIEWS: [View; 4] = [View::Shaded, View::Ids, View::Lod, View::Heatmap];

pub(crate) fn view_name(v: View) -> &'static str {
    match v {
        View::Shaded => "shaded",
        View::Ids => "ids",
        View::Lod => "lod",
        View::Heatmap => "heatmap",
        View::Albedo => "albedo",
    }
}

impl<S: FrameSource> App<S> {
    fn fail(&mut self, el: &ActiveEventLoop, e: ViewError) {
        if self.error.is_none() {
            self.error = Some(e);
        }
        el.exit();
    }

    fn open_window(&mut self, el: &ActiveEventLoop) -> Result<(), ViewError> {
        let attrs = Window::default_attributes()
            .with_title(self.opts.title.clone())
            .with_inner_size(PhysicalSize::new(self.opts.width, self.opts.height))
            .with_resizable(self.opts.frames.is_none());
        let window = el
            .create_window(attrs)
            .map_err(|e| ViewError::Window(e.to_string()))?;
        let size = window.inner_size();
        let display = window
            .display_handle()
            .map_err(|e| ViewError::Window(e.to_string()))?
            .as_raw();
        let handle = window
            .window_handle()
            .map_err(|e| ViewError::Window(e.to_string()))?
            .as_raw();
        // SAFETY: the handles belong to `window`, which `run` drops only after the presenter.
        let presenter = unsafe {
            Presenter::new(
                self.source.context(),
                display,
                handle,
                [size.width, size.height],
                self.opts.vsync,
            )
        }
        .map_err(motu_gpu::GpuError::from)?;
        self.presenter = Some(presenter);
        self.egui_input = Some(egui_winit::State::new(
            self.egui.clone(),
            egui::ViewportId::ROOT,
            &window,
            Some(window.scale_factor() as f32),
            None,
            None,
        ));
        self.window = Some(window);
        Ok(())
    }

    fn on_key(&mut self, el: &ActiveEventLoop, code: KeyCode, pressed: bool) {
        if self.ctl.key(code, pressed, self.modifiers.shift_key()) {
            el.exit();
        }
    }

    fn frame(&mut self, el: &ActiveEventLoop) -> Result<(), ViewError> {
        let now = Instant::now();
        let dt = (now - self.last_tick).as_secs_f32().min(0.25);
        self.last_tick = now;
        let Some(presenter) = self.presenter.as_mut() else {
            return Ok(());
        };
        let extent = presenter.prepare().map_err(motu_gpu::GpuError::from)?;
        let automated = self.opts.frames.is_some();
        let [w, h] = if automated {
            [self.opts.width, self.opts.height]
        } else {
            extent
        };
        if extent == [0, 0] {
            self.skips += 1;
            return self.check_skips();
        }
        if automated && extent != [w, h] {
            return Err(ViewError::WrongSize {
                got_w: extent[0],
                got_h: extent[1],
                want_w: w,
                want_h: h,
            });
        }
        let k = &self.ctl.keys;
        let axis = |a: bool, b: bool| f32::from(u8::from(a)) - f32::from(u8::from(b));
        let motion = Motion {
            right: axis(k.right, k.left),
            up: axis(k.up, k.down),
            forward: axis(k.forward, k.back),
        };
        let fast = if self.modifiers.shift_key() { 4.0 } else { 1.0 };
        self.ctl.fly.speed *= fast;
        self.ctl.fly.step(motion, dt);
        self.ctl.fly.speed /= fast;
        let index = self.result.frames_shown as usize;
        let pose = match &self.opts.replay {
            Some(p) if !p.is_empty() => p[index.min(p.len() - 1)],
            _ => self.ctl.fly.pose,
        };
        let camera = pose.params(w, h);
        let t0 = Instant::now();
        let mut opts = self.ctl.render;
        let first = if self.ctl.accumulate {
            self.accum
                .first_sample(&camera, &opts, &self.ctl.elements_on, self.ctl.lod_instance)
        } else {
            self.accum.reset();
            None
        };
        opts.shading.first_sample = first.unwrap_or(0);
        let mut frame = self
            .source
            .render(&camera, &opts, &self.ctl.elements_on, self.ctl.lod_instance)
            .map_err(ViewError::Source)?;
        let last = automated && self.opts.frames == Some(self.result.frames_shown as u32 + 1);
        if last && frame.stats.incomplete_pixels > 0 {
            return Err(ViewError::Incomplete(frame.stats.incomplete_pixels));
        }
        // A streamed frame still refining changes from frame to frame: it starts again.
        let samples = match first {
            Some(_) if frame.stats.incomplete_pixels == 0 => {
                self.accum.add(&mut frame.output, &opts)
            }
            _ => {
                self.accum.reset();
                opts.shading.spp
            }
        };
        let denoised = self.ctl.denoise && opts.view == View::Shaded;
        if denoised {
            let (on, lod_instance) = (&self.ctl.elements_on, self.ctl.lod_instance);
            guide::denoise(
                &mut self.source,
                &mut frame.output,
                &camera,
                &opts,
                on,
                lod_instance,
            )
            .map_err(ViewError::Source)?;
        }
        let primitives = if self.ctl.panel {
            let info = panel::PanelInfo {
                width: w,
                height: h,
                backend: frame.output.stats.backend,
                frame_ms: self.last_frame_ms,
                gpu_ms: frame.output.stats.ms_per_frame,
                rays_per_second: frame.output.stats.rays_per_second,
                traces_per_ray: frame.output.stats.traces_per_ray,
                exposure_ev: frame.output.stats.exposure_ev,
                stats: frame.stats.clone(),
                samples,
                denoised,
            };
            self.run_panel(&info)?
        } else {
            None
        };
        let Some(presenter) = self.presenter.as_mut() else {
            return Ok(());
        };
        let paint = primitives.as_ref().map(|(p, ppp)| PanelPaint {
            primitives: p,
            textures: &self.textures,
            pixels_per_point: *ppp,
        });
        match presenter
            .present(&frame.output.rgba8, w, h, last, paint.as_ref())
            .map_err(motu_gpu::GpuError::from)?
        {
            Presented::Skipped => {
                self.skips += 1;
                return self.check_skips();
            }
            Presented::Shown {
                readback,
                panel,
                shown,
            } => {
                if panel {
                    // Uploaded: the next panel starts from these textures.
                    self.textures = egui::TexturesDelta::default();
                    self.result.panel_frames += 1;
                }
                if let (Some(shot), Some(shown)) = (&readback, &shown) {
                    self.result.panel_pixels = shot
                        .chunks_exact(4)
                        .zip(shown.chunks_exact(4))
                        .filter(|(a, b)| a[..3] != b[..3])
                        .count() as u64;
                }
                self.skips = 0;
                self.last_frame_ms = t0.elapsed().as_secs_f64() * 1e3;
                self.result.frame_ms.push(self.last_frame_ms);
                self.history
                    .push(self.last_frame_ms, frame.output.stats.ms_per_frame);
                self.result.frames_shown += 1;
                self.result.incomplete_frames += u64::from(frame.stats.incomplete_pixels > 0);
                self.result
                    .incomplete_pixels_per_frame
                    .push(frame.stats.incomplete_pixels);
                self.result.poses.push(pose);
                self.result.last_size = [w, h];
                if last {
                    self.result.screenshot_rgba8 = readback;
                }
                self.result.accumulated_samples = samples;
                self.result.denoised = denoised;
                self.result.last = Some(frame);
            }
        }
        if let Some(n) = self.opts.frames {
            if self.result.frames_shown >= u64::from(n) {
                el.exit();
            }
        }
        Ok(())
    }

    fn check_skips(&self) -> Result<(), ViewError> {
        // Minimised interactive windows wait; automation must not spin forever.
        if self.opts.frames.is_some() && self.skips > 200 {
            return Err(ViewError::Window(
                "the window never became presentable (200 frames skipped)".into(),
            ));
        }
        Ok(())
    }

    /// Lays the panel out (applying its changes to the controls) and tessellates it; the
    /// new textures join `self.textures` until a presented panel uploads them.
    /// Scripted clicks ([`script`]) join the window's input.
    #[allow(clippy::type_complexity)]
    fn run_panel(
        &mut self,
        info: &panel::PanelInfo,
    ) -> Result<Option<(Vec<egui::ClippedPrimitive>, f32)>, ViewError> {
        let (Some(state), Some(window)) = (self.egui_input.as_mut(), self.window.as_ref()) else {
            return Ok(None);
        };
        let mut input = state.take_egui_input(window);
        let frame = self.result.frames_shown as u32;
        self.script
            .inject(frame, &mut input)
            .map_err(ViewError::PanelScript)?;
        let (ctl, history) = (&mut self.ctl, &self.history);
        let out = self
            .egui
            .run(input, |ctx| panel::build(ctx, info, history, ctl));
        if !self.script.is_empty() {
            self.script.observe(&out.shapes);
        }
        state.handle_platform_output(window, out.platform_output);
        self.textures.append(out.textures_delta);
        let primitives = self.egui.tessellate(out.shapes, out.pixels_per_point);
        Ok(Some((primitives, out.pixels_per_point)))
    }
}

impl<S: FrameSource> ApplicationHandler for App<S> {
    fn resumed(&mut self, el: &ActiveEventLoop) {
        if self.window.is_none() {
            if let Err(e) = self.open_window(el) {
                self.fail(el, e);
            }
        }
    }

    fn window_event(&mut self, el: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        // The panel sees every event; what it takes (a click on it, a focused slider's keys)
        // does not reach the camera. Tab and Esc always do.
        let taken = match (
            self.ctl.panel,
            self.egui_input.as_mut(),
            self.window.as_ref(),
        ) {
            (true, Some(state), Some(window)) => state.on_window_event(window, &event).consumed,
            _ => false,
        };
        match event {
            WindowEvent::CloseRequested => el.exit(),
            WindowEvent::Resized(size) => {
                if let Some(p) = self.presenter.as_mut() {
                    p.resize([size.width, size.height]);
                }
            }
            WindowEvent::ModifiersChanged(m) => self.modifiers = m.state(),
            WindowEvent::KeyboardInput { event, .. } => {
                if let PhysicalKey::Code(code) = event.physical_key {
                    let always = matches!(code, KeyCode::Tab | KeyCode::Escape);
                    if self.opts.frames.is_none() && (always || !taken) {
                        self.on_key(el, code, event.state == ElementState::Pressed);
                    }
                }
            }
            WindowEvent::MouseInput { state, button, .. } => {
                if matches!(button, MouseButton::Left | MouseButton::Right) {
                    self.dragging = state == ElementState::Pressed && !taken;
                }
            }
            WindowEvent::CursorMoved { position, .. } => {
                if let (true, Some((x, y))) = (self.dragging, self.cursor) {
                    let rad_per_px = 0.004;
                    self.ctl
                        .fly
                        .look((position.x - x) as f32, (position.y - y) as f32, rad_per_px);
                }
                self.cursor = Some((position.x, position.y));
            }
            WindowEvent::MouseWheel { .. } if taken => {}
            WindowEvent::MouseWheel { delta, .. } => {
                let notches = match delta {
                    MouseScrollDelta::LineDelta(_, y) => y,
                    MouseScrollDelta::PixelDelta(p) => (p.y / 40.0) as f32,
                };
                self.ctl.fly.speed = (self.ctl.fly.speed * 1.25f32.powf(notches)).clamp(1e-6, 1e9);
            }
            WindowEvent::RedrawRequested => {
                if let Err(e) = self.frame(el) {
                    self.fail(el, e);
                }
            }
            _ => {}
        }
    }

    fn about_to_wait(&mut self, _el: &ActiveEventLoop) {
        if let Some(w) = &self.window {
            w.request_redraw();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;

    pub(crate) fn pose(z: f32) -> CameraPose {
        CameraPose {
            world_eye: Vec3::new(0.0, 0.0, z),
            world_forward: Vec3::NEG_Z,
            world_up: Vec3::Y,
            fov_deg: 45.0,
            mirror_x: false,
        }
    }

    pub(crate) fn controls() -> Controls {
        Controls::new(&ViewOptions {
            title: String::new(),
            width: 8,
            height: 8,
            start: pose(0.0),
            cameras: vec![("a".into(), pose(1.0)), ("b".into(), pose(2.0))],
            render: RenderOptions::default(),
            lod_instance: true,
            elements: vec!["x".into(), "y".into()],
            elements_on: vec![true, true],
            speed: 1.0,
            frames: None,
            replay: None,
            panel: true,
            vsync: true,
            accumulate: true,
            denoise: false,
            panel_clicks: Vec::new(),
            display: None,
        })
    }

    fn press(c: &mut Controls, code: KeyCode, shift: bool) -> bool {
        let quit = c.key(code, true, shift);
        c.key(code, false, shift);
        quit
    }

    #[test]
    fn keys_switch_views_lod_cameras_elements_and_panel() {
        let mut c = controls();
        press(&mut c, KeyCode::KeyV, false);
        assert_eq!(c.render.view, View::Ids);
        press(&mut c, KeyCode::F4, false);
        assert_eq!(c.render.view, View::Heatmap);
        press(&mut c, KeyCode::KeyV, false);
        assert_eq!(c.render.view, View::Shaded);
        // LOD: auto → 0 → 1 … → 7 → auto.
        assert!(c.render.lod.forced_lod < 0);
        press(&mut c, KeyCode::KeyL, false);
        assert_eq!(c.render.lod.forced_lod, 0);
        for _ in 0..7 {
            press(&mut c, KeyCode::KeyL, false);
        }
        assert_eq!(c.render.lod.forced_lod, 7);
        press(&mut c, KeyCode::KeyL, false);
        assert!(c.render.lod.forced_lod < 0);
        // LOD mode: instance ↔ traversal.
        assert!(c.lod_instance);
        press(&mut c, KeyCode::KeyM, false);
        assert!(!c.lod_instance);
        press(&mut c, KeyCode::KeyM, false);
        assert!(c.lod_instance);
        // Cameras on digits; a missing one changes nothing.
        press(&mut c, KeyCode::Digit2, false);
        assert_eq!(c.fly.pose, pose(2.0));
        press(&mut c, KeyCode::Digit9, false);
        assert_eq!(c.fly.pose, pose(2.0));
        // Elements on Shift+digits; the last one stays on; Shift+0 turns all on.
        press(&mut c, KeyCode::Digit1, true);
        assert_eq!(c.elements_on, [false, true]);
        press(&mut c, KeyCode::Digit2, true);
        assert_eq!(c.elements_on, [false, true], "{}", c.message);
        press(&mut c, KeyCode::Digit0, true);
        assert_eq!(c.elements_on, [true, true]);
        assert_eq!(c.fly.pose, pose(2.0), "Shift+digit is not a camera");
        press(&mut c, KeyCode::Tab, false);
        assert!(!c.panel);
        press(&mut c, KeyCode::KeyH, false);
        assert!(!c.render.shadows);
        assert!(press(&mut c, KeyCode::Escape, false));
    }

    #[test]
    fn movement_keys_hold_until_released() {
        let mut c = controls();
        c.key(KeyCode::KeyW, true, false);
        c.key(KeyCode::KeyE, true, false);
        assert!(c.keys.forward && c.keys.up);
        c.key(KeyCode::KeyW, false, false);
        assert!(!c.keys.forward && c.keys.up);
    }
}
