//! Bounded work per frame: the frame's build budget (bytes, milliseconds), the progressive
//! mode ("trace this frame with what is resident, the fallback for the rest, build toward the
//! next frame"), and the frame buffers kept between frames of one size.

use std::time::Instant;

use motu_abi::camera::CameraParams;

use super::buffers::{alloc_frame_buffers, FrameBuffers};
use super::clock::FrameClock;
use super::{FrameStreamStats, StreamFallback, StreamingRenderer};
use crate::error::Result;
use crate::render::{FrameParams, RenderOptions, RenderOutput};

/// Frame buffers with the image size and guard-band length they were made for.
pub(super) struct KeptFrameBuffers {
    pub buffers: FrameBuffers,
    pub width: u32,
    pub height: u32,
    pub guard_len: usize,
}

/// State kept between frames.
#[derive(Default)]
pub(super) struct Kept {
    /// The last frame's buffers: reused while their size and guard length stay the same (no
    /// allocation per frame, and a prefetch never takes the room the next frame's buffers
    /// need).
    frame_buffers: Option<KeptFrameBuffers>,
    /// When the running build step started (its time counts against `frame_build_ms`).
    step_start: Option<Instant>,
    /// Pass cap of the running frame when set ([`StreamingRenderer::render_progressive`]).
    pass_cap: Option<u32>,
    /// The running frame's camera: stale TLASes it sees are rebuilt first
    /// (`piece_order.rs`).
    camera: Option<CameraParams>,
    /// Open pixels the running frame's passes left waiting (not traced again) because their
    /// blocker was resident under a stale TLAS (`stale_blocked_pixels`).
    stale_waiting: u64,
    /// The last frame stopped with pixels open: under a frame build budget (a refining
    /// frame), the running one most likely spends its budget in its first build step too.
    pub(super) refining: bool,
    /// The last progressive frame's camera, and how many progressive frames there were
    /// incomplete since it came there ([`StreamingRenderer::render_progressive`]).
    progressive_camera: Option<CameraParams>,
    still_incomplete: u32,
    /// The running frame settles a camera at rest: no frame build budget, so it takes passes
    /// until complete ([`StreamingRenderer::render_progressive`]).
    settling: bool,
    /// The whole-frame clock: the running frame's start and this device's estimates
    /// (`StreamOptions::frame_ms`, `clock.rs`).
    clock: FrameClock,
    /// The running frame is progressive and names a next camera other than its own: on the
    /// clock it flies (`flying.rs`).
    moving: bool,
}

impl Kept {
    /// A frame starts: its clock starts, no build step runs yet.
    pub(super) fn begin_frame(&mut self) {
        self.step_start = None;
        self.moving = false;
        self.clock.begin(Instant::now());
    }

    /// The whole-frame clock.
    pub(super) fn clock(&self) -> &FrameClock {
        &self.clock
    }

    /// The whole-frame clock, to sample.
    pub(super) fn clock_mut(&mut self) -> &mut FrameClock {
        &mut self.clock
    }

    /// A build step starts at `t0`: its time counts against the frame's build budget while it
    /// runs.
    pub(super) fn start_step(&mut self, t0: Instant) {
        self.step_start = Some(t0);
    }

    /// The running build step is over (its time is in the frame's `build_ms`).
    pub(super) fn end_step(&mut self) {
        self.step_start = None;
    }

    /// The running frame names `next` as the next frame's camera: it moves when it is a
    /// progressive frame ([`StreamingRenderer::render_progressive`]) and `next` is another
    /// camera than its own (set by [`Self::set_camera`] first).
    pub(super) fn set_next(&mut self, next: Option<&CameraParams>) {
        self.moving = self.pass_cap.is_some() && next.is_some() && next != self.camera.as_ref();
    }

    /// Whether the running frame moves (see [`Self::set_next`]).
    pub(super) fn moving(&self) -> bool {
        self.moving
    }

    /// The running frame's camera (`piece_order.rs`).
    pub(super) fn set_camera(&mut self, camera: CameraParams) {
        self.camera = Some(camera);
    }

    pub(super) fn camera(&self) -> Option<&CameraParams> {
        self.camera.as_ref()
    }

