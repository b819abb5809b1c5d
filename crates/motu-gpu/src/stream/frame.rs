//! One frame: trace pipeline and frame buffers, the passes, the prefetch, the statistics.

mod measure;

use motu_abi::camera::CameraParams;

use super::budget::{Kept, KeptFrameBuffers};
use super::buffers::FrameBuffers;
use super::demand::Demand;
use super::passes::{guard_pixels, FrameImage, PROBE_MET, PROBE_RESIDENT};
use super::probe::{ProbeFound, ProbeNeed};
use super::{FrameStreamStats, StreamingRenderer};
use crate::error::{GpuError, Result};
use crate::render::{
    frame_params, Backend, FrameMeasure, RenderOptions, RenderOutput, RenderStats, Tracer,
};

/// The frame part: the frame in progress (its number, statistics and pass stamps), what the
/// probe of the next camera saw, and what is kept between frames (the trace pipeline, the
/// frame buffers, the build clock).
///
/// Invariants: `stamp` only grows (one a pass or probe; the shaders compare stamps); the
/// frame's sightings from `first_stamp` on are what a prefetch keeps resident; `stats` is
/// reset by each frame's start only (or set aside and put back whole around work outside a
/// frame) and handed out at its end; the probe's sightings and need start afresh with each
/// frame's first probe round and add up over its later rounds. Every field is private: the
/// other files count into `stats` through [`FrameState::stats_mut`] (adding to a counter
/// breaks no invariant; replacing the whole is this file's) and reach the rest through the
/// methods below.
pub(super) struct FrameState {
    /// Frames started so far (the current one's number).
    number: u64,
    stats: FrameStreamStats,
    /// The latest pass stamp.
    stamp: u32,
    /// The first stamp whose sightings a prefetch keeps resident: the frame's first pass, or
    /// the probe of the next camera once it ran.
    first_stamp: u32,
    /// The last frame after which [`PassMarks::auto_wanted`](super::PassMarks::auto_wanted)
    /// held (0: none yet).
    pass_marks_held: u64,
    /// The frame's passes are over: what it builds or evicts now is its prefetch.
    prefetching: bool,
    /// The stamp of the frame's first pass.
    pass_first_stamp: u32,
    /// The prefetch keeps what the frame's own passes saw (its working set fits its room,
    /// `StreamOptions::prefetch_keeps_frame`), beside what the probe met.
    keeps_frame: bool,
    /// The next frame's camera, probed after this frame (`set_next_camera`).
    next_camera: Option<CameraParams>,
    /// The caller renders no frame after this one (`set_last_frame`): no prefetch.
    pub(super) last_frame: bool,
    /// Per BLAS, what the last probe saw (`PROBE_MET`, `PROBE_RESIDENT` bits), kept for the
    /// next frame's first pass to say why it missed what it missed; empty when no probe ran.
    probe_sighting: Vec<u8>,
    /// What the probe rounds after this frame used of the resident set (`probe.rs`).
    probe_need: ProbeNeed,
    /// The trace pipeline with the backend and stack size it was made for.
    tracer: Option<FrameTracer>,
    /// State kept between frames: the frame buffers, the frame's build clock (its fields are
    /// `budget.rs`'s, kept by `Kept`'s methods).
    kept: Kept,
}

/// A frame's statistics set aside by [`FrameState::set_stats_aside`]: give them back with
/// [`FrameState::put_stats_back`].
#[must_use = "the frame's statistics come back only through put_stats_back"]
pub(super) struct StatsAside(FrameStreamStats);

/// The streamed frames' trace pipeline and what it was made for: a frame asking for another
/// backend or stack size gets a new one.
pub(super) struct FrameTracer {
    backend: Backend,
    stack_size: u32,
    tracer: Tracer,
    /// Counting mode's stats buffer (`proxy_count.rs`), made by the first pass that needs it.
    counts: Option<super::proxy_count::CountBuffers>,
}

impl FrameState {
    /// The current frame's statistics.
    pub fn stats(&self) -> &FrameStreamStats {
        &self.stats
    }

