//! Quantised member boxes: a cheap first test for the proxy clusters' member instances.
//!
//! A ray that enters a proxy box tests each member instance's box (`proxy_entry` in
//! `candidates.glsl`): its BLAS bounds under its `tlas_from_blas`, padded. Computing that box
//! needs the member's instance record (a scattered 64-byte read) and a transform, and a ray
//! enters a member's box in well under 1% of those tests (session 45's lavapipe counts), so
//! the member tests were most of the streamed trace's tax (~40 of ~56 ms on an H100 with
//! everything resident). The member table therefore keeps, per member, its box quantised to
//! 8 bits an axis against a reference box derived from the proxy box alone ([`reference`]),
//! rounded outward: 8 bytes a member, read contiguously per cluster. The shader runs the exact
//! test only for members whose quantised box the ray enters, so what it computes is unchanged:
//! the quantised box holds the exact one ([`member_box`], the shader's arithmetic), and one the
//! quantisation cannot hold is stored as [`ALWAYS`] (the exact test always runs).
//!
//! Layout of a cluster's words in the member table (`member_first` names the first):
//! `2 × n` words of packed boxes (`[lo.x, lo.y, lo.z, hi.x]`, `[hi.y, hi.z, 0, 0]` as bytes,
//! little end first), then `n` global instance indices.

/// Words of the member table a member takes (two of box, one of index).
pub(super) const MEMBER_WORDS: usize = 3;

/// A packed box the shader never skips on (`lo.x > hi.x`): the exact test always runs.
pub(super) const ALWAYS: [u32; 2] = [0x0000_00ff, 0];

/// The dequantisation's own rounding (relative to the proxy box's magnitude and extent), a
/// margin far above the few ulps the shader's `fma`s may differ from this code by.
const DEQUANT_PAD: f32 = 1e-5;

fn max3(v: [f32; 3]) -> f32 {
    v[0].max(v[1]).max(v[2])
}

/// The reference box of proxy box `bounds` (`[min, max]`) that member boxes are quantised
/// against, as `(origin, step, pad)`: a quantised value `q` stands for `origin + q × step`,
/// less (lower bounds) or plus (upper bounds) `pad`. Grown beyond the proxy box by more than a
/// member's padding can reach past it (`padded` pads the proxy box by 1e-3 of its extent and
/// 1e-5 of its magnitude; a member pads by 1e-3 of its own extent and 2e-5 of its magnitude).
/// `candidates.glsl` computes the same, in the same order.
pub(super) fn reference(bounds: &[f32; 6]) -> ([f32; 3], [f32; 3], f32) {
    let lo = [bounds[0], bounds[1], bounds[2]];
    let hi = [bounds[3], bounds[4], bounds[5]];
    let ext = [hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]];
    let magnitude = lo.iter().chain(&hi).fold(0.0f32, |m, v| m.max(v.abs()));
    let grow = 2e-3 * max3(ext) + 4e-5 * magnitude;
    let origin = [lo[0] - grow, lo[1] - grow, lo[2] - grow];
    let step = [
        (ext[0] + 2.0 * grow) * (1.0 / 255.0),
        (ext[1] + 2.0 * grow) * (1.0 / 255.0),
        (ext[2] + 2.0 * grow) * (1.0 / 255.0),
    ];
    let pad = DEQUANT_PAD * (magnitude + max3(ext));
    (origin, step, pad)
}

/// The box `proxy_entry` tests for a member instance placed by `m` (row-major 3×4) of a BLAS
/// with bounds `blas_lo..blas_hi`: the transformed bounds (centre and half-size form), padded
/// by 1e-3 of its extent and 2e-5 of its magnitude. The shader's arithmetic, in f32.
pub(super) fn member_box(m: &[f32; 12], blas_lo: [f32; 3], blas_hi: [f32; 3]) -> [f32; 6] {
    let centre = [
        0.5 * (blas_lo[0] + blas_hi[0]),
        0.5 * (blas_lo[1] + blas_hi[1]),
        0.5 * (blas_lo[2] + blas_hi[2]),
    ];
    let half = [
        0.5 * (blas_hi[0] - blas_lo[0]),
        0.5 * (blas_hi[1] - blas_lo[1]),
        0.5 * (blas_hi[2] - blas_lo[2]),
    ];
    let c = motu_abi::xform_point(m, centre);
    let h: [f32; 3] = std::array::from_fn(|r| {
        m[4 * r].abs() * half[0] + m[4 * r + 1].abs() * half[1] + m[4 * r + 2].abs() * half[2]
    });
    let lo: [f32; 3] = std::array::from_fn(|a| c[a] - h[a]);
    let hi: [f32; 3] = std::array::from_fn(|a| c[a] + h[a]);
    let extent = 2.0 * max3(h);
    let magnitude = lo.iter().chain(&hi).fold(0.0f32, |m, v| m.max(v.abs()));
    let pad = 1e-3 * extent + 2e-5 * magnitude;
    [
        lo[0] - pad,
        lo[1] - pad,
        lo[2] - pad,
        hi[0] + pad,
        hi[1] + pad,
        hi[2] + pad,
    ]
}

