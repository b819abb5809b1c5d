//! Small fixed-layout math types for the skeleton (glam for the arithmetic).

use glam::{Mat4, Vec3, Vec3A};
use serde::{Deserialize, Serialize};

/// A 3×4 affine transform, row-major (the layout of `VkTransformMatrixKHR`): rows are
/// `[m00 m01 m02 tx]`, `[m10 m11 m12 ty]`, `[m20 m21 m22 tz]`. 48 bytes, `Pod`, so edge tables
/// can be written to packages and GPU buffers without conversion.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct Transform34 {
    pub rows: [[f32; 4]; 3],
}

impl Default for Transform34 {
    fn default() -> Self {
        Self::IDENTITY
    }
}

impl Transform34 {
    pub const IDENTITY: Self = Self {
        rows: [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ],
    };

    /// From a glam affine matrix (the last row of `m` is assumed to be `0 0 0 1`).
    pub fn from_mat4(m: Mat4) -> Self {
        let c = m.to_cols_array_2d(); // c[col][row]
        let mut rows = [[0.0f32; 4]; 3];
        for (r, row) in rows.iter_mut().enumerate() {
            for (col, v) in row.iter_mut().enumerate() {
                *v = c[col][r];
            }
        }
        Self { rows }
    }

    /// From a row-major 4×4 array (pbrt's `Transform [...]` is column-major; convert first).
    pub fn from_rows4(m: [[f32; 4]; 4]) -> Self {
        Self {
            rows: [m[0], m[1], m[2]],
        }
    }

    pub fn to_mat4(&self) -> Mat4 {
        let r = &self.rows;
        Mat4::from_cols_array_2d(&[
            [r[0][0], r[1][0], r[2][0], 0.0],
            [r[0][1], r[1][1], r[2][1], 0.0],
            [r[0][2], r[1][2], r[2][2], 0.0],
            [r[0][3], r[1][3], r[2][3], 1.0],
        ])
    }

    pub fn from_translation(t: Vec3) -> Self {
        let mut m = Self::IDENTITY;
        m.rows[0][3] = t.x;
        m.rows[1][3] = t.y;
        m.rows[2][3] = t.z;
        m
    }

    /// `self ∘ rhs`: applies `rhs` first (`a_from_c = a_from_b.mul(b_from_c)`).
    pub fn mul(&self, rhs: &Self) -> Self {
        Self::from_mat4(self.to_mat4() * rhs.to_mat4())
    }

    /// The inverse, or `None` when the linear part is singular (degenerate instance).
    pub fn inverse(&self) -> Option<Self> {
        let m = self.to_mat4();
        let det = m.determinant();
        if !det.is_finite() || det.abs() < 1e-30 {
            return None;
        }
        Some(Self::from_mat4(m.inverse()))
    }

    #[inline]
    pub fn transform_point(&self, p: Vec3) -> Vec3 {
        let r = &self.rows;
        Vec3::new(
            r[0][0] * p.x + r[0][1] * p.y + r[0][2] * p.z + r[0][3],
            r[1][0] * p.x + r[1][1] * p.y + r[1][2] * p.z + r[1][3],
            r[2][0] * p.x + r[2][1] * p.y + r[2][2] * p.z + r[2][3],
        )
    }

    #[inline]
    pub fn transform_vector(&self, v: Vec3) -> Vec3 {
        let r = &self.rows;
        Vec3::new(
            r[0][0] * v.x + r[0][1] * v.y + r[0][2] * v.z,
            r[1][0] * v.x + r[1][1] * v.y + r[1][2] * v.z,
            r[2][0] * v.x + r[2][1] * v.y + r[2][2] * v.z,
        )
    }

    pub fn is_identity(&self, tolerance: f32) -> bool {
        self.rows
            .iter()
            .flatten()
            .zip(Self::IDENTITY.rows.iter().flatten())
            .all(|(a, b)| (a - b).abs() <= tolerance)
    }

    pub fn is_finite(&self) -> bool {
        self.rows.iter().flatten().all(|v| v.is_finite())
    }
}

/// An axis-aligned box. The empty box has `min > max` and absorbs nothing in unions.
#[derive(
    Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable, Serialize, Deserialize,
)]
#[repr(C)]
pub struct Aabb {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl Default for Aabb {
    fn default() -> Self {
        Self::EMPTY
    }
}

impl Aabb {
    pub const EMPTY: Self = Self {
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
    };

    pub fn from_min_max(min: Vec3, max: Vec3) -> Self {
        Self {
            min: min.to_array(),
            max: max.to_array(),
        }
    }

    pub fn is_empty(&self) -> bool {
        (0..3).any(|i| self.min[i] > self.max[i])
    }

    pub fn min_v(&self) -> Vec3 {
        Vec3::from_array(self.min)
    }

    pub fn max_v(&self) -> Vec3 {
        Vec3::from_array(self.max)
    }

    pub fn center(&self) -> Vec3 {
        (self.min_v() + self.max_v()) * 0.5
    }

    pub fn extent(&self) -> Vec3 {
        if self.is_empty() {
            Vec3::ZERO
        } else {
            self.max_v() - self.min_v()
        }
    }

    pub fn grow_point(&mut self, p: Vec3) {
        let (lo, hi) = (Vec3A::from(self.min_v()).min(p.into()), self.max_v().max(p));
        self.min = Vec3::from(lo).to_array();
        self.max = hi.to_array();
    }

    pub fn union(&self, o: &Self) -> Self {
        Self {
            min: self.min_v().min(o.min_v()).to_array(),
            max: self.max_v().max(o.max_v()).to_array(),
        }
    }

    pub fn contains(&self, o: &Self, tolerance: f32) -> bool {
        o.is_empty()
            || (0..3)
                .all(|i| o.min[i] >= self.min[i] - tolerance && o.max[i] <= self.max[i] + tolerance)
    }

    pub fn corners(&self) -> [Vec3; 8] {
        let (a, b) = (self.min_v(), self.max_v());
        std::array::from_fn(|i| {
            Vec3::new(
                if i & 1 == 0 { a.x } else { b.x },
                if i & 2 == 0 { a.y } else { b.y },
                if i & 4 == 0 { a.z } else { b.z },
            )
        })
    }

    /// The bounds of this box after `parent_from_child`: all 8 corners are transformed, so
    /// rotated boxes stay conservative.
    pub fn transformed(&self, parent_from_child: &Transform34) -> Self {
        if self.is_empty() {
            return Self::EMPTY;
        }
        let mut out = Self::EMPTY;
        for c in self.corners() {
            out.grow_point(parent_from_child.transform_point(c));
        }
        out
    }

    pub fn surface_area(&self) -> f32 {
        let e = self.extent();
        2.0 * (e.x * e.y + e.y * e.z + e.z * e.x)
    }
}

#[cfg(test)]
mod tests;