    /// The current frame's statistics, to count into.
    pub fn stats_mut(&mut self) -> &mut FrameStreamStats {
        &mut self.stats
    }

    /// Sets the frame's statistics aside for work outside any frame (storing structures after
    /// the frames): what is counted until [`Self::put_stats_back`] goes into fresh ones.
    pub fn set_stats_aside(&mut self) -> StatsAside {
        let fresh = FrameStreamStats {
            frame: self.number,
            ..Default::default()
        };
        StatsAside(std::mem::replace(&mut self.stats, fresh))
    }

    /// Puts the statistics set aside back and returns what was counted meanwhile.
    pub fn put_stats_back(&mut self, aside: StatsAside) -> FrameStreamStats {
        std::mem::replace(&mut self.stats, aside.0)
    }

    /// What the frame's probe rounds used of the resident set so far, taken out to add a
    /// round to ([`Self::keep_probe_need`] puts it back); `first`: the frame's first round,
    /// which starts afresh.
    pub fn take_probe_need(&mut self, first: bool) -> ProbeNeed {
        let need = std::mem::take(&mut self.probe_need);
        if first {
            ProbeNeed::default()
        } else {
            need
        }
    }

    /// Keeps what the probe rounds used (see [`Self::take_probe_need`]).
    pub fn keep_probe_need(&mut self, need: ProbeNeed) {
        self.probe_need = need;
    }

    /// Adds a probe round's sightings: per BLAS, `PROBE_MET` where its stamp in `stamps` is
    /// the round's `stamp`, `PROBE_RESIDENT` where `resident`. `first`: the frame's first
    /// round, which starts afresh.
    pub fn note_probe_sighting(
        &mut self,
        stamps: &[u32],
        resident: &[bool],
        stamp: u32,
        first: bool,
    ) {
        if first || self.probe_sighting.len() != stamps.len() {
            self.probe_sighting = vec![0; stamps.len()];
        }
        for ((s, &v), &r) in self.probe_sighting.iter_mut().zip(stamps).zip(resident) {
            *s |=
                (if v >> 2 == stamp { PROBE_MET } else { 0 }) | if r { PROBE_RESIDENT } else { 0 };
        }
    }

    /// Whether a probe round of this frame met BLAS `b` while it was resident (false when
    /// none ran): the next frame's rays need it where it is.
    pub fn probe_met_resident(&self, b: usize) -> bool {
        let both = PROBE_MET | PROBE_RESIDENT;
        self.probe_sighting
            .get(b)
            .is_some_and(|&s| s & both == both)
    }

