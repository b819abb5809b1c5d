//! A frame on the clock while the camera moves (issue 45.6; notes/flight.md D5A, D6): it
//! builds only into free room, and its probe of the next camera is cheaper.
//!
//! Why no evictions while flying: an eviction makes every TLAS piece holding the victim's
//! instances a *must* rebuild before the next trace (a stale piece may be traced, one
//! referencing a freed BLAS may not: `piece_order.rs`), and with a split root and popular
//! BLASes that is nearly every piece, ~100 ms on an H100 at ¼ of island 0.3, twice the whole
//! frame the clock aims at. While the camera moves, what does not fit the free room waits on
//! the counted fallback (`flying_no_room`); a camera at rest (its next camera its own, or none
//! named) evicts as before and converges to the exact image.
//!
//! Why a cheaper probe: only a complete frame probes, and its probe (every pixel, then its
//! rounds' build steps) is the longest part of such a frame while flying. On the clock it uses
//! [`StreamOptions::clocked_probe`](super::StreamOptions::clocked_probe) (by default a
//! sixteenth of the pixels, one round, no verifying round), and one the clock has no room for
//! is skipped and counted (`probe_skipped_clock`).

use motu_abi::camera::CameraParams;

use super::{ProbeSettings, StreamingRenderer};

impl<'a> StreamingRenderer<'a> {
    /// Whether the running frame flies: on the clock ([`Self::clocked`]), progressive, and
    /// naming a next camera other than its own. Its build steps (the prefetch's too) evict
    /// nothing.
    pub(super) fn flying(&self) -> bool {
        self.clocked() && self.frame.kept().moving()
    }

    /// The build queue of a flying frame stops at BLAS `blas`: it does not fit the free room
    /// (by estimate, or the budget refused it) and a flying frame evicts nothing. Counted;
    /// returns `left`, the BLASes of the queue left unbuilt.
    pub(super) fn flying_no_room(&mut self, blas: u32, left: usize) -> usize {
        self.frame.stats_mut().flying_no_room += 1;
        tracing::debug!(
            blas,
            left,
            free = self.free_budget_bytes(),
            "build queue stops: no free room while flying"
        );
        left
    }

    /// How the running frame probes the next camera: on the clock, as
    /// [`StreamOptions::clocked_probe`](super::StreamOptions::clocked_probe) says when set;
    /// otherwise as `probe_stride`, `probe_rounds` and `probe_verify_rounds` say.
    pub(super) fn probe_settings(&self) -> ProbeSettings {
        match self.opts.clocked_probe {
            Some(p) if self.clocked() => p,
            _ => ProbeSettings {
                stride: self.opts.probe_stride,
                rounds: self.opts.probe_rounds,
                verify_rounds: self.opts.probe_verify_rounds,
            },
        }
    }

    /// Whether the frame just traced (`width` × `height`) probes `next`: a probe stride, the
    /// same image size, a complete frame, and room in its build budget and on its clock
    /// ([`Self::probe_within_budget`]). A probe only the clock refused is counted
    /// (`probe_skipped_clock`).
    pub(super) fn may_probe(&mut self, next: &CameraParams, width: u32, height: u32) -> bool {
        if self.probe_settings().stride == 0
            || (next.width, next.height) != (width, height)
            || !self.frame.stats().complete
        {
            return false;
        }
        if self.probe_within_budget() {
            return true;
        }
        if self.clocked() && !self.build_budget_spent() {
            self.frame.stats_mut().probe_skipped_clock += 1;
        }
        false
    }
}
