//! Deferred TLAS rebuilds (issue 45.6; notes/flight.md D4): TLASes dirty only because BLASes
//! under them were built (*stale*, `tlases.rs`) may be traced as they are in a frame with a
//! build budget in milliseconds (`StreamOptions::frame_build_ms`: the viewer's progressive
//! mode, `--stream-build-ms`), and are rebuilt within that budget, those the camera sees
//! first, then the oldest.
//!
//! Why tracing a stale TLAS is safe: it references only resident BLASes (an eviction or a
//! move makes it a *must* rebuild, before any trace), and its proxy BLAS was built while the
//! new BLASes were not resident, so it still holds their clusters' boxes. A ray entering such
//! a box in front of its hit stays open (`record_proxy` in shaders/candidates.glsl: a
//! resident target, walked this pass, is never "resolved"; the walk keeps the box as the ray's
//! nearest open structure): the pixel shows the fallback, is counted, and never loses the
//! geometry. The host sees that BLAS resident and demands nothing for it; the pixel is exact
//! once its TLAS is rebuilt. Without a frame build budget in milliseconds (`motu render`, the
//! exact path) every dirty TLAS is rebuilt at each build step's end and before each trace, as
//! before.

use std::time::Instant;

use motu_abi::camera::CameraParams;
use motu_abi::TlasRecord;

use super::StreamingRenderer;
use crate::error::Result;

impl<'a> StreamingRenderer<'a> {
    /// Whether this frame may trace stale TLASes (a frame build budget in milliseconds or the
    /// frame's clock, and `StreamOptions::defer_stale_tlases`).
    pub(super) fn defers_stale_tlases(&self) -> bool {
        (self.frame_budget().1 > 0.0 || self.clocked()) && self.opts.defer_stale_tlases
    }

    /// BLAS `b` was built: its resident parents' instance sets grew (stale, see the module).
    pub(super) fn stale_parents(&mut self, b: usize) {
        let step = self.frame.number();
        for &p in self.topo.parents(b) {
            self.tlases.instances_added(p, step);
        }
    }

    /// Whether some TLAS must be rebuilt before the next trace: any dirty one, or with a frame
    /// build budget in milliseconds any dirty one that is not stale.
    pub(super) fn dirty_before_trace(&self) -> bool {
        if self.defers_stale_tlases() {
            self.tlases.any_must()
        } else {
            self.tlases.any_dirty()
        }
    }

    /// The TLAS rebuilds before a trace: those [`Self::dirty_before_trace`] names.
    pub(super) fn rebuild_before_trace(&mut self) -> Result<()> {
        if !self.defers_stale_tlases() {
            return self.rebuild_dirty();
        }
        self.rebuild_timed(|s| {
            s.rebuild_while(|s| {
                let must = |t| !s.tlases.is_stale(t);
                s.next_rebuild_group(must)
            })
        })
    }

    /// The TLAS rebuilds at a build step's end: every dirty TLAS; with a frame build budget
    /// in milliseconds every must one, then stale ones (those the frame's camera sees first,
    /// then the oldest) while the budget holds, at least one group in a frame that built or
    /// restored no BLAS and rebuilt no stale TLAS yet (so a camera at rest reaches the
    /// exact image) or, for up to the budget's time again, whose pixels wait on stale TLASes
    /// (so a moving one refines). On the frame's clock (`StreamOptions::frame_ms`) stale ones
    /// while its time left covers them by estimate, with the same guarantees of one group cut
    /// to one piece (`stale_within_clock`). Evictions for their room make must rebuilds, done
    /// before the next stale one. Each rebuild group's wall is a sample of the clock's piece
    /// estimate.
    pub(super) fn rebuild_step(&mut self) -> Result<()> {
        if !self.defers_stale_tlases() {
            return self.rebuild_dirty();
        }
        let order = self.stale_order();
        let mut next = 0usize;
        let mut stale_since: Option<Instant> = None;
        // The running group: its start and the frame's rebuild count then.
        let mut lap: Option<(Instant, u32)> = None;
        self.rebuild_timed(|s| {
            s.rebuild_while(|s| {
                if let Some((t0, before)) = lap.take() {
                    let ms = t0.elapsed().as_secs_f64() * 1e3;
                    let pieces = s.frame.stats().tlas_rebuilt.saturating_sub(before);
                    s.frame.kept_mut().clock_mut().note_pieces(ms, pieces);
                }
                let g = s.next_step_group(&order, &mut next, &mut stale_since)?;
                if g.is_some() {
                    lap = Some((Instant::now(), s.frame.stats().tlas_rebuilt));
                }
                Ok(g)
            })
        })
    }