    /// What the last probe saw (empty when none ran since), forgotten here: the next frame's
    /// first pass reads it once.
    pub fn take_probe_sighting(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.probe_sighting)
    }

    /// State kept between frames.
    pub fn kept(&self) -> &Kept {
        &self.kept
    }

    /// State kept between frames, to change through `Kept`'s methods.
    pub fn kept_mut(&mut self) -> &mut Kept {
        &mut self.kept
    }

    /// The trace pipeline of the current frame, once `ensure_tracer` made it.
    pub fn tracer(&self) -> Option<&Tracer> {
        self.tracer.as_ref().map(|t| &t.tracer)
    }

    /// Counting mode's stats buffer, once a pass made it.
    pub fn proxy_counts(&self) -> Option<&super::proxy_count::CountBuffers> {
        self.tracer.as_ref().and_then(|t| t.counts.as_ref())
    }

    /// Where counting mode's stats buffer is kept (with the trace pipeline, made for it).
    pub fn proxy_counts_slot(&mut self) -> Option<&mut Option<super::proxy_count::CountBuffers>> {
        self.tracer.as_mut().map(|t| &mut t.counts)
    }

    /// Names the next frame's camera (see `StreamingRenderer::set_next_camera`).
    pub fn set_next_camera(&mut self, camera: Option<CameraParams>) {
        self.next_camera = camera;
    }

    /// The current frame's number (frames started so far).
    pub fn number(&self) -> u64 {
        self.number
    }

    /// The latest pass stamp.
    pub fn stamp(&self) -> u32 {
        self.stamp
    }

    /// The first stamp whose sightings a prefetch keeps resident.
    pub fn first_stamp(&self) -> u32 {
        self.first_stamp
    }

    /// The last frame after which the pass marks were wanted (0: none yet).
    pub fn pass_marks_held(&self) -> u64 {
        self.pass_marks_held
    }

    /// A new frame: its number, fresh statistics, its first stamp (the next pass's), its
    /// clock started.
    pub fn begin(&mut self) {
        self.kept.refining = self.number > 0 && !self.stats.complete;
        self.number += 1;
        self.stats = FrameStreamStats {
            frame: self.number,
            ..Default::default()
        };
        self.first_stamp = self.stamp + 1;
        self.pass_first_stamp = self.first_stamp;
        self.prefetching = false;
        self.keeps_frame = false;
        self.kept.begin_frame();
    }

    /// The frame's passes are over: what follows is its prefetch for the next frame, which
    /// keeps what the frame's passes saw when `keeps_frame`.
    pub fn start_prefetch(&mut self, keeps_frame: bool) {
        self.prefetching = true;
        self.keeps_frame = keeps_frame;
        self.stats.prefetch_kept_frame = keeps_frame;
    }

    /// The first stamp whose sightings the prefetch's build steps pin: the frame's first
    /// pass's when it keeps the frame's working set, else [`Self::first_stamp`].
    pub fn prefetch_pins_from(&self) -> u32 {
        if self.keeps_frame {
            self.pass_first_stamp.min(self.first_stamp)
        } else {
            self.first_stamp
        }
    }

    /// Whether the frame's passes are over (its prefetch runs).
    pub fn prefetching(&self) -> bool {
        self.prefetching
    }

    /// The next pass's stamp (stamps only grow), or the limit when stamps would reach
    /// `limit` (they must not wrap: the shaders compare them).
    pub fn next_stamp(&mut self, limit: u32) -> Result<u32> {
        if self.stamp + 1 >= limit {
            // ~20 days of a viewer at 60 frames a second and 5 passes a frame: refuse rather
            // than let stamps wrap and marks lie.
            return Err(GpuError::LimitExceeded {
                what: "streaming passes of one renderer (stamps)",
                requested: u64::from(self.stamp) + 1,
                limit: u64::from(limit - 1),
            });
        }
        self.stamp += 1;
        Ok(self.stamp)
    }

    /// The probe of the next camera ran: its sightings (from the latest stamp on) are what
    /// the prefetch keeps.
    pub fn probe_ran(&mut self) {
        self.first_stamp = self.stamp;
    }

    /// The pass marks were wanted after this frame.
    pub fn hold_pass_marks(&mut self) {
        self.pass_marks_held = self.number;
    }

    /// Moves the stamp on to `stamp`, never back (tests of the stamp limit).
    #[cfg(test)]
    pub fn skip_stamps_to(&mut self, stamp: u32) {
        self.stamp = self.stamp.max(stamp);
    }

    pub fn new() -> FrameState {
        FrameState {
            number: 0,
            stats: FrameStreamStats::default(),
            stamp: 0,
            first_stamp: 1,
            pass_marks_held: 0,
            prefetching: false,
            pass_first_stamp: 1,
            keeps_frame: false,
            next_camera: None,
            last_frame: false,
            probe_sighting: Vec::new(),
            probe_need: Default::default(),
            tracer: None,
            kept: Default::default(),
        }
    }
}

/// The probe of the next frame's camera after the passes: that camera, and what its first
/// round met.
struct FirstProbe {
    camera: CameraParams,
    found: ProbeFound,
}

/// What the first probe round leaves the later rounds: the next frame's camera, the pixels it
/// left open (packed `x | y << 16`) and the structures its rays needed first.
struct LaterRounds {
    camera: CameraParams,
    open: Vec<u32>,
    needed: Vec<u32>,
}

