//! The build–traverse pass loop: per-pass parameters, pixel lists (with the guard band),
//! readback of stamps, requests and incomplete pixels.

use std::time::Instant;

use motu_abi::aov::AovRecord;

use super::buffers::FrameBuffers;
use super::demand::Demand;
use super::params::{
    StreamParams, CARRY_BYTES, STAMP_LIMIT, STREAM_LAST_PASS, STREAM_NO_MARK_WALK,
    STREAM_OPEN_BOUND,
};
use super::proxy_count::{self, PROXY_COUNT_WORDS};
use super::{FrameStreamStats, PassStats, StreamFallback, StreamingRenderer, GUARD_BIAS};
use crate::error::{GpuError, Result};
use crate::render::{
    Tracer, STAT_MARK_TLAS_WALKS, STAT_MARK_WALKS, STAT_PROXY_EXACT_TESTS, STAT_PROXY_MEMBER_TESTS,
    STAT_SHADOW_RAYS, STAT_TLAS_WALKS, STAT_WORDS,
};
use crate::scene::Slot;

/// Stamp levels of `common.glsl` (`STREAM_*`).
const LEVEL_OPEN: u32 = 1;
pub(super) const LEVEL_NEEDED: u32 = 2;

/// `probe_sighting` bits (`probe.rs`): a probe ray met the BLAS; the BLAS was resident while
/// the probe ran.
pub(super) const PROBE_MET: u8 = 1;
pub(super) const PROBE_RESIDENT: u8 = 2;

/// What a frame's passes leave: the image, the shaders' stats counters and what the guard
/// band saw.
pub(super) struct FrameImage {
    pub records: Vec<AovRecord>,
    /// Colour, one packed RGBA8 word a pixel.
    pub rgba_words: Vec<u32>,
    /// The shaders' stats counters (`STAT_WORDS`).
    pub counters: Vec<u32>,
    /// What the guard band (and pass 1's open marks) saw: the prefetch after the frame.
    pub guard_demand: Demand,
}

