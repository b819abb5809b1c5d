//! Rays, the 3×4 affine helpers traversal needs, the slab test and the watertight
//! ray–triangle test (Woop, Benthin, Wald 2013, "Watertight Ray/Triangle Intersection").

use motu_abi::{xform_point, xform_vector};

/// The identity as a row-major 3×4 matrix.
pub const IDENTITY_3X4: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// `a ∘ b` (apply `b` first) for row-major 3×4 affine matrices.
pub fn compose(a: &[f32; 12], b: &[f32; 12]) -> [f32; 12] {
    let mut r = [0.0f32; 12];
    for row in 0..3 {
        for col in 0..4 {
            let mut s = if col == 3 { a[row * 4 + 3] } else { 0.0 };
            for k in 0..3 {
                s += a[row * 4 + k] * b[k * 4 + col];
            }
            r[row * 4 + col] = s;
        }
    }
    r
}

/// The inverse of a row-major 3×4 affine matrix, computed in f64; `None` when singular or not
/// finite (such an instance can never be hit).
pub fn invert(m: &[f32; 12]) -> Option<[f32; 12]> {
    motu_abi::invert_3x4(m).filter(|r| r.iter().all(|v| v.is_finite()))
}

/// `Mᵀ n` of the linear part: turns an object-space normal into world space when `m` is
/// `object_from_world` (the inverse transpose of `world_from_object`, without inverting).
pub fn transpose_vector(m: &[f32; 12], n: [f32; 3]) -> [f32; 3] {
    [
        m[0] * n[0] + m[4] * n[1] + m[8] * n[2],
        m[1] * n[0] + m[5] * n[1] + m[9] * n[2],
        m[2] * n[0] + m[6] * n[1] + m[10] * n[2],
    ]
}