impl<'a> StreamingRenderer<'a> {
    /// Renders one frame: build–traverse passes until every pixel is complete (or
    /// `max_passes`), then a prefetch of what the guard band saw and, when the caller named
    /// the next frame's camera ([`Self::set_next_camera`]), what a probe of it met.
    /// `opts.frames` is ignored (one frame per call: a camera path calls this per frame).
    pub fn render_frame(
        &mut self,
        camera: &CameraParams,
        opts: &RenderOptions,
    ) -> Result<(RenderOutput, FrameStreamStats)> {
        if let Some(why) = &self.poisoned {
            return Err(GpuError::InvalidRequest(format!(
                "streaming renderer unusable after an earlier failure: {why}"
            )));
        }
        let (w, h) = (camera.width, camera.height);
        if w == 0 || h == 0 || w >= 1 << 15 || h >= 1 << 15 {
            return Err(GpuError::InvalidRequest(format!(
                "image size {w}×{h} is invalid for streaming (each side 1 to 32767)"
            )));
        }
        let span = tracing::info_span!(
            "stream_frame",
            frame = self.frame.number() + 1,
            width = w,
            height = h
        );
        let _g = span.enter();
        let mark = self.begin_frame();
        self.ensure_tracer(opts)?;
        let guard = guard_pixels(w, h, self.opts.guard_band_px);
        let fb = self.prepare_frame_buffers(camera, opts, guard.len())?;
        let next = self.frame.next_camera.take();
        self.frame.kept.set_next(next.as_ref());
        let last = std::mem::take(&mut self.frame.last_frame);
        let result = self.run_passes(&fb, w, h, &guard).and_then(|image| {
            self.settle_stale_after_passes()?;
            // A camera at rest whose frame left resident all it saw (one pass, or no eviction
            // of what it saw): the probe's primary rays would only find it again.
            let still = next == Some(*camera)
                && (self.frame.stats.passes == 1 || self.seen_evicted_in_frame() == 0);
            self.frame.stats.probe_skipped_still = still;
            // The probe of the next frame's camera (its buffers are this frame's: same size).
            let probe = match next.filter(|_| !still) {
                Some(n) if self.may_probe(&n, w, h) => Some(FirstProbe {
                    camera: n,
                    found: self.probe_next_camera(&fb, &n, opts, None, false)?,
                }),
                _ => None,
            };
            Ok((image, probe))
        });
        let (mut image, probe) = match result {
            Ok(r) => r,
            Err(e) => {
                fb.release(&mut self.heap);
                return Err(e);
            }
        };
        self.keep_frame_buffers(KeptFrameBuffers {
            buffers: fb,
            width: w,
            height: h,
            guard_len: guard.len(),
        });
        self.measure_working_set();
        let guard_demand = std::mem::take(&mut image.guard_demand);
        // No frame follows the last: what the guard band saw would be built for none.
        if !last {
            self.prefetch_after_frame(guard_demand, probe, opts)?;
        }
        self.note_pass_marks();
        self.note_stale_tlases();
        let report = self.heap.report();
        mark.note(&self.ctx, &mut self.frame.stats);
        self.measure_residency(&report);
        self.totals.add_frame(&self.frame.stats, &report);
        self.totals.host_clone_bytes = self.clones.bytes();
        self.frame_output(camera, image, opts, report)
            .inspect(|_| self.end_frame_clock())
    }

    /// A new frame's counters: its number, its statistics, its first stamp, its build clock;
    /// returns its start (time, submissions) for `frame_ms` and `submits`.
    fn begin_frame(&mut self) -> super::stats::FrameMark {
        self.frame.begin();
        super::stats::FrameMark::now(&self.ctx)
    }