impl<'a> StreamingRenderer<'a> {
    /// The frame's build–traverse passes. Returns the image, the stats counters and what the
    /// guard band saw (the prefetch).
    pub(super) fn run_passes(
        &mut self,
        fb: &FrameBuffers,
        w: u32,
        h: u32,
        guard: &[u32],
    ) -> Result<FrameImage> {
        let pixels = u64::from(w) * u64::from(h);
        let final_off = ReadbackLayout::new(self.view.blases.len(), pixels).final_off;
        let mut full_count = pixels as u32;
        let mut list: Vec<u32> = self.pass_one_guard(guard).to_vec();
        self.frame.stats_mut().guard_rays = list.len() as u64;
        let mut guard_demand = Demand::default();
        let max_passes = self.frame_pass_cap();
        // The pass about to run is the frame's last (its cap, or the build budget spent).
        let mut last = max_passes <= 1;
        // Open pixels the last pass leaves as they are (unbiased; see `split_waiting`).
        let mut waiting: Vec<u32> = Vec::new();
        let mut shader_before = ShaderCounters::default();
        loop {
            let pass_t0 = Instant::now();
            let before = PassCounters::of(self.frame.stats());
            let traced = u64::from(full_count) + list.len() as u64;
            self.frame.stats_mut().passes += 1;
            let first = self.frame.stats().passes == 1;
            let flags = self.frame_pass_flags(last);
            let (
                PassReadback {
                    stamps,
                    requests,
                    incomplete,
                    trace_ms,
                },
                extra,
            ) = self.trace_pass_with(fb, pixels, full_count, &list, first, flags)?;
            self.frame.stats_mut().trace_ms += trace_ms;
            let count = (incomplete.len() + waiting.len()) as u32;
            // Resident BLASes seen refresh their LRU age; empty ones are needed (some pixel's
            // nearest open one), open (needed later) or, in pass 1, prefetch candidates (the
            // guard band saw them).
            let mut demand = Demand::default();
            for Sighting { blas: b, level } in self.sightings(&stamps, &requests, true) {
                let n = requests.get(b as usize).copied().unwrap_or(0);
                match level {
                    LEVEL_NEEDED => demand.need(b, n),
                    LEVEL_OPEN => {
                        demand.open(b);
                        if first {
                            // Also a prefetch candidate when the frame completes without it.
                            guard_demand.need(b, 0);
                        }
                    }
                    _ if first => guard_demand.need(b, 0),
                    _ => {}
                }
            }
            demand.sort();
            demand.defer_later_when_open(u64::from(count), pixels);
            if first {
                self.classify_first_pass_misses(&demand);
            }
            let mut pass = PassStats {
                traced,
                open_pixels: u64::from(count),
                needed: demand.needed().len() as u32,
                later: demand.later().len() as u32,
                later_deferred: demand.later_deferred(),
                needed_camera: demand.needed_camera(),
                open_closest: self.note_blockers(&extra.blockers, waiting.len()),
                last_pass: last,
                ..Default::default()
            };
            extra.counters.since(&shader_before, &mut pass);
            shader_before = extra.counters.clone();
            let host_before_build = pass_t0.elapsed().as_secs_f64() * 1e3;
            let log_pass = |s: &mut Self, mut pass: PassStats, host_extra: f64| {
                before.since(s.frame.stats(), &mut pass);
                pass.host_ms = (host_before_build - pass.trace_ms).max(0.0) + host_extra;
                s.frame.stats_mut().host_ms += pass.host_ms;
                s.frame.stats_mut().pass_log.push(pass);
            };
            if count == 0 {
                log_pass(self, pass, 0.0);
                self.frame.stats_mut().complete = true;
                break;
            }
            let spent = self.frame_build_spent();
            if self.frame.stats().passes >= max_passes || spent {
                self.frame.stats_mut().incomplete_pixels = u64::from(count);
                self.frame.stats_mut().build_budget_spent = spent;
                if self.builds_after_last_pass() {
                    // Bounded frames: build toward the next frame (what is left of the budget).
                    if !spent {
                        if let Err(e) = self.make_resident(&demand, false) {
                            self.quarantine_after_failure(&e);
                            return Err(e);
                        }
                    }
                } else {
                    tracing::warn!(
                        incomplete = count,
                        passes = self.frame.stats().passes,
                        "stream pass cap reached with pixels unfinished"
                    );
                }
                list = incomplete;
                list.append(&mut waiting);
                log_pass(self, pass, 0.0);
                break;
            }
            if let Err(e) = self.make_resident(&demand, false) {
                self.quarantine_after_failure(&e);
                return Err(e);
            }
            let t_list = Instant::now();
            last = self.frame.stats().passes + 1 >= max_passes || self.frame_build_spent();
            let retrace = if last {
                let (retrace, wait) = self.split_waiting(&incomplete, &extra.blockers);
                waiting = wait;
                retrace
            } else {
                incomplete
            };
            pass.left_waiting = waiting.len() as u64;
            if retrace.is_empty() {
                // Every open pixel waits for a structure still missing: the pass that would
                // come could change none of them, so the frame ends here.
                let spent = self.frame_build_spent();
                let st = self.frame.stats_mut();
                st.incomplete_pixels = waiting.len() as u64;
                st.build_budget_spent = spent;
                list = std::mem::take(&mut waiting);
                log_pass(self, pass, t_list.elapsed().as_secs_f64() * 1e3);
                break;
            }
            self.frame.stats_mut().reshot_pixels += retrace.len() as u64;
            full_count = 0;
            list = relist(&retrace);
            log_pass(self, pass, t_list.elapsed().as_secs_f64() * 1e3);
        }
        guard_demand.sort();
        let mut image = self.read_image(fb, w, h, final_off, &list)?;
        image.guard_demand = guard_demand;
        Ok(image)
    }