    /// Open pixels left waiting under stale TLASes by the running frame's passes so far.
    pub(super) fn set_stale_waiting(&mut self, pixels: u64) {
        self.stale_waiting = pixels;
    }

    pub(super) fn stale_waiting(&self) -> u64 {
        self.stale_waiting
    }

    /// Milliseconds the running build step has taken so far (0 when none runs).
    fn step_ms_now(&self) -> f64 {
        self.step_start
            .map_or(0.0, |t| t.elapsed().as_secs_f64() * 1e3)
    }
}

impl<'a> StreamingRenderer<'a> {
    /// Renders one frame with the structures resident now and builds toward the next one: one
    /// trace pass, pixels whose structures are missing show the fallback
    /// ([`StreamOptions::fallback`](super::StreamOptions::fallback); off: they are unfinished,
    /// magenta), then one build step for what they need, within the frame's build budget
    /// (`frame_build_bytes`/`frame_build_ms`). The next call traces with what was built, so a
    /// viewer stays responsive and the image refines over frames; a frame is exact when
    /// [`FrameStreamStats::complete`]. A camera at rest settles: after
    /// [`StreamOptions::settle_after_still_frames`](super::StreamOptions::settle_after_still_frames)
    /// incomplete frames at the same camera, each further one
    /// there takes passes until complete, without the frame build budget (until the camera
    /// moves), so a still view reaches the exact image and stays there even where one pass a
    /// frame, or a budget a frame, would churn.
    pub fn render_progressive(
        &mut self,
        camera: &CameraParams,
        opts: &RenderOptions,
    ) -> Result<(RenderOutput, FrameStreamStats)> {
        // A settling frame's cap: the options' when above one, else the automatic one (the
        // viewer's flying mode sets one pass in its options).
        let settle_cap = match self.opts.max_passes {
            n if n > 1 => n,
            _ => self.automatic_pass_cap(),
        };
        let after = self.opts.settle_after_still_frames;
        let k = self.frame.kept_mut();
        let still = k.progressive_camera.as_ref() == Some(camera);
        if !still {
            k.still_incomplete = 0;
        }
        let settle = still && after > 0 && k.still_incomplete >= after;
        k.pass_cap = Some(if settle { settle_cap } else { 1 });
        k.settling = settle;
        k.progressive_camera = Some(*camera);
        let r = self.render_frame(camera, opts);
        let k = self.frame.kept_mut();
        k.pass_cap = None;
        k.settling = false;
        // Counted until the camera moves (a complete frame does not reset it): once settled,
        // a still view stays exact instead of going back to one pass and churning again.
        if matches!(&r, Ok((_, st)) if !st.complete) {
            k.still_incomplete += 1;
        }
        r
    }

    /// The running frame's pass cap.
    pub(super) fn frame_pass_cap(&self) -> u32 {
        self.frame
            .kept()
            .pass_cap
            .unwrap_or_else(|| self.max_passes())
    }

    /// Whether a frame that stops with unfinished pixels still builds what they need (for the
    /// next frame): with a fallback, a frame build budget or a progressive frame.
    pub(super) fn builds_after_last_pass(&self) -> bool {
        self.opts.fallback != StreamFallback::Off
            || self.opts.frame_build_bytes > 0
            || self.opts.frame_build_ms > 0.0
            || self.opts.frame_ms > 0.0
            || self.opts.frame_caps.is_some()
            || self.frame.kept().pass_cap.is_some()
    }

    /// Milliseconds built this frame, including the running step.
    fn frame_build_ms_now(&self) -> f64 {
        self.frame.stats().build_ms + self.frame.kept().step_ms_now()
    }

    /// Whether the running frame's first pass is a refining frame's (under a frame build
    /// budget, the last frame stopped with pixels open): its marks would steer nothing. They name structures in
    /// front of open rays' hits besides the nearest (`Demand::later`), which a step builds only
    /// when few pixels are open and the budget is left after the needed ones, and the guard
    /// band's prefetch, which runs only after a complete frame. The nearest open structure of
    /// each open ray, what refines the image, is requested by its first walk, not its mark walk.
    pub(super) fn refining_first_pass(&self) -> bool {
        let (bytes, ms) = self.frame_budget();
        let budget = bytes > 0 || ms > 0.0 || self.clocked();
        budget && self.frame.kept().refining && self.frame.stats().passes <= 1
    }