    /// [`Self::rebuild_step`]'s next group: a must one, else a stale one from `order` (from
    /// `*next` on) while the budget or the clock allows; `stale_since`: when the frame's first
    /// stale group was taken.
    fn next_step_group(
        &mut self,
        order: &[u32],
        next: &mut usize,
        stale_since: &mut Option<Instant>,
    ) -> Result<Option<(Vec<u32>, u64)>> {
        let must = |t| !self.tlases.is_stale(t);
        if let Some(g) = self.next_rebuild_group(must)? {
            return Ok(Some(g));
        }
        let max = if self.clocked() {
            self.stale_within_clock()
        } else {
            let progressed = self.frame_progressed();
            let st = self.frame.stats();
            // While pixels wait on stale pieces, stale groups past the budget for up to
            // the frame build budget's time again (at least one group): else a moving
            // camera, whose every frame spends its budget on BLASes, would see new BLASes
            // only once it stops. With one group a frame, an H100 flying island 0.3 at a
            // quarter kept ~85k of 230k pixels on the fallback against ~45k rebuilding
            // every piece (session 50).
            let stale_ms = stale_since.map_or(0.0, |t| t.elapsed().as_secs_f64() * 1e3);
            let owed = st.stale_blocked_pixels > 0
                && (st.tlas_stale_rebuilt == 0 || stale_ms < self.frame_budget().1);
            if self.frame_build_spent() && progressed && !owed {
                return Ok(None);
            }
            usize::MAX
        };
        if max == 0 {
            return Ok(None);
        }
        while *next < order.len() && !self.tlases.is_stale(order[*next]) {
            *next += 1;
        }
        let Some(g) = self.stale_group(&order[*next..], max)? else {
            return Ok(None);
        };
        self.frame.stats_mut().tlas_stale_rebuilt += g.0.len() as u32;
        stale_since.get_or_insert_with(Instant::now);
        Ok(Some(g))
    }

    /// How many stale pieces the frame's clock allows next: those its time left covers by
    /// the piece estimate (with counts: `FrameCaps::pieces` less those rebuilt), at least
    /// one in a frame that made nothing resident and rebuilt no stale piece yet (a camera at
    /// rest converges) or whose pixels wait on stale pieces and rebuilt none yet (a moving
    /// camera refines; the BLAS groups kept one piece's time for it).
    fn stale_within_clock(&self) -> usize {
        let st = self.frame.stats();
        let must =
            !self.frame_progressed() || (st.stale_blocked_pixels > 0 && st.tlas_stale_rebuilt == 0);
        match self.opts.frame_caps {
            Some(c) => {
                let left = c.pieces.saturating_sub(st.tlas_stale_rebuilt) as usize;
                left.max(usize::from(must))
            }
            None => self
                .frame
                .kept()
                .clock()
                .pieces_within(self.frame_time_left_ms(), must),
        }
    }

    /// The next stale group from `order` (priority order; those no longer stale skipped),
    /// at most `max` TLASes: its first, then the next ones while the group's rebuilds need no
    /// more room than that one's or a 64th of the budget (as `group_by_need`, in priority
    /// order).
    fn stale_group(&self, order: &[u32], max: usize) -> Result<Option<(Vec<u32>, u64)>> {
        let counts = self.resident_instance_counts();
        let mut group = Vec::new();
        let (mut sum, mut cap) = (0u64, 0u64);
        for &t in order.iter().filter(|&&t| self.tlases.is_stale(t)) {
            let n = self.tlas_rebuild_bytes(t, counts[t as usize])?;
            if group.is_empty() {
                cap = n.max(self.build_opts.budget_bytes / 64);
            } else if sum + n > cap || group.len() >= max {
                break;
            }
            sum += n;
            group.push(t);
        }
        Ok((!group.is_empty()).then_some((group, sum)))
    }

    /// The stale TLASes, those whose bounds meet the frame's view first, then oldest first
    /// (ties by index). Bounds are in a TLAS's own space: for the root's pieces (the TLASes
    /// that matter here) that is the world's; a nested TLAS's test is a guess, and the order
    /// only decides which rebuild comes first, never what is traced.
    fn stale_order(&self) -> Vec<u32> {
        let camera = self.frame.kept().camera();
        let mut v: Vec<(bool, u64, u32)> = self
            .tlases
            .stale()
            .iter()
            .map(|(&t, &step)| {
                let seen =
                    camera.is_some_and(|c| tlas_meets_view(c, &self.view.tlases[t as usize]));
                (!seen, step, t)
            })
            .collect();
        v.sort_unstable();
        v.into_iter().map(|(_, _, t)| t).collect()
    }