    /// The final readback of the image (AOV records, colour words, stats counters) from
    /// `fb` through its readback buffer at `final_off`; `list`: the last pass's incomplete
    /// pixels, unbiased (shown as misses unless the fallback wrote them). The guard band's
    /// demand is left empty.
    fn read_image(
        &mut self,
        fb: &FrameBuffers,
        w: u32,
        h: u32,
        final_off: u64,
        list: &[u32],
    ) -> Result<FrameImage> {
        let pixels = u64::from(w) * u64::from(h);
        let mut rec = self.ctx.record("stream readback")?;
        rec.copy_buffer(&fb.aov, 0, &fb.readback, final_off, pixels * 16)?;
        rec.copy_buffer(
            &fb.rgba,
            0,
            &fb.readback,
            final_off + pixels * 16,
            pixels * 4,
        )?;
        rec.copy_buffer(
            self.frame.proxy_counts().map_or(&fb.stats, |c| &c.counts),
            0,
            &fb.readback,
            final_off + pixels * 20,
            (STAT_WORDS * 4) as u64,
        )?;
        rec.submit_and_wait()?;
        let mut records: Vec<AovRecord> = fb.readback.read_vec(final_off, pixels as usize)?;
        let mut rgba: Vec<u32> = fb
            .readback
            .read_vec(final_off + pixels * 16, pixels as usize)?;
        let counters: Vec<u32> = fb.readback.read_vec(final_off + pixels * 20, STAT_WORDS)?;
        if !self.frame.stats().complete && self.opts.fallback != StreamFallback::Off {
            // Each wrote its fallback when it was deferred (render_pixel.glsl).
            self.frame.stats_mut().fallback_pixels = list.len() as u64;
        } else if !self.frame.stats().complete {
            // Never written: misses, magenta so they are not mistaken for sky.
            // `list` holds the last pass's incomplete pixels, unbiased.
            for &v in list {
                let (x, y) = (v & 0xffff, v >> 16);
                if x < w && y < h {
                    let i = y as usize * w as usize + x as usize;
                    records[i] = AovRecord::MISS;
                    rgba[i] = 0xFFFF_00FF;
                }
            }
        }
        Ok(FrameImage {
            records,
            rgba_words: rgba,
            counters,
            guard_demand: Demand::default(),
        })
    }
}

impl<'a> StreamingRenderer<'a> {
    /// The flags of a frame pass: its last (`last`) traces no secondary rays ahead of open
    /// primary rays; a last pass after which nothing is built (the build budget spent) takes
    /// no mark walks, whose marks would steer nothing. A refining frame's first pass
    /// (`refining_first_pass`) takes neither: its marks would steer nothing either, and the
    /// secondary rays it would trace ahead of an open primary ray are lost when the pixel
    /// waits past the frame's build step (`split_waiting`; the carry starts afresh each frame),
    /// while a pixel whose structure arrives traces them in the next pass, as after a last
    /// pass. Its open pixels and fallbacks are what they would be; only the requests of those
    /// secondary rays go, so what primary rays wait for leads the next step's needed list.
    fn frame_pass_flags(&self, last: bool) -> u32 {
        if self.refining_first_pass() {
            return STREAM_LAST_PASS | STREAM_NO_MARK_WALK;
        }
        match (last, last && self.frame_build_spent()) {
            (true, true) => STREAM_LAST_PASS | STREAM_NO_MARK_WALK,
            (true, false) => STREAM_LAST_PASS,
            _ => 0,
        }
    }

    /// The flags every pass adds: [`StreamOptions::open_bound`](super::StreamOptions::open_bound)'s.
    fn proxy_test_flags(&self) -> u32 {
        if self.opts.open_bound {
            STREAM_OPEN_BOUND
        } else {
            0
        }
    }

