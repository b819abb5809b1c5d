//! The window's event loop: [`run`] opens the window and the presenter, and each redraw
//! renders a frame from the [`FrameSource`] for the controls' camera and options, accumulates
//! or denoises it, lays the panel out and presents it.

use std::time::Instant;

use motu_gpu::{PanelPaint, Presented, Presenter, View};
use winit::application::ApplicationHandler;
use winit::dpi::PhysicalSize;
use winit::event::{ElementState, MouseButton, MouseScrollDelta, WindowEvent};
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::keyboard::{KeyCode, ModifiersState, PhysicalKey};
use winit::raw_window_handle::{HasDisplayHandle, HasWindowHandle};
use winit::window::{Window, WindowId};

use motu_abi::camera::CameraPose;

use crate::{
    check_display, guide, panel, progressive, script, Controls, FrameSource, Motion, SourceFrame,
    ViewError, ViewOptions, ViewResult,
};

/// Opens the window and runs until it is closed (or `opts.frames` frames were shown).
/// `make_source` gets the options with [`ViewOptions::display`] set and opens the device and
/// the scene on it.
pub fn run<S, F>(mut opts: ViewOptions, make_source: F) -> Result<ViewResult, ViewError>
where
    S: FrameSource,
    F: FnOnce(&ViewOptions) -> Result<S, String>,
{
    check_display()?;
    let event_loop = EventLoop::new().map_err(|e| ViewError::WindowSystem {
        source: Box::new(e),
        hint: " (motu view opens X11 and Wayland windows: check DISPLAY / WAYLAND_DISPLAY, or \
               render headless with `motu render`)",
    })?;
    let display = event_loop
        .display_handle()
        .map_err(ViewError::window_system)?
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
        .map_err(ViewError::window_system)?;
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
        let window = el.create_window(attrs).map_err(ViewError::window_system)?;
        let size = window.inner_size();
        let display = window
            .display_handle()
            .map_err(ViewError::window_system)?
            .as_raw();
        let handle = window
            .window_handle()
            .map_err(ViewError::window_system)?
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
        let pose = self.step_camera(dt);
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
                self.record_shown(ShownFrame {
                    frame,
                    pose,
                    size: [w, h],
                    readback,
                    last,
                    samples,
                    denoised,
                });
            }
        }
        if let Some(n) = self.opts.frames {
            if self.result.frames_shown >= u64::from(n) {
                el.exit();
            }
        }
        Ok(())
    }

    /// Moves the fly camera by the held keys over `dt` seconds (faster with Shift); returns
    /// the frame's pose (the replayed one, when replaying).
    fn step_camera(&mut self, dt: f32) -> CameraPose {
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
        match &self.opts.replay {
            Some(p) if !p.is_empty() => p[index.min(p.len() - 1)],
            _ => self.ctl.fly.pose,
        }
    }

    /// Adds a presented frame to the run's result and the panel's history.
    fn record_shown(&mut self, shown: ShownFrame) {
        let ShownFrame {
            frame,
            pose,
            size,
            readback,
            last,
            samples,
            denoised,
        } = shown;
        self.result.frame_ms.push(self.last_frame_ms);
        self.history
            .push(self.last_frame_ms, frame.output.stats.ms_per_frame);
        self.result.frames_shown += 1;
        self.result.incomplete_frames += u64::from(frame.stats.incomplete_pixels > 0);
        self.result
            .incomplete_pixels_per_frame
            .push(frame.stats.incomplete_pixels);
        self.result.poses.push(pose);
        self.result.last_size = size;
        if last {
            self.result.screenshot_rgba8 = readback;
        }
        self.result.accumulated_samples = samples;
        self.result.denoised = denoised;
        self.result.last = Some(frame);
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

/// A frame that reached the window, for [`App::record_shown`].
struct ShownFrame {
    frame: SourceFrame,
    pose: CameraPose,
    size: [u32; 2],
    /// The swapchain image read back, if it was (the screenshot of the last frame).
    readback: Option<Vec<u8>>,
    last: bool,
    samples: u32,
    denoised: bool,
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