    /// Whether this frame's build budget is spent, or its clock
    /// ([`Self::clocked`]: no time left, or its BLAS cap built).
    pub(super) fn frame_build_spent(&self) -> bool {
        self.build_budget_spent() || self.clock_spent()
    }

    /// Whether this frame's build budget (`frame_build_bytes`, `frame_build_ms`) is spent.
    pub(super) fn build_budget_spent(&self) -> bool {
        let (bytes, ms) = self.frame_budget();
        (bytes > 0 && self.frame.stats().built_bytes >= bytes)
            || (ms > 0.0 && self.frame_build_ms_now() >= ms)
    }

    /// Whether the running frame is on the whole-frame clock (`StreamOptions::frame_ms` or
    /// `frame_caps`; `clock.rs`): never while a camera at rest settles, which takes passes
    /// until complete.
    pub(super) fn clocked(&self) -> bool {
        !self.frame.kept().settling && (self.opts.frame_ms > 0.0 || self.opts.frame_caps.is_some())
    }

    /// Milliseconds left of the running frame by its clock, its tail's estimate taken off
    /// (infinite off the clock or with counts for times).
    pub(super) fn frame_time_left_ms(&self) -> f64 {
        if !self.clocked() || self.opts.frame_caps.is_some() || self.opts.frame_ms <= 0.0 {
            return f64::INFINITY;
        }
        let clock = self.frame.kept().clock();
        clock.time_left_ms(self.opts.frame_ms, clock.elapsed_ms())
    }

    /// Whether the clock ends the frame's building: its BLAS cap built, or no time left,
    /// once the frame made something resident or rebuilt a stale piece. Before that its
    /// build step still runs, for the one BLAS or piece a frame must take (a trace longer
    /// than the whole frame's time would otherwise stop every frame's refinement).
    fn clock_spent(&self) -> bool {
        if !self.clocked() || !self.frame_progressed() {
            return false;
        }
        match self.opts.frame_caps {
            Some(c) => self.frame.stats().blas_built >= c.blases,
            None => self.frame_time_left_ms() <= 0.0,
        }
    }

    /// Whether the running frame built or restored a BLAS or rebuilt a stale TLAS piece.
    pub(super) fn frame_progressed(&self) -> bool {
        let st = self.frame.stats();
        st.blas_built + st.restored_blases + st.tlas_stale_rebuilt > 0
    }

    /// Whether a complete frame may probe the next camera: its build budget left and, on
    /// the clock, a probe round fits what is left (with counts: `FrameCaps::probe`).
    pub(super) fn probe_within_budget(&self) -> bool {
        if self.frame_build_spent() {
            return false;
        }
        if !self.clocked() {
            return true;
        }
        match self.opts.frame_caps {
            Some(c) => c.probe,
            None => self
                .frame
                .kept()
                .clock()
                .probe_fits(self.frame_time_left_ms()),
        }
    }

    /// BLAS build group `group` took from `t0` to now: a sample of the clock's build cost.
    pub(super) fn note_build_time(&mut self, group: &[u32], t0: Instant) {
        let triangles = group
            .iter()
            .map(|&b| u64::from(self.view.blases[b as usize].primitive_count))
            .sum();
        let ms = t0.elapsed().as_secs_f64() * 1e3;
        self.frame.kept_mut().clock_mut().note_build(ms, triangles);
    }

    /// The running frame ends (its outputs made): its tail and probe rounds are samples of
    /// the clock.
    pub(super) fn end_frame_clock(&mut self) {
        let (rounds, probe_ms) = (self.frame.stats().probe_rounds, self.frame.stats().probe_ms);
        let clock = self.frame.kept_mut().clock_mut();
        if rounds > 0 {
            clock.note_probe(probe_ms / f64::from(rounds));
            // The probe came after the frame's last build decision: not a tail's sample.
            clock.decided(None);
        }
        clock.end(Instant::now());
    }

    /// The running frame's build budget, bytes and milliseconds (0: none): the options', or
    /// none while a camera at rest settles.
    pub(super) fn frame_budget(&self) -> (u64, f64) {
        if self.frame.kept().settling {
            return (0, 0.0);
        }
        (self.opts.frame_build_bytes, self.opts.frame_build_ms)
    }