    /// The guard band pass 1 traces: none in a refining frame (`refining_first_pass`), whose
    /// guard rays would only mark (for the prefetch after a complete frame), in mark walks it
    /// does not take.
    fn pass_one_guard<'g>(&self, guard: &'g [u32]) -> &'g [u32] {
        if self.refining_first_pass() {
            &[]
        } else {
            guard
        }
    }

    /// Splits a pass's open pixels `incomplete` (with what each waits for, `blockers`) before
    /// the frame's last pass: those to trace again, and those left as they are because their
    /// closest-hit ray waits for a structure still not resident. Such a ray stays open in any
    /// pass before that structure arrives (everything else built lies behind its entry), so
    /// its pixel would stay unfinished and write the same fallback: tracing it again is work
    /// for nothing. So are pixels whose structure is resident under a TLAS still stale (a
    /// frame with a build budget in ms; `piece_order.rs`): the stale proxy keeps their ray
    /// open until that TLAS is rebuilt. Pixels that name none (secondary rays open) are
    /// traced again.
    fn split_waiting(&mut self, incomplete: &[u32], blockers: &[u32]) -> (Vec<u32>, Vec<u32>) {
        let mut retrace = Vec::with_capacity(incomplete.len());
        let mut waiting = Vec::new();
        let mut stale = 0u64;
        for (i, &px) in incomplete.iter().enumerate() {
            let b = blockers.get(i).copied().unwrap_or(NONE_BLOCKER) as usize;
            if b >= self.view.blases.len() {
                retrace.push(px);
            } else if !self.res.has_blas(b) {
                waiting.push(px);
            } else if self.under_stale_tlas(b) {
                waiting.push(px);
                stale += 1;
            } else {
                retrace.push(px);
            }
        }
        self.frame.kept_mut().set_stale_waiting(stale);
        (retrace, waiting)
    }

    /// Counts why the first pass's needed structures were missing (see
    /// `FrameStreamStats::first_pass_missed_evicted`), from the last probe's sightings, which
    /// it then forgets.
    fn classify_first_pass_misses(&mut self, demand: &Demand) {
        let sighting = self.frame.take_probe_sighting();
        for r in demand.needed() {
            let s = sighting.get(r.blas as usize).copied().unwrap_or(0);
            let st = self.frame.stats_mut();
            if s & PROBE_MET != 0 {
                st.first_pass_missed_probed += 1;
            } else if s & PROBE_RESIDENT != 0 {
                st.first_pass_missed_evicted += 1;
            } else {
                st.first_pass_missed_unprobed += 1;
            }
        }
    }
}

/// The frame's counters when a pass starts: its `PassStats` are what they grew by.
struct PassCounters {
    trace_ms: f64,
    build_ms: f64,
    tlas_ms: f64,
    blas_built: u32,
    built_bytes: u64,
    evicted: u32,
    evicted_bytes: u64,
    evicted_for_tlas: u32,
    evicted_on_refusal: u32,
}

impl PassCounters {
    fn of(f: &FrameStreamStats) -> Self {
        PassCounters {
            trace_ms: f.trace_ms,
            build_ms: f.build_ms,
            tlas_ms: f.tlas_ms,
            blas_built: f.blas_built,
            built_bytes: f.built_bytes,
            evicted: f.evicted,
            evicted_bytes: f.evicted_bytes,
            evicted_for_tlas: f.evicted_for_tlas,
            evicted_on_refusal: f.evicted_on_refusal,
        }
    }

    /// Fills `pass` with what the counters grew by since `self`.
    fn since(&self, f: &FrameStreamStats, pass: &mut PassStats) {
        pass.trace_ms = f.trace_ms - self.trace_ms;
        pass.build_ms = f.build_ms - self.build_ms;
        pass.tlas_ms = f.tlas_ms - self.tlas_ms;
        pass.blas_built = f.blas_built - self.blas_built;
        pass.built_bytes = f.built_bytes - self.built_bytes;
        pass.evicted = f.evicted - self.evicted;
        pass.evicted_bytes = f.evicted_bytes - self.evicted_bytes;
        pass.evicted_for_tlas = f.evicted_for_tlas - self.evicted_for_tlas;
        pass.evicted_on_refusal = f.evicted_on_refusal - self.evicted_on_refusal;
    }
}