/// Quantised value `q`'s level on axis `a`, before the shader's pad.
fn level(reference: &([f32; 3], [f32; 3], f32), a: usize, q: u8) -> f32 {
    reference.0[a] + f32::from(q) * reference.1[a]
}

/// What the shader makes of quantised value `q` on axis `a`: the lower bound when `upper` is
/// false, else the upper one (its level less or plus the pad, which covers the few ulps by
/// which the shader's rounding may differ from this code's).
#[cfg(test)]
fn dequantised(reference: &([f32; 3], [f32; 3], f32), a: usize, q: u8, upper: bool) -> f32 {
    let pad = reference.2;
    if upper {
        level(reference, a, q) + pad
    } else {
        level(reference, a, q) - pad
    }
}

/// Member box `b` quantised against proxy box `bounds` ([`Quantiser::quantise`]).
#[cfg(test)]
fn quantised(bounds: &[f32; 6], b: &[f32; 6]) -> [u32; 2] {
    Quantiser::new(bounds).quantise(b)
}

/// Quantises the member boxes of one proxy box: its reference box made once (a cluster's
/// members share it; island 0.63 has 17M members to quantise at the start).
pub(super) struct Quantiser {
    reference: ([f32; 3], [f32; 3], f32),
    /// `1 / step` per axis (0 for a flat axis), for the first guess only.
    inverse_step: [f32; 3],
    /// The proxy box and its reference are finite.
    finite: bool,
}

impl Quantiser {
    pub(super) fn new(bounds: &[f32; 6]) -> Quantiser {
        let reference = reference(bounds);
        let finite = bounds
            .iter()
            .chain(&reference.0)
            .chain(&reference.1)
            .all(|v| v.is_finite());
        let inverse_step = reference.1.map(|s| if s > 0.0 { 1.0 / s } else { 0.0 });
        Quantiser {
            reference,
            inverse_step,
            finite,
        }
    }

    /// Member box `b` quantised, rounded outward so the shader's dequantised box holds `b`;
    /// [`ALWAYS`] where it cannot (a box outside the reference, or anything not finite).
    pub(super) fn quantise(&self, b: &[f32; 6]) -> [u32; 2] {
        if !self.finite || !b.iter().all(|v| v.is_finite()) {
            return ALWAYS;
        }
        let r = &self.reference;
        let mut q = [0u8; 6];
        for a in 0..3 {
            // A first guess (any rounding is corrected below), clamped to the byte first so
            // the cast's truncation is a floor (and a NaN becomes 0): `floor` is a libm call
            // on the baseline x86-64 target.
            let guess = |v: f32| ((v - r.0[a]) * self.inverse_step[a]).clamp(0.0, 255.0) as i32;
            // The largest q whose level is at or below b's lower bound, and the smallest
            // whose level is at or above its upper one: the shader's pad is then all margin.
            let mut lo = guess(b[a]);
            while lo > 0 && level(r, a, lo as u8) > b[a] {
                lo -= 1;
            }
            let mut hi = (guess(b[3 + a]) + 1).min(255);
            while hi > 0 && level(r, a, (hi - 1) as u8) >= b[3 + a] {
                hi -= 1;
            }
            while hi < 255 && level(r, a, hi as u8) < b[3 + a] {
                hi += 1;
            }
            if level(r, a, lo as u8) > b[a] || level(r, a, hi as u8) < b[3 + a] {
                return ALWAYS;
            }
            q[a] = lo as u8;
            q[3 + a] = hi as u8;
        }
        [
            u32::from_le_bytes([q[0], q[1], q[2], q[3]]),
            u32::from_le_bytes([q[4], q[5], 0, 0]),
        ]
    }
}

#[cfg(test)]
mod tests;
