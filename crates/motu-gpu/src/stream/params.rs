//! The per-pass parameter block the traversal shaders read (`StreamParams` of `common.glsl`)
//! and the size of the per-pixel state carried across passes: the GPU-facing layout that the
//! pass loop fills and the frame buffers size, kept below both.

use bytemuck::{Pod, Zeroable};

/// `StreamParams` of `common.glsl` (96 bytes).
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
#[repr(C)]
pub(super) struct StreamParams {
    /// u32 per BLAS: `4 × stamp + level` (seen 0, open 1, needed 2) of the latest pass.
    pub(super) blas_stamps: u64,
    /// u32 per BLAS: the latest stamp of a pass it was resident (walked) in.
    pub(super) walked: u64,
    pub(super) pixel_list: u64,
    pub(super) incomplete: u64,
    pub(super) stamp: u32,
    pub(super) full_count: u32,
    pub(super) list_count: u32,
    pub(super) blas_count: u32,
    /// u32 per BLAS: pixels of the pass whose nearest open structure it is (build priority),
    /// with [`REQUEST_CAMERA`] where a camera ray's; for a resident BLAS, the kinds of ray
    /// whose closest hit it held (`HIT_*`).
    pub(super) requests: u64,
    /// [`CARRY_BYTES`] per pixel: the state carried across passes (`Carry` of
    /// `render_pixel.glsl`).
    pub(super) carry: u64,
    /// u32 global instance indices of the proxy clusters' members (a proxy PI record names
    /// its range), 0: no proxies.
    pub(super) cluster_members: u64,
    /// `[first, fan]` (u32 each) per BLAS and the boxes inside BLASes (`[f32; 6]` each, BLAS
    /// space) a ray must also enter to open one (`proxy_boxes.rs`); 0: none.
    pub(super) proxy_box_index: u64,
    pub(super) proxy_boxes: u64,
    /// [`STREAM_PROBE_PASS`] or 0 (with [`STREAM_PROBE_STOP`]), with a probe's pass-mark row
    /// stride `<<` [`STREAM_PASS_ROWS_SHIFT`], and [`STREAM_OPEN_BOUND`].
    pub(super) flags: u32,
    pub(super) _pad: u32,
}

/// `STREAM_PROBE_PASS` of `common.glsl`: the pass probes the next frame's camera (every
/// pixel's rays run against what is resident and only mark what they meet).
pub(super) const STREAM_PROBE_PASS: u32 = 1;

/// `STREAM_PROBE_STOP` of `common.glsl`: a probe ray of a closest-hit link left open ends its
/// pixel's path ([`ProbePaths::Stop`](super::ProbePaths::Stop)).
pub(super) const STREAM_PROBE_STOP: u32 = 2;

/// `STREAM_LAST_PASS` of `common.glsl`: the frame's last pass (its pass cap or build budget
/// ends the frame after it): an open primary ray traces no secondary rays ahead.
pub(super) const STREAM_LAST_PASS: u32 = 4;

/// `STREAM_NO_MARK_WALK` of `common.glsl`: a last pass after which nothing is built (the
/// frame's build budget spent): no mark walks, whose marks only steer that build.
pub(super) const STREAM_NO_MARK_WALK: u32 = 8;

/// `STREAM_OPEN_BOUND` of `common.glsl`: a ray's walks after its first start from its
/// nearest open entry so far, and the pipeline's proxy intersection shader reads the current
/// walk's from the carry buffer ([`StreamOptions::open_bound`](super::StreamOptions::open_bound)).
pub(super) const STREAM_OPEN_BOUND: u32 = 16;

/// `STREAM_PASS_ROWS_SHIFT` of `common.glsl`: `flags >> it` is the probe's pass-mark row
/// stride (0: none; `StreamOptions::pass_marks`).
pub(super) const STREAM_PASS_ROWS_SHIFT: u32 = 8;

/// The largest pass-mark row stride the flags hold (a stride at or above the image height
/// marks row 0 only, so larger ones mean the same).
pub(super) const MAX_PASS_ROWS: u32 = u32::MAX >> STREAM_PASS_ROWS_SHIFT;

/// Stamps stay below this (`STREAM_START_STAMP` of `common.glsl` + 1): a ray's payload keeps
/// its start stamp in the low 29 bits, and a stamp table `4 × stamp + level` in a u32.
pub(super) const STAMP_LIMIT: u32 = 1 << 29;

/// The `flags` of a probe pass marking what the rays of every `pass_rows`-th row pass.
pub(super) fn probe_flags(pass_rows: u32, paths: super::ProbePaths) -> u32 {
    let stop = if paths == super::ProbePaths::Stop {
        STREAM_PROBE_STOP
    } else {
        0
    };
    STREAM_PROBE_PASS | stop | pass_rows.min(MAX_PASS_ROWS) << STREAM_PASS_ROWS_SHIFT
}

/// Whether a stamp-table value is a pass-mark walk's mark of pass `stamp`
/// (`4 × stamp - 1`, `candidates.glsl`).
pub(super) fn passed_mark(value: u32, stamp: u32) -> bool {
    stamp > 0 && value == 4 * stamp - 1
}

/// Bytes of one pixel's `Carry` (`render_pixel.glsl`).
pub(super) const CARRY_BYTES: u64 = 176;

#[cfg(test)]
mod tests;

/// `STREAM_HIT_*` of `common.glsl`: the kinds of ray whose closest hit lay in a resident BLAS,
/// or-ed per pass into its word of the requests buffer (a resident BLAS is never requested).
pub(super) const HIT_CAMERA: u32 = 1;
pub(super) const HIT_GUARD: u32 = 2;
pub(super) const HIT_OCCLUSION: u32 = 4;
pub(super) const HIT_BOUNCE: u32 = 8;

/// `STREAM_REQUEST_CAMERA` of `common.glsl`: the request word's bit of a non-resident BLAS
/// that some camera ray's nearest open structure is (the low bits count the rays).
pub(super) const REQUEST_CAMERA: u32 = 0x8000_0000;