/// What a pixel on the incomplete list names when it waits for no one structure
/// (`NONE_U32` of the shaders).
const NONE_BLOCKER: u32 = u32::MAX;

/// The shaders' counters of a frame's passes so far (the stats words, cumulative over the
/// frame's passes): what a pass added is its `PassStats`'.
#[derive(Clone, Default)]
pub(super) struct ShaderCounters {
    secondary_rays: u32,
    tlas_walks: u32,
    mark_walks: u32,
    mark_tlas_walks: u32,
    proxy_member_tests: u32,
    proxy_exact_tests: u32,
    /// Counting mode's counters (`proxy_count.rs`; empty without it).
    proxy: Vec<u32>,
}

impl ShaderCounters {
    fn of(words: &[u32], proxy: Vec<u32>) -> Self {
        let at = |i: usize| words.get(i).copied().unwrap_or(0);
        ShaderCounters {
            secondary_rays: at(STAT_SHADOW_RAYS),
            tlas_walks: at(STAT_TLAS_WALKS),
            mark_walks: at(STAT_MARK_WALKS),
            mark_tlas_walks: at(STAT_MARK_TLAS_WALKS),
            proxy_member_tests: at(STAT_PROXY_MEMBER_TESTS),
            proxy_exact_tests: at(STAT_PROXY_EXACT_TESTS),
            proxy,
        }
    }

    /// Fills `pass` with what the counters grew by since `before`.
    fn since(&self, before: &Self, pass: &mut PassStats) {
        let grown = |now: u32, then: u32| u64::from(now.wrapping_sub(then));
        pass.secondary_rays = grown(self.secondary_rays, before.secondary_rays);
        pass.tlas_walks = grown(self.tlas_walks, before.tlas_walks);
        pass.mark_walks = grown(self.mark_walks, before.mark_walks);
        pass.mark_tlas_walks = grown(self.mark_tlas_walks, before.mark_tlas_walks);
        pass.proxy_member_tests = grown(self.proxy_member_tests, before.proxy_member_tests);
        pass.proxy_exact_tests = grown(self.proxy_exact_tests, before.proxy_exact_tests);
        proxy_count::fill_pass(&self.proxy, &before.proxy, pass);
    }
}

/// Offsets in the frame's readback buffer: stamps at 0, requests, the incomplete list (count,
/// pixels, what each waits for), then the final image (AOV, colour, stats words).
struct ReadbackLayout {
    req_off: u64,
    inc_off: u64,
    final_off: u64,
}

impl ReadbackLayout {
    fn new(blases: usize, pixels: u64) -> Self {
        let stamps_bytes = (blases * 4) as u64;
        let req_off = stamps_bytes.div_ceil(16) * 16;
        let inc_off = req_off + req_off;
        ReadbackLayout {
            req_off,
            inc_off,
            final_off: (inc_off + 4 + 8 * pixels).div_ceil(16) * 16,
        }
    }
}

/// What a frame's own pass reads back beside [`PassReadback`]: what each incomplete pixel
/// waits for, and the shaders' counters so far.
pub(super) struct PassExtra {
    pub(super) blockers: Vec<u32>,
    pub(super) counters: ShaderCounters,
}

/// A non-resident buildable BLAS a pass met, with the stamp level it met it at
/// (`LEVEL_NEEDED`: some ray's nearest open structure, `LEVEL_OPEN`: open for some ray, lower:
/// passed through). Plain data (`pub(super)` fields): no invariant ties the two.
pub(super) struct Sighting {
    pub(super) blas: u32,
    pub(super) level: u32,
}