    /// How many BLASes of `queue` (from its start, at most `max`) the next build group takes:
    /// those that fit in what is left of the frame's byte budget (at least one), and on the
    /// clock of those the ones that fit what is left of its time (or its BLAS cap) next to one
    /// stale piece's rebuild, which may be none; at least one when `must_progress` and the
    /// frame built none yet, so a camera at rest converges (notes/flight.md D3).
    pub(super) fn group_within_frame_budget(
        &self,
        queue: &[u32],
        max: usize,
        must_progress: bool,
    ) -> usize {
        let n = self.group_within_byte_budget(queue, max);
        if !self.clocked() {
            return n;
        }
        let built = self.frame.stats().blas_built;
        let must = must_progress && built == 0;
        if let Some(c) = self.opts.frame_caps {
            let left = c.blases.saturating_sub(built) as usize;
            return n.min(left.max(usize::from(must)));
        }
        // Time for one stale piece kept: the BLASes built make their parents stale, and
        // pixels behind them wait on those rebuilds.
        let clock = self.frame.kept().clock();
        let reserve_ms = if self.defers_stale_tlases() {
            clock.piece_estimate_ms()
        } else {
            0.0
        };
        let triangles = queue[..n]
            .iter()
            .map(|&b| u64::from(self.view.blases[b as usize].primitive_count));
        clock.blases_within(triangles, self.frame_time_left_ms(), reserve_ms, must)
    }

    /// How many BLASes of `queue` (from its start, at most `max`) fit in what is left of the
    /// frame's byte budget by estimate (meshes plus ~64 bytes of structure per triangle); at
    /// least one.
    fn group_within_byte_budget(&self, queue: &[u32], max: usize) -> usize {
        let budget = self.frame_budget().0;
        if budget == 0 {
            return max.min(queue.len());
        }
        let mut left = budget.saturating_sub(self.frame.stats().built_bytes);
        let mut n = 0;
        for &b in queue.iter().take(max) {
            let tris = u64::from(self.view.blases[b as usize].primitive_count);
            // Bytes built: positions and indices, ~64 bytes a triangle of structure.
            let mesh = self.missing_mesh_bytes(b, 12, 12);
            let est = mesh + 64 * tris;
            if n > 0 && est > left {
                break;
            }
            left = left.saturating_sub(est);
            n += 1;
        }
        n.max(1).min(queue.len())
    }

    /// The frame's buffers: last frame's when the size is unchanged (parameters rewritten),
    /// else new ones, evicting for room.
    pub(super) fn frame_buffers(
        &mut self,
        w: u32,
        h: u32,
        guard_len: usize,
        params: &FrameParams,
        shading: &motu_abi::shade::Shading,
    ) -> Result<FrameBuffers> {
        if let Some(kept) = self.frame.kept_mut().frame_buffers.take() {
            let fb = kept.buffers;
            if (kept.width, kept.height, kept.guard_len) == (w, h, guard_len)
                && fb.params.size_bytes() >= crate::render::params_bytes(shading)
            {
                crate::render::write_params(&fb.params, params, shading)?;
                return Ok(fb);
            }
            fb.release(&mut self.heap);
        }
        let pixels = u64::from(w) * u64::from(h);
        let nitems = self.item_count() as u64;
        self.with_eviction_or_rebuilt_tlases(|s| {
            alloc_frame_buffers(
                &mut s.heap,
                w,
                pixels,
                guard_len as u64,
                nitems,
                params,
                shading,
            )
        })
        .map_err(|e| self.skeleton_error("the frame buffers", e))
    }

    /// Takes the kept frame buffers for a use between frames; [`Self::keep_frame_buffers`]
    /// puts them back.
    pub(super) fn take_kept_frame_buffers(&mut self) -> Option<KeptFrameBuffers> {
        self.frame.kept_mut().frame_buffers.take()
    }

    /// Keeps frame buffers for the next frame of the same size.
    pub(super) fn keep_frame_buffers(&mut self, kept: KeptFrameBuffers) {
        if let Some(old) = self.frame.kept_mut().frame_buffers.replace(kept) {
            old.buffers.release(&mut self.heap);
        }
    }
}
