//! The whole-frame clock (issue 45.6; notes/flight.md D2, D3): with
//! [`StreamOptions::frame_ms`](super::StreamOptions::frame_ms) a frame's build work goes on only
//! while what is left of the frame covers it by estimate, so the trace, the build step, the
//! stale TLAS pieces and the readback share one budget instead of the build alone having one.
//! The estimates are running averages measured on this renderer's device: what a triangle costs
//! to make resident (mesh upload and BLAS build together), a TLAS piece rebuild, the frame's
//! tail after its last build decision (tables, readback, statistics, outputs) and a probe round.
//! [`FrameCaps`](super::FrameCaps) replaces them by counts for tests: lavapipe's times say
//! nothing about a GPU's, and counts make frames repeatable.
//!
//! Pure bookkeeping (no GPU): the renderer samples it (`budget.rs`, `demand.rs`,
//! `piece_order.rs`) and asks it how much fits.

use std::time::Instant;

/// A new sample's weight in a running average. A group of builds or a piece rebuild varies
/// from one to the next by tens of percent (sizes differ): with a quarter, one outlier moves
/// the estimate by a quarter of its error and a lasting change is followed within ~4 samples.
const EWMA_WEIGHT: f64 = 0.25;

/// An exponentially weighted moving average; none until the first sample, which it takes
/// as it is.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub(super) struct Ewma(Option<f64>);

impl Ewma {
    /// Adds a sample; negative or non-finite ones (a clock read across a suspend) are dropped.
    pub(super) fn note(&mut self, sample: f64) {
        if !sample.is_finite() || sample < 0.0 {
            return;
        }
        self.0 = Some(match self.0 {
            None => sample,
            Some(v) => v + EWMA_WEIGHT * (sample - v),
        });
    }

    /// The average, none before the first sample.
    pub(super) fn get(self) -> Option<f64> {
        self.0
    }
}

/// The running frame's start and the renderer's estimates (kept between frames in `Kept`).
#[derive(Debug, Default)]
pub(super) struct FrameClock {
    /// When the running frame began (`FrameState::begin`).
    start: Option<Instant>,
    /// When the running frame's last build decision was taken, if no prefetch or probe came
    /// after it: what the frame does from there to its end is its tail.
    tail_from: Option<Instant>,
    /// Nanoseconds a triangle takes to make resident: a build group's wall (room, mesh upload,
    /// BLAS build) over its triangles.
    build_ns_per_triangle: Ewma,
    /// Milliseconds a TLAS piece rebuild takes (a rebuild group's wall over its pieces).
    piece_ms: Ewma,
    /// Milliseconds from a frame's last build decision to its end.
    tail_ms: Ewma,
    /// Milliseconds a probe round's trace takes.
    probe_ms: Ewma,
}

impl FrameClock {
    /// A frame starts at `now`.
    pub(super) fn begin(&mut self, now: Instant) {
        self.start = Some(now);
        self.tail_from = None;
    }

    /// Milliseconds since the running frame began (0 before any).
    pub(super) fn elapsed_ms(&self) -> f64 {
        self.start.map_or(0.0, |t| t.elapsed().as_secs_f64() * 1e3)
    }

    /// Milliseconds left of a frame of `frame_ms` after `elapsed_ms`, less the tail it still
    /// has to run by estimate (negative: over).
    pub(super) fn time_left_ms(&self, frame_ms: f64, elapsed_ms: f64) -> f64 {
        frame_ms - elapsed_ms - self.tail_ms.get().unwrap_or(0.0)
    }

    /// A build group of `triangles` took `ms` (from making its room to its BLASes built).
    pub(super) fn note_build(&mut self, ms: f64, triangles: u64) {
        if triangles > 0 {
            self.build_ns_per_triangle.note(ms * 1e6 / triangles as f64);
        }
    }

    /// A TLAS rebuild group of `pieces` took `ms`.
    pub(super) fn note_pieces(&mut self, ms: f64, pieces: u32) {
        if pieces > 0 {
            self.piece_ms.note(ms / f64::from(pieces));
        }
    }

    /// A probe round's trace took `ms`.
    pub(super) fn note_probe(&mut self, ms: f64) {
        self.probe_ms.note(ms);
    }

    /// The running frame took its last build decision at `now` (a pass's build step), or
    /// (`None`) a prefetch or probe followed: only a frame whose tail is the readback and
    /// outputs after its step samples it.
    pub(super) fn decided(&mut self, now: Option<Instant>) {
        self.tail_from = now;
    }

    /// The running frame ends at `now`: its tail is a sample when it has one.
    pub(super) fn end(&mut self, now: Instant) {
        if let Some(t) = self.tail_from.take() {
            self.tail_ms
                .note(now.saturating_duration_since(t).as_secs_f64() * 1e3);
        }
        self.start = None;
    }

    /// The estimate of one TLAS piece rebuild (0 before any was measured).
    pub(super) fn piece_estimate_ms(&self) -> f64 {
        self.piece_ms.get().unwrap_or(0.0)
    }

    /// How many BLASes of `triangles` (each one's count, in build order) fit in `left_ms`
    /// less `reserve_ms` by estimate: the longest prefix that fits, at least one when `must`
    /// (the frame has built nothing yet: a camera at rest must still converge). Before any
    /// build was measured, one when anything is left: its build is the first sample.
    pub(super) fn blases_within(
        &self,
        triangles: impl IntoIterator<Item = u64>,
        left_ms: f64,
        reserve_ms: f64,
        must: bool,
    ) -> usize {
        let floor = usize::from(must);
        let left = left_ms - reserve_ms;
        let mut tris = triangles.into_iter();
        let Some(ns) = self.build_ns_per_triangle.get() else {
            return match tris.next() {
                Some(_) if left > 0.0 || must => 1,
                _ => 0,
            };
        };
        let mut sum_ms = 0.0;
        let mut n = 0;
        for t in tris {
            sum_ms += t as f64 * ns * 1e-6;
            if sum_ms > left {
                return n.max(floor);
            }
            n += 1;
        }
        n
    }

    /// How many TLAS pieces fit in `left_ms` by estimate, at least one when `must`; one when
    /// anything is left and no rebuild was measured yet.
    pub(super) fn pieces_within(&self, left_ms: f64, must: bool) -> usize {
        let floor = usize::from(must);
        match self.piece_ms.get() {
            _ if left_ms <= 0.0 => floor,
            None => 1,
            Some(ms) if ms <= 0.0 => usize::MAX,
            Some(ms) => ((left_ms / ms).floor() as usize).max(floor),
        }
    }

    /// Whether a probe round fits in `left_ms` by estimate (before any was measured: when
    /// anything is left).
    pub(super) fn probe_fits(&self, left_ms: f64) -> bool {
        left_ms > 0.0 && self.probe_ms.get().is_none_or(|ms| ms <= left_ms)
    }
}

#[cfg(test)]
mod tests;