/// What one traced pass left for the host: per-BLAS stamps and request counts, and the
/// incomplete pixels (packed `x | y << 16`).
pub(super) struct PassReadback {
    pub(super) stamps: Vec<u32>,
    pub(super) requests: Vec<u32>,
    pub(super) incomplete: Vec<u32>,
    /// Wall time of the trace submission.
    pub(super) trace_ms: f64,
}

impl<'a> StreamingRenderer<'a> {
    /// What the pass just traced (the current stamp) met, from its readback `stamps`: every
    /// BLAS it met is seen now (`last_seen`); a resident one refreshes its LRU age and, when
    /// `this_frame` (the frame's own passes, not the probe of the next frame), counts in the
    /// frame's working set with the kinds of ray whose closest hit it held (its word in
    /// `requests`, `HIT_*`). Returns the non-resident buildable ones with their stamp level.
    pub(super) fn sightings(
        &mut self,
        stamps: &[u32],
        requests: &[u32],
        this_frame: bool,
    ) -> Vec<Sighting> {
        let mut out = Vec::new();
        for (b, &v) in stamps.iter().enumerate() {
            if v >> 2 != self.frame.stamp() {
                continue;
            }
            self.res.seen_at(b, self.frame.stamp());
            if self.res.has_blas(b) {
                let hit_kinds = requests.get(b).copied().unwrap_or(0);
                if this_frame {
                    self.res.used_in(b, self.frame.number(), hit_kinds);
                }
                if self.topo.buildable(b) {
                    self.res.saw(b, self.frame.stamp());
                }
            } else if self.topo.buildable(b) {
                out.push(Sighting {
                    blas: b as u32,
                    level: v & 3,
                });
            }
        }
        out
    }

    /// Traces one pass under a new stamp: the first `full_count` image pixels (row order) then
    /// `list` (packed, biased), with `flags` (`STREAM_PROBE_PASS`); `first` clears the stats
    /// and the carried state. Reads back the stamps, requests and incomplete pixels.
    pub(super) fn trace_pass(
        &mut self,
        fb: &FrameBuffers,
        pixels: u64,
        full_count: u32,
        list: &[u32],
        first: bool,
        flags: u32,
    ) -> Result<PassReadback> {
        self.trace_pass_with(fb, pixels, full_count, list, first, flags)
            .map(|(r, _)| r)
    }