    /// The trace pipeline of `opts`'s backend and stack size, made (evicting for room) when
    /// the last frame's was another.
    fn ensure_tracer(&mut self, opts: &RenderOptions) -> Result<()> {
        let need_tracer = !matches!(&self.frame.tracer, Some(t) if t.backend == opts.backend && t.stack_size == opts.stack_size);
        if need_tracer {
            if let Some(t) = self.frame.tracer.take() {
                t.tracer.release(&mut self.heap);
                if let Some(b) = t.counts {
                    b.release(&mut self.heap);
                }
            }
            self.res.unpin_all(self.item_count());
            let t = self
                .with_eviction_or_rebuilt_tlases(|s| {
                    // Streamed TLASes keep every PI in the hardware walk (no box lists).
                    let slots = crate::scene::pi_capacity(&s.view, false);
                    let count = s.opts.count_proxy_calls;
                    Tracer::new(&s.ctx.clone(), &mut s.heap, opts, slots, true, count)
                })
                .map_err(|e| self.skeleton_error("the trace pipeline", e))?;
            self.frame.tracer = Some(FrameTracer {
                backend: opts.backend,
                stack_size: opts.stack_size,
                tracer: t,
                counts: None,
            });
        }
        Ok(())
    }

    /// The frame's buffers with `camera`'s parameters, and every TLAS clean: making room for
    /// them may have evicted BLASes that TLASes still reference.
    fn prepare_frame_buffers(
        &mut self,
        camera: &CameraParams,
        opts: &RenderOptions,
        guard_len: usize,
    ) -> Result<FrameBuffers> {
        let params = frame_params(camera, opts, self.view.root_tlas, self.shading.address());
        self.res.unpin_all(self.item_count());
        let fb = self.frame_buffers(
            camera.width,
            camera.height,
            guard_len,
            &params,
            &opts.shading,
        )?;
        self.frame.kept_mut().set_camera(*camera);
        if self.dirty_before_trace() {
            self.res.forget_built_now();
            if let Err(e) = self
                .rebuild_before_trace()
                .and_then(|()| self.upload_tlas_addresses())
            {
                fb.release(&mut self.heap);
                self.quarantine_after_failure(&e);
                return Err(e);
            }
        }
        Ok(fb)
    }

    /// Prefetch: what the guard band saw, evicting only what this frame did not see (what
    /// does not fit is skipped), within what is left of the frame's build budget. With a
    /// probe of the next camera, what its rays need comes first; what the probe saw is kept
    /// (with `StreamOptions::prefetch_keeps_frame`, also what this frame's passes saw while
    /// the frame's working set fits its room; otherwise this frame is done, the next one is
    /// what the room is for).
    fn prefetch_after_frame(
        &mut self,
        guard_demand: Demand,
        probe: Option<FirstProbe>,
        opts: &RenderOptions,
    ) -> Result<()> {
        // With `prefetch_keeps_frame`, a frame whose working set fits its room keeps it: the
        // next camera's set is mostly this one's (one-sample bounce rays meet a different
        // fringe of it each frame, which no probe sees), and what it does not need goes in the
        // next frame's passes, least recently seen first.
        // Fits: beside the frame's largest TLAS rebuild transient and the free space inside
        // blocks that only requests fitting its ranges can use.
        let report = self.heap.report();
        let fragments = report
            .budget_block_bytes
            .saturating_sub(report.budget_in_use_bytes);
        let st = &self.frame.stats;
        let keeps = self.opts.prefetch_keeps_frame
            && st.working_set_bytes + st.tlas_rebuild_transient_bytes + fragments
                <= self.room_bytes(&report);
        self.frame.start_prefetch(keeps);
        let evicted_before = self.frame.stats.evicted;
        let r = self.prefetch_steps(guard_demand, probe, opts);
        self.frame.stats.evicted_in_prefetch = self.frame.stats.evicted - evicted_before;
        r
    }

    /// [`Self::prefetch_after_frame`]'s build steps.
    fn prefetch_steps(
        &mut self,
        mut guard_demand: Demand,
        probe: Option<FirstProbe>,
        opts: &RenderOptions,
    ) -> Result<()> {
        let mut again = None;
        let evictions_at_probe = self.res.evictions();
        if let Some(FirstProbe { camera, found }) = probe {
            let needed = found.demand.needed_ids();
            guard_demand.merge_first(found.demand);
            self.frame.probe_ran();
            again = Some(LaterRounds {
                camera,
                open: found.open_pixels,
                needed,
            });
        }
        if !guard_demand.is_empty() && self.frame.stats.complete && !self.frame_build_spent() {
            let before = ProbeStep::of(&self.frame.stats);
            let open = again.as_ref().map_or(0, |r| r.open.len());
            if let Err(e) = self
                .make_resident(&guard_demand, true)
                .map(|()| before.log(&self.frame.stats, "first", open))
                .and_then(|()| match again {
                    Some(rounds) => self.probe_again(rounds, opts, evictions_at_probe),
                    None => Ok(()),
                })
            {
                self.quarantine_after_failure(&e);
                return Err(e);
            }
        }
        Ok(())
    }

