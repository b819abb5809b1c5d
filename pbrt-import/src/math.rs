//! 4x4 transforms. Composition happens in f64; events carry f32 [`Mat4`]s.

/// A 4x4 affine/projective transform, `m[row][col]`, column-vector convention
/// (`p' = M * p`, translation in `m[0..3][3]`).
///
/// pbrt's `Transform [16]` lists the transpose of this, i.e. exactly
/// [`Mat4::to_cols_array`] (also glam's `Mat4::from_cols_array` order).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mat4(pub [[f32; 4]; 4]);

impl Mat4 {
    /// The identity.
    pub const IDENTITY: Mat4 = Mat4([
        [1.0, 0.0, 0.0, 0.0],
        [0.0, 1.0, 0.0, 0.0],
        [0.0, 0.0, 1.0, 0.0],
        [0.0, 0.0, 0.0, 1.0],
    ]);

    /// Column-major 16 values: pbrt's `Transform` order and glam's `from_cols_array`.
    pub fn to_cols_array(&self) -> [f32; 16] {
        let m = &self.0;
        std::array::from_fn(|i| m[i % 4][i / 4])
    }

    /// Inverse of [`Mat4::to_cols_array`].
    pub fn from_cols_array(v: &[f32; 16]) -> Mat4 {
        Mat4(std::array::from_fn(|r| {
            std::array::from_fn(|c| v[c * 4 + r])
        }))
    }

    /// Transform a point (with perspective divide when w != 1).
    pub fn transform_point(&self, p: [f32; 3]) -> [f32; 3] {
        let m = &self.0;
        let r: [f32; 4] =
            std::array::from_fn(|i| m[i][0] * p[0] + m[i][1] * p[1] + m[i][2] * p[2] + m[i][3]);
        if r[3] == 1.0 || r[3] == 0.0 {
            [r[0], r[1], r[2]]
        } else {
            [r[0] / r[3], r[1] / r[3], r[2] / r[3]]
        }
    }

    /// Whether the upper 3x3 has a negative determinant (flips handedness).
    pub fn swaps_handedness(&self) -> bool {
        let m = &self.0;
        let det = m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0]);
        det < 0.0
    }
}

pub(crate) type M64 = [[f64; 4]; 4];

pub(crate) const IDENTITY: M64 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
];

pub(crate) fn to_f32(m: &M64) -> Mat4 {
    Mat4(m.map(|r| r.map(|v| v as f32)))
}

pub(crate) fn mul(a: &M64, b: &M64) -> M64 {
    std::array::from_fn(|r| std::array::from_fn(|c| (0..4).map(|k| a[r][k] * b[k][c]).sum()))
}

/// From pbrt's 16 file values (column-major).
pub(crate) fn from_pbrt(v: &[f64; 16]) -> M64 {
    std::array::from_fn(|r| std::array::from_fn(|c| v[c * 4 + r]))
}

pub(crate) fn translate(d: [f64; 3]) -> M64 {
    let mut m = IDENTITY;
    m[0][3] = d[0];
    m[1][3] = d[1];
    m[2][3] = d[2];
    m
}

pub(crate) fn scale(s: [f64; 3]) -> M64 {
    let mut m = IDENTITY;
    m[0][0] = s[0];
    m[1][1] = s[1];
    m[2][2] = s[2];
    m
}

fn normalize(v: [f64; 3]) -> Option<[f64; 3]> {
    let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    (l > 0.0 && l.is_finite()).then(|| v.map(|c| c / l))
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

/// pbrt's `Rotate angle x y z` (degrees, right-handed about the axis). A zero axis gives identity.
pub(crate) fn rotate(deg: f64, axis: [f64; 3]) -> M64 {
    let Some(a) = normalize(axis) else {
        return IDENTITY;
    };
    let (s, c) = deg.to_radians().sin_cos();
    let mut m = IDENTITY;
    m[0][0] = a[0] * a[0] + (1.0 - a[0] * a[0]) * c;
    m[0][1] = a[0] * a[1] * (1.0 - c) - a[2] * s;
    m[0][2] = a[0] * a[2] * (1.0 - c) + a[1] * s;
    m[1][0] = a[0] * a[1] * (1.0 - c) + a[2] * s;
    m[1][1] = a[1] * a[1] + (1.0 - a[1] * a[1]) * c;
    m[1][2] = a[1] * a[2] * (1.0 - c) - a[0] * s;
    m[2][0] = a[0] * a[2] * (1.0 - c) - a[1] * s;
    m[2][1] = a[1] * a[2] * (1.0 - c) + a[0] * s;
    m[2][2] = a[2] * a[2] + (1.0 - a[2] * a[2]) * c;
    m
}

/// pbrt's `LookAt`: camera-from-world. `None` when up is parallel to the view direction.
pub(crate) fn look_at(pos: [f64; 3], look: [f64; 3], up: [f64; 3]) -> Option<M64> {
    let dir = normalize([look[0] - pos[0], look[1] - pos[1], look[2] - pos[2]])?;
    let right = normalize(cross(normalize(up)?, dir))?;
    let new_up = cross(dir, right);
    let mut world_from_camera = IDENTITY;
    for i in 0..3 {
        world_from_camera[i][0] = right[i];
        world_from_camera[i][1] = new_up[i];
        world_from_camera[i][2] = dir[i];
        world_from_camera[i][3] = pos[i];
    }
    inverse(&world_from_camera)
}

/// General 4x4 inverse (Gauss-Jordan, partial pivoting); `None` if singular.
pub(crate) fn inverse(m: &M64) -> Option<M64> {
    let mut a = *m;
    let mut inv = IDENTITY;
    for col in 0..4 {
        let pivot = (col..4).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[pivot][col].abs() < 1e-300 || !a[pivot][col].is_finite() {
            return None;
        }
        a.swap(col, pivot);
        inv.swap(col, pivot);
        let p = a[col][col];
        for c in 0..4 {
            a[col][c] /= p;
            inv[col][c] /= p;
        }
        for r in 0..4 {
            if r != col {
                let f = a[r][col];
                if f != 0.0 {
                    for c in 0..4 {
                        a[r][c] -= f * a[col][c];
                        inv[r][c] -= f * inv[col][c];
                    }
                }
            }
        }
    }
    Some(inv)
}

#[cfg(test)]
mod tests;