    /// [`Self::trace_pass`], also reading back what each incomplete pixel waits for and the
    /// shaders' counters.
    fn trace_pass_with(
        &mut self,
        fb: &FrameBuffers,
        pixels: u64,
        full_count: u32,
        list: &[u32],
        first: bool,
        flags: u32,
    ) -> Result<(PassReadback, PassExtra)> {
        let nb = self.view.blases.len();
        let stamps_bytes = (nb * 4) as u64;
        let ReadbackLayout {
            req_off,
            inc_off,
            final_off,
        } = ReadbackLayout::new(nb, pixels);
        self.ensure_proxy_counts(u64::from(full_count) + list.len() as u64)?;
        self.frame.next_stamp(STAMP_LIMIT)?;
        // Every resident BLAS is walked by every ray of this pass that reaches its box in
        // front of its best hit: a ray that started by now needs it no more.
        let resident = (0..nb).filter(|&b| self.res.has_blas(b) && self.topo.buildable(b));
        self.gpu.write_walked(resident, self.frame.stamp())?;
        let walked = self.gpu.walked_table()?;
        fb.pixel_list.write(0, list)?;
        let (cluster_members, proxy_box_index, proxy_boxes) = self.gpu.proxy_addresses();
        let sp = StreamParams {
            blas_stamps: self
                .gpu
                .blas_stamps()
                .map_or(Ok(0), |b| b.device_address().map(|a| a.0))?,
            walked: walked.device_address()?.0,
            pixel_list: fb.pixel_list.device_address()?.0,
            incomplete: fb.incomplete.device_address()?.0,
            stamp: self.frame.stamp(),
            full_count,
            list_count: list.len() as u32,
            blas_count: nb as u32,
            requests: fb.requests.device_address()?.0,
            carry: fb.carry.device_address()?.0,
            cluster_members,
            proxy_box_index,
            proxy_boxes,
            flags: flags | self.proxy_test_flags(),
            _pad: 0,
        };
        fb.stream.write(0, std::slice::from_ref(&sp))?;
        let mut addresses = self.gpu.addresses();
        addresses[Slot::Frame as usize] = fb.params.device_address()?.0;
        addresses[Slot::Aov as usize] = fb.aov.device_address()?.0;
        addresses[Slot::Rgba as usize] = fb.rgba.device_address()?.0;
        // Counting mode's shaders write a longer stats buffer of their own (proxy_count.rs).
        let (stats, stats_clear) = self.pass_stats_buffer(fb);
        addresses[Slot::Stats as usize] = stats.device_address()?.0;
        addresses[Slot::Stream as usize] = fb.stream.device_address()?.0;
        let push_bytes: &[u8] = bytemuck::cast_slice(&addresses);
        let n = full_count + list.len() as u32;
        let Some(tracer) = self.frame.tracer() else {
            return Err(GpuError::InvalidRequest(
                "streaming: no trace pipeline".into(),
            ));
        };
        let (dims, groups) = match tracer {
            Tracer::Pipeline(_) => (super::buffers::launch_dims(n, fb.launch_row_items), None),
            Tracer::Query(_) => {
                let g = n.div_ceil(64).max(1);
                ([0, 0], Some([g.min(65535), g.div_ceil(65535)]))
            }
        };
        let t0 = Instant::now();
        let mut rec = self.ctx.record("stream pass")?;
        if first {
            rec.fill_buffer(stats, 0, stats_clear, 0)?;
            rec.fill_buffer(&fb.carry, 0, pixels * CARRY_BYTES, 0)?;
        }
        rec.fill_buffer(&fb.incomplete, 0, 4, 0)?;
        rec.fill_buffer(&fb.requests, 0, stamps_bytes.max(4), 0)?;
        rec.barrier();
        tracer.record(&mut rec, push_bytes, dims, groups)?;
        rec.barrier();
        if let Some(bs) = self.gpu.blas_stamps() {
            if nb > 0 {
                rec.copy_buffer(bs, 0, &fb.readback, 0, stamps_bytes)?;
                rec.copy_buffer(&fb.requests, 0, &fb.readback, req_off, stamps_bytes)?;
            }
        }
        // The incomplete list holds at most one entry per item traced: its count, then that
        // many pixels and what each waits for (not the whole frame's list).
        let listed = (u64::from(full_count) + list.len() as u64).min(pixels);
        rec.copy_buffer(&fb.incomplete, 0, &fb.readback, inc_off, 4 + 4 * listed)?;
        if listed > 0 {
            let blockers_off = 4 + 4 * pixels;
            rec.copy_buffer(
                &fb.incomplete,
                blockers_off,
                &fb.readback,
                inc_off + blockers_off,
                4 * listed,
            )?;
        }
        // The counters so far, where the final image's stats words go (read_image overwrites).
        let counters_off = final_off + pixels * 20;
        self.record_counter_copies(&mut rec, stats, &fb.readback, counters_off)?;
        rec.submit_and_wait()?;
        let trace_ms = t0.elapsed().as_secs_f64() * 1e3;
        let stamps: Vec<u32> = fb.readback.read_vec(0, nb)?;
        let requests: Vec<u32> = fb.readback.read_vec(req_off, nb)?;
        let count = fb
            .readback
            .read_vec::<u32>(inc_off, 1)?
            .first()
            .copied()
            .unwrap_or(0);
        let count = count.min(listed as u32);
        let incomplete: Vec<u32> = fb.readback.read_vec(inc_off + 4, count as usize)?;
        let blockers: Vec<u32> = fb
            .readback
            .read_vec(inc_off + 4 + 4 * pixels, count as usize)?;
        let words: Vec<u32> = fb.readback.read_vec(counters_off, STAT_WORDS)?;
        Ok((
            PassReadback {
                stamps,
                requests,
                incomplete,
                trace_ms,
            },
            PassExtra {
                blockers,
                counters: ShaderCounters::of(&words, self.read_proxy_counts()?),
            },
        ))
    }
}