    /// Pass marks (auto) for the next probes: this frame evicted for build room and its
    /// prefetch built all it wanted.
    fn note_pass_marks(&mut self) {
        let st = &self.frame.stats;
        let build_room = st
            .evicted
            .saturating_sub(st.evicted_for_tlas + st.evicted_on_refusal);
        if super::PassMarks::auto_wanted(build_room, st.prefetch_skipped) {
            self.frame.hold_pass_marks();
        }
    }

    /// The frame's image, AOVs and render statistics.
    fn frame_output(
        &mut self,
        camera: &CameraParams,
        image: FrameImage,
        opts: &RenderOptions,
        report: motu_alloc::AllocReport,
    ) -> Result<(RenderOutput, FrameStreamStats)> {
        let (w, h) = (camera.width, camera.height);
        let pixels = u64::from(w) * u64::from(h);
        let FrameImage {
            records,
            rgba_words,
            counters,
            ..
        } = image;
        let (aov, rgba8, heatmap_max, exposure_ev) =
            crate::render::frame_outputs(w, h, records, &rgba_words, opts);
        crate::render::check_texture_residency(&counters)?;
        self.frame.stats.truncated_rays = u64::from(counters[crate::render::STAT_TRUNCATED_RAYS]);
        let stats = RenderStats::measured(
            opts,
            FrameMeasure {
                width: w,
                height: h,
                frames: 1,
                ms_per_frame: self.frame.stats.trace_ms,
                primary_rays: pixels + self.frame.stats.reshot_pixels,
                aov: &aov,
                counters: &counters,
                heatmap_max,
                exposure_ev,
                as_bytes: self
                    .res
                    .blases()
                    .iter()
                    .flatten()
                    .map(|a| a.size_bytes)
                    .chain(self.tlases.resident().map(|t| t.accel().size_bytes))
                    .sum(),
                alloc: report,
                passes: self.frame.stats.passes,
            },
        );
        tracing::info!(
            frame = self.frame.number(),
            passes = self.frame.stats.passes,
            blas_built = self.frame.stats.blas_built,
            evicted = self.frame.stats.evicted,
            "stream frame done"
        );
        Ok((RenderOutput { aov, rgba8, stats }, self.frame.stats.clone()))
    }