    /// After a frame's passes: a frame with no pixel open whose budget is left rebuilds its
    /// stale TLASes within it (no build step ran to do it); one that leaves any stale is not
    /// complete (its image is exact, but later frames still have rebuilds to do, and a
    /// complete frame's probe would meet stale marks).
    pub(super) fn settle_stale_after_passes(&mut self) -> Result<()> {
        if self.tlases.stale().is_empty() {
            return Ok(());
        }
        if self.frame.stats().complete && !self.frame_build_spent() {
            let t0 = Instant::now();
            self.frame.kept_mut().start_step(t0);
            self.res.forget_built_now();
            let r = self
                .rebuild_step()
                .and_then(|()| self.upload_tlas_addresses());
            self.frame.kept_mut().end_step();
            self.frame.stats_mut().build_ms += t0.elapsed().as_secs_f64() * 1e3;
            if let Err(e) = r {
                self.quarantine_after_failure(&e);
                return Err(e);
            }
        }
        self.note_stale_tlases();
        Ok(())
    }

    /// The frame's `tlas_pieces_stale`; a frame that leaves any is not complete.
    pub(super) fn note_stale_tlases(&mut self) {
        let stale = self.tlases.stale().len() as u32;
        let st = self.frame.stats_mut();
        st.tlas_pieces_stale = stale;
        if stale > 0 {
            st.complete = false;
        }
    }

    /// A pass's open pixels that name a structure (`blockers`, read right after its trace,
    /// so residency is the trace's) plus `waiting` left untraced: its `open_closest`. Notes
    /// the frame's `stale_blocked_pixels` (the last pass's stands): blockers resident when
    /// traced (met in a stale TLAS's proxy: no other box names a resident BLAS to a frame
    /// pass) plus those left waiting under stale TLASes.
    pub(super) fn note_blockers(&mut self, blockers: &[u32], waiting: usize) -> u64 {
        if self.frame.stats().passes == 1 {
            self.frame.kept_mut().set_stale_waiting(0);
        }
        let nb = self.view.blases.len();
        let resident = blockers
            .iter()
            .filter(|&&b| (b as usize) < nb && self.res.has_blas(b as usize))
            .count();
        let stale = resident as u64 + self.frame.kept().stale_waiting();
        self.frame.stats_mut().stale_blocked_pixels = stale;
        // `NONE_U32` of the shaders: a pixel open for secondary rays only names none.
        let named = blockers.iter().filter(|&&b| b != u32::MAX).count();
        (named + waiting) as u64
    }

    /// Whether resident BLAS `b` has a stale parent: a ray open for it there stays open until
    /// that TLAS is rebuilt, so tracing its pixel again before then changes nothing.
    pub(super) fn under_stale_tlas(&self, b: usize) -> bool {
        self.topo
            .parents(b)
            .iter()
            .any(|&t| self.tlases.is_stale(t))
    }
}

/// Whether TLAS `t`'s bounds (taken as world space) meet the view pyramid of `c` (its four
/// side planes through the eye; no near or far plane). Empty bounds meet nothing.
pub(super) fn tlas_meets_view(c: &CameraParams, t: &TlasRecord) -> bool {
    box_meets_view(c, t.bounds_min, t.bounds_max)
}

/// [`tlas_meets_view`] for the box `lo`–`hi`.
pub(super) fn box_meets_view(c: &CameraParams, lo: [f32; 3], hi: [f32; 3]) -> bool {
    if !(0..3).all(|k| lo[k] <= hi[k]) {
        return false;
    }
    let add =
        |a: [f32; 3], b: [f32; 3], s: f32| [a[0] + s * b[0], a[1] + s * b[1], a[2] + s * b[2]];
    let cross = |a: [f32; 3], b: [f32; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let dot = |a: [f32; 3], b: [f32; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    let (w, h) = (c.width as f32, c.height as f32);
    let d00 = c.world_dir00;
    let d10 = add(d00, c.world_du, w);
    let d11 = add(d10, c.world_dv, h);
    let d01 = add(d00, c.world_dv, h);
    let centre = add(add(d00, c.world_du, 0.5 * w), c.world_dv, 0.5 * h);
    let corners = [d00, d10, d11, d01];
    for i in 0..4 {
        let mut n = cross(corners[i], corners[(i + 1) % 4]);
        if dot(n, centre) < 0.0 {
            n = [-n[0], -n[1], -n[2]];
        }
        // The box corner farthest along the plane's inward normal.
        let p: [f32; 3] = std::array::from_fn(|k| if n[k] >= 0.0 { hi[k] } else { lo[k] });
        let rel = add(p, c.world_eye, -1.0);
        if dot(n, rel) < 0.0 {
            return false;
        }
    }
    true
}

#[cfg(test)]
mod tests;