impl StreamingRenderer<'_> {
    /// Counting mode: makes or grows its stats buffer for a pass of `items` launch items.
    fn ensure_proxy_counts(&mut self, items: u64) -> Result<()> {
        if !self.opts.count_proxy_calls {
            return Ok(());
        }
        match self.frame.proxy_counts_slot() {
            Some(slot) => proxy_count::ensure_count_buffer(&mut self.heap, slot, items),
            None => Ok(()),
        }
    }

    /// The stats buffer a pass's shaders write (the frame's, or counting mode's) and the bytes
    /// a frame's first pass clears (counting mode: all, its launch items' words included).
    fn pass_stats_buffer<'b>(&'b self, fb: &'b FrameBuffers) -> (&'b motu_vk::HeapBuffer, u64) {
        match self.frame.proxy_counts() {
            Some(c) => (&c.counts, c.counts.size_bytes()),
            None => (&fb.stats, (STAT_WORDS * 4) as u64),
        }
    }

    /// Records the copies of a pass's counters: the stats words to `readback` at `offset`, and
    /// counting mode's counters to its own read-back.
    fn record_counter_copies<'r>(
        &'r self,
        rec: &mut motu_vk::CommandRecorder<'r>,
        stats: &'r motu_vk::HeapBuffer,
        readback: &'r motu_vk::HeapBuffer,
        offset: u64,
    ) -> Result<()> {
        rec.copy_buffer(stats, 0, readback, offset, (STAT_WORDS * 4) as u64)?;
        if let Some(c) = self.frame.proxy_counts() {
            let words = (4 * PROXY_COUNT_WORDS) as u64;
            rec.copy_buffer(&c.counts, (STAT_WORDS * 4) as u64, &c.readback, 0, words)?;
        }
        Ok(())
    }

    /// Counting mode's counters so far (its read-back, copied by the pass; empty without it).
    fn read_proxy_counts(&self) -> Result<Vec<u32>> {
        match self.frame.proxy_counts() {
            Some(c) => Ok(c.readback.read_vec(0, PROXY_COUNT_WORDS)?),
            None => Ok(Vec::new()),
        }
    }
}

/// Packs image coordinates (possibly outside the image) for the pass's pixel list.
pub(super) fn pack_biased(x: i32, y: i32) -> u32 {
    let bx = (x + GUARD_BIAS).clamp(0, 0xffff) as u32;
    let by = (y + GUARD_BIAS).clamp(0, 0xffff) as u32;
    bx | (by << 16)
}

/// The pixel list of a pass that traces again the `incomplete` pixels a pass read back
/// (packed `x | y << 16`, unbiased).
pub(super) fn relist(incomplete: &[u32]) -> Vec<u32> {
    incomplete
        .iter()
        .map(|&v| pack_biased((v & 0xffff) as i32, (v >> 16) as i32))
        .collect()
}

/// Every other pixel of a `band`-pixel ring around a `w × h` image (primary rays only).
pub(super) fn guard_pixels(w: u32, h: u32, band: u32) -> Vec<u32> {
    let band = band.min(GUARD_BIAS as u32 / 2) as i32;
    if band == 0 {
        return Vec::new();
    }
    let (w, h) = (w as i32, h as i32);
    let mut out = Vec::new();
    let mut y = -band;
    while y < h + band {
        let mut x = -band;
        while x < w + band {
            if x < 0 || y < 0 || x >= w || y >= h {
                out.push(pack_biased(x, y));
            }
            x += 2;
        }
        y += 2;
    }
    out
}