    /// Later probe rounds (`StreamOptions::probe_rounds`; on the clock `clocked_probe`'s) of
    /// `rounds.camera`: the pixels
    /// `rounds.open` the round before left open are probed again against what the prefetch
    /// just built, and what they need is prefetched, while the prefetch built some structure a
    /// round's rays `rounds.needed` first (the
    /// open pixels' rays go on from there) and pixels stay open. Then verifying rounds
    /// (`StreamOptions::probe_verify_rounds`) over every pixel, unless the rounds settled
    /// (no pixel left open) and nothing was evicted since the first probe (`self.res.evictions()`
    /// was `evictions_at_probe` then): the next frame then finds everything its rays need.
    fn probe_again(
        &mut self,
        rounds: LaterRounds,
        opts: &RenderOptions,
        evictions_at_probe: u64,
    ) -> Result<()> {
        let LaterRounds {
            camera,
            mut open,
            mut needed,
        } = rounds;
        let next = &camera;
        let mut settled = open.is_empty();
        let probe = self.probe_settings();
        // `ProbeLater::Verify`: the prefetch evicted, so verifying rounds follow; they probe
        // the open pixels too, one build step for both.
        let merged = self.opts.probe_later == super::ProbeLater::Verify
            && probe.verify_rounds > 0
            && self.res.evictions() != evictions_at_probe;
        // Merged, the verifying rounds may go as deep as the open-pixel rounds would have.
        let verify_rounds = probe.verify_rounds
            + if merged && !open.is_empty() {
                probe.rounds.saturating_sub(1)
            } else {
                0
            };
        self.frame.stats.probe_later_merged = merged;
        while !merged
            && !open.is_empty()
            && self.frame.stats.probe_rounds < probe.rounds
            && needed.iter().any(|&b| self.res.has_blas(b as usize))
            && !self.frame_build_spent()
        {
            let Some(ProbeFound {
                demand,
                open_pixels: still_open,
            }) = self.probe_round(next, opts, Some(&open))?
            else {
                return Ok(());
            };
            needed = demand.needed_ids();
            if needed.is_empty() {
                settled = true;
                break;
            }
            let before = ProbeStep::of(&self.frame.stats);
            self.make_resident(&demand, true)?;
            before.log(&self.frame.stats, "open", still_open.len());
            open = still_open;
            settled = open.is_empty();
        }
        if settled && self.res.evictions() == evictions_at_probe {
            return Ok(());
        }
        // Verifying rounds: the prefetch evicted, for room, structures no round met, and the
        // next frame's rays may pass through some of them; every pixel again finds those. A
        // round that built something leaves its open pixels' rays going on past it, so the
        // next round runs whether or not it evicted.
        while self.frame.stats.probe_verify_rounds < verify_rounds && !self.frame_build_spent() {
            self.frame.stats.probe_verify_rounds += 1;
            let Some(ProbeFound {
                demand,
                open_pixels,
            }) = self.probe_round(next, opts, None)?
            else {
                return Ok(());
            };
            if demand.needed_ids().is_empty() {
                break;
            }
            let built = self.frame.stats.prefetched;
            let before = ProbeStep::of(&self.frame.stats);
            self.make_resident(&demand, true)?;
            before.log(&self.frame.stats, "verify", open_pixels.len());
            if self.frame.stats.prefetched == built {
                break;
            }
        }
        Ok(())
    }

    /// One later probe round in the kept frame buffers: the pixels `again`, or (None) a
    /// verifying round over every pixel. None when no buffers are kept.
    fn probe_round(
        &mut self,
        next: &CameraParams,
        opts: &RenderOptions,
        again: Option<&[u32]>,
    ) -> Result<Option<ProbeFound>> {
        let Some(kept) = self.take_kept_frame_buffers() else {
            return Ok(None);
        };
        let probed = self.probe_next_camera(&kept.buffers, next, opts, again, again.is_none());
        self.keep_frame_buffers(kept);
        probed.map(Some)
    }
}

/// The frame's counters before a probe round's prefetch step: what the step added is logged
/// (`MOTU_LOG=motu_gpu=debug`), per round, to see which rounds find what and what their TLAS
/// rebuilds cost.
struct ProbeStep {
    rays: u64,
    prefetched: u32,
    evicted: u32,
    tlas_rebuilt: u32,
    records: u64,
}

impl ProbeStep {
    fn of(f: &FrameStreamStats) -> Self {
        ProbeStep {
            rays: f.probe_rays,
            prefetched: f.prefetched,
            evicted: f.evicted,
            tlas_rebuilt: f.tlas_rebuilt,
            records: f.tlas_instances_written,
        }
    }

    /// Logs the step of a `kind` round (`first`, `open`, `verify`) that left `open` pixels.
    fn log(&self, f: &FrameStreamStats, kind: &str, open: usize) {
        tracing::debug!(
            frame = f.frame,
            kind,
            round = f.probe_rounds,
            rays_so_far = f.probe_rays,
            rays_before = self.rays,
            open,
            built = f.prefetched - self.prefetched,
            evicted = f.evicted - self.evicted,
            tlas_rebuilt = f.tlas_rebuilt - self.tlas_rebuilt,
            records = f.tlas_instances_written - self.records,
            "probe step"
        );
    }
}