#[inline]
pub(crate) fn sub(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

#[inline]
pub(crate) fn cross(a: [f32; 3], b: [f32; 3]) -> [f32; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

#[inline]
pub(crate) fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[inline]
pub(crate) fn length(a: [f32; 3]) -> f32 {
    dot(a, a).sqrt()
}

pub(crate) fn normalize(a: [f32; 3]) -> [f32; 3] {
    let l = length(a);
    if l > 0.0 && l.is_finite() {
        [a[0] / l, a[1] / l, a[2] / l]
    } else {
        [0.0, 0.0, 1.0]
    }
}

/// A ray in some space with everything the box and triangle tests precompute.
#[derive(Clone, Copy, Debug)]
pub struct LocalRay {
    pub org: [f32; 3],
    pub dir: [f32; 3],
    pub inv_dir: [f32; 3],
    /// Woop's permutation: `kz` is the dominant axis of `dir`.
    kx: usize,
    ky: usize,
    kz: usize,
    /// Shear constants.
    sx: f32,
    sy: f32,
    sz: f32,
}

impl LocalRay {
    pub fn new(org: [f32; 3], dir: [f32; 3]) -> Self {
        let inv_dir = dir.map(|d| 1.0 / d);
        let ad = dir.map(f32::abs);
        let kz = if ad[0] > ad[1] {
            if ad[0] > ad[2] {
                0
            } else {
                2
            }
        } else if ad[1] > ad[2] {
            1
        } else {
            2
        };
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        // Swap to keep the winding so U, V, W signs stay consistent.
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let sz = 1.0 / dir[kz];
        Self {
            org,
            dir,
            inv_dir,
            kx,
            ky,
            kz,
            sx: dir[kx] * sz,
            sy: dir[ky] * sz,
            sz,
        }
    }

    /// The ray mapped by a 3×4 affine matrix; the direction is NOT renormalised so `t` keeps
    /// its meaning (world units) in every space.
    pub fn transformed(&self, m: &[f32; 12]) -> Self {
        Self::new(xform_point(m, self.org), xform_vector(m, self.dir))
    }

    /// Slab test: the entry distance when `[t_min, t_max]` overlaps the box. The far distance
    /// is widened by `1 + 2γ₃` (Ize 2013) so boxes stay conservative for the watertight test.
    #[inline]
    pub fn hit_box(&self, min: &[f32; 3], max: &[f32; 3], t_min: f32, t_max: f32) -> Option<f32> {
        let mut t0 = t_min;
        let mut t1 = t_max;
        for a in 0..3 {
            let n = (min[a] - self.org[a]) * self.inv_dir[a];
            let f = (max[a] - self.org[a]) * self.inv_dir[a];
            // 0 × ∞: a ray parallel to this axis lying in a slab plane; it is inside the slab
            // for every t, so the axis does not constrain (conservative).
            if n.is_nan() || f.is_nan() {
                continue;
            }
            t0 = t0.max(n.min(f));
            t1 = t1.min(n.max(f) * 1.000_000_4);
        }
        (t0 <= t1).then_some(t0)
    }

    /// Watertight ray–triangle test; returns `t` in `(t_min, t_max)`, double-sided. Edges and
    /// vertices are inclusive, so rays through shared edges never leak between triangles.
    #[inline]
    pub fn hit_triangle(
        &self,
        v0: [f32; 3],
        v1: [f32; 3],
        v2: [f32; 3],
        t_min: f32,
        t_max: f32,
    ) -> Option<f32> {
        self.hit_triangle_bary(v0, v1, v2, t_min, t_max)
            .map(|h| h.0)
    }

    /// [`LocalRay::hit_triangle`] with the hit's barycentric weights of `v0`, `v1`, `v2`.
    #[inline]
    pub fn hit_triangle_bary(
        &self,
        v0: [f32; 3],
        v1: [f32; 3],
        v2: [f32; 3],
        t_min: f32,
        t_max: f32,
    ) -> Option<(f32, [f32; 3])> {
        let (kx, ky, kz) = (self.kx, self.ky, self.kz);
        let a = sub(v0, self.org);
        let b = sub(v1, self.org);
        let c = sub(v2, self.org);
        let ax = a[kx] - self.sx * a[kz];
        let ay = a[ky] - self.sy * a[kz];
        let bx = b[kx] - self.sx * b[kz];
        let by = b[ky] - self.sy * b[kz];
        let cx = c[kx] - self.sx * c[kz];
        let cy = c[ky] - self.sy * c[kz];
        let mut u = cx * by - cy * bx;
        let mut v = ax * cy - ay * cx;
        let mut w = bx * ay - by * ax;
        // On an edge in f32: decide in f64 so neighbours agree exactly.
        if u == 0.0 || v == 0.0 || w == 0.0 {
            let (ax, ay, bx, by, cx, cy) = (
                ax as f64, ay as f64, bx as f64, by as f64, cx as f64, cy as f64,
            );
            u = (cx * by - cy * bx) as f32;
            v = (ax * cy - ay * cx) as f32;
            w = (bx * ay - by * ax) as f32;
        }
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None;
        }
        let az = self.sz * a[kz];
        let bz = self.sz * b[kz];
        let cz = self.sz * c[kz];
        let t = (u * az + v * bz + w * cz) / det;
        (t > t_min && t < t_max).then_some((t, [u / det, v / det, w / det]))
    }
}

/// Moves a hit point off its surface along the face-forwarded normal `n` (Wächter & Binder,
/// "A Fast and Robust Method for Avoiding Self-Intersection", Ray Tracing Gems ch. 6): an
/// offset of 256 ULPs per unit of normal, a small absolute one near the origin. The GPU
/// mirrors this, so shadow rays start at the same point.
pub fn shadow_offset(p: [f32; 3], n: [f32; 3], reach: f32) -> [f32; 3] {
    // `reach` (largest |origin| component + hit distance) bounds the error of p = o + t·d,
    // which Wächter & Binder's offset (made for exact p) does not cover.
    let p: [f32; 3] = std::array::from_fn(|a| p[a] + n[a] * (reach * (1.0 / 262_144.0)));
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    std::array::from_fn(|a| {
        if p[a].abs() < ORIGIN {
            p[a] + FLOAT_SCALE * n[a]
        } else {
            let of = (INT_SCALE * n[a]) as i32;
            let bits = p[a].to_bits() as i32;
            f32::from_bits((if p[a] < 0.0 { bits - of } else { bits + of }) as u32)
        }
    })
}

#[cfg(test)]
mod tests;
