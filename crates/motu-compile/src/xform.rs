//! Affine helpers on the row-major 3×4 layout shared by `Transform34` and the ABI records.
//! Composition and inversion are written out (inversion in f64) because the walk composes one
//! transform per flattened instance and the PI table stores inverses: both are hot and both
//! decide whether flattening the compiled hierarchy reproduces the source transforms.

use motu_scene::{Aabb, Transform34};

/// `a ∘ b`: applies `b` first.
#[inline]
pub(crate) fn compose(a: &Transform34, b: &Transform34) -> Transform34 {
    let (a, b) = (&a.rows, &b.rows);
    let mut out = [[0.0f32; 4]; 3];
    for (r, row) in out.iter_mut().enumerate() {
        for (c, v) in row.iter_mut().enumerate() {
            *v = a[r][0] * b[0][c] + a[r][1] * b[1][c] + a[r][2] * b[2][c];
        }
        row[3] += a[r][3];
    }
    Transform34 { rows: out }
}

/// The determinant below which a transform counts as degenerate (matches
/// `Transform34::inverse`).
const MIN_ABS_DET: f64 = 1e-30;

#[inline]
fn det(t: &Transform34) -> f64 {
    let m = |r: usize, c: usize| t.rows[r][c] as f64;
    m(0, 0) * (m(1, 1) * m(2, 2) - m(1, 2) * m(2, 1))
        - m(0, 1) * (m(1, 0) * m(2, 2) - m(1, 2) * m(2, 0))
        + m(0, 2) * (m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0))
}

/// The inverse, or `None` when the linear part is singular or the result is not finite.
pub(crate) fn inverse(t: &Transform34) -> Option<Transform34> {
    let m = |r: usize, c: usize| t.rows[r][c] as f64;
    let det = det(t);
    if !det.is_finite() || det.abs() < MIN_ABS_DET {
        return None;
    }
    let inv_det = 1.0 / det;
    // Adjugate / det.
    let l = [
        [
            (m(1, 1) * m(2, 2) - m(1, 2) * m(2, 1)) * inv_det,
            (m(0, 2) * m(2, 1) - m(0, 1) * m(2, 2)) * inv_det,
            (m(0, 1) * m(1, 2) - m(0, 2) * m(1, 1)) * inv_det,
        ],
        [
            (m(1, 2) * m(2, 0) - m(1, 0) * m(2, 2)) * inv_det,
            (m(0, 0) * m(2, 2) - m(0, 2) * m(2, 0)) * inv_det,
            (m(0, 2) * m(1, 0) - m(0, 0) * m(1, 2)) * inv_det,
        ],
        [
            (m(1, 0) * m(2, 1) - m(1, 1) * m(2, 0)) * inv_det,
            (m(0, 1) * m(2, 0) - m(0, 0) * m(2, 1)) * inv_det,
            (m(0, 0) * m(1, 1) - m(0, 1) * m(1, 0)) * inv_det,
        ],
    ];
    let t3 = [m(0, 3), m(1, 3), m(2, 3)];
    let mut rows = [[0.0f32; 4]; 3];
    for r in 0..3 {
        let tr = -(l[r][0] * t3[0] + l[r][1] * t3[1] + l[r][2] * t3[2]);
        rows[r] = [l[r][0] as f32, l[r][1] as f32, l[r][2] as f32, tr as f32];
    }
    let out = Transform34 { rows };
    out.is_finite().then_some(out)
}

/// The degeneracy test of [`inverse`] without computing it (run per edge in every pass).
#[inline]
pub(crate) fn is_invertible(t: &Transform34) -> bool {
    let d = det(t);
    d.is_finite() && d.abs() >= MIN_ABS_DET
}

#[inline]
pub(crate) fn to_array(t: &Transform34) -> [f32; 12] {
    bytemuck_cast(t)
}

#[inline]
pub(crate) fn from_array(a: &[f32; 12]) -> Transform34 {
    Transform34 {
        rows: [
            [a[0], a[1], a[2], a[3]],
            [a[4], a[5], a[6], a[7]],
            [a[8], a[9], a[10], a[11]],
        ],
    }
}

#[inline]
fn bytemuck_cast(t: &Transform34) -> [f32; 12] {
    let r = &t.rows;
    [
        r[0][0], r[0][1], r[0][2], r[0][3], r[1][0], r[1][1], r[1][2], r[1][3], r[2][0], r[2][1],
        r[2][2], r[2][3],
    ]
}

pub(crate) fn aabb_from_record(min: [f32; 3], max: [f32; 3]) -> Aabb {
    Aabb { min, max }
}

#[cfg(test)]
mod tests;
