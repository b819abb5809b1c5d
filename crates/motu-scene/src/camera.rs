//! Named perspective cameras.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// A perspective camera as a look-at frame in world space.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub name: String,
    pub world_eye: [f32; 3],
    /// Unit view direction in world space.
    pub world_forward: [f32; 3],
    /// Unit up vector in world space, orthogonal to `world_forward`.
    pub world_up: [f32; 3],
    /// pbrt semantics: the field of view spans the *shorter* image axis, in degrees.
    pub fov_deg: f32,
    pub width: u32,
    pub height: u32,
    /// pbrt's `Scale -1 1 1` before `LookAt` mirrors the image; kept so renders match pbrt.
    pub mirror_x: bool,
}

impl Camera {
    /// A camera at `eye` looking at `target`; `up` need not be orthogonal.
    pub fn look_at(
        name: &str,
        eye: Vec3,
        target: Vec3,
        up: Vec3,
        fov_deg: f32,
        w: u32,
        h: u32,
    ) -> Self {
        let forward = (target - eye).normalize_or(Vec3::NEG_Z);
        let right = forward.cross(up).normalize_or(Vec3::X);
        let up = right.cross(forward).normalize_or(Vec3::Y);
        Self {
            name: name.into(),
            world_eye: eye.to_array(),
            world_forward: forward.to_array(),
            world_up: up.to_array(),
            fov_deg,
            width: w,
            height: h,
            mirror_x: false,
        }
    }
}
