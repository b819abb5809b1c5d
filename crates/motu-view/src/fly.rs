//! The fly camera: position plus yaw/pitch about the scene camera's up vector.

use glam::{Quat, Vec3};
use motu_abi::camera::CameraPose;

#[derive(Clone, Copy, Debug)]
pub struct FlyCamera {
    pub pose: CameraPose,
    /// World units per second.
    pub speed: f32,
}

/// Movement intent of one frame: each axis in −1..=1 (right, up, forward).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Motion {
    pub right: f32,
    pub up: f32,
    pub forward: f32,
}

impl FlyCamera {
    pub fn new(pose: CameraPose, speed: f32) -> Self {
        FlyCamera { pose, speed }
    }

    fn basis(&self) -> (Vec3, Vec3, Vec3) {
        let up = self.pose.world_up.normalize_or(Vec3::Y);
        let fwd = self.pose.world_forward.normalize_or(Vec3::NEG_Z);
        // Image right as CameraParams sees it (pbrt: cross(up, forward), flipped if mirrored).
        let mut right = up.cross(fwd).normalize_or(Vec3::X);
        if self.pose.mirror_x {
            right = -right;
        }
        (right, up, fwd)
    }

    /// Moves by `motion` for `dt_s` seconds.
    pub fn step(&mut self, motion: Motion, dt_s: f32) {
        let (right, up, fwd) = self.basis();
        let d = right * motion.right + up * motion.up + fwd * motion.forward;
        if d.length_squared() > 0.0 {
            self.pose.world_eye += d.normalize() * self.speed * dt_s;
        }
    }

    /// Turns by a mouse delta in pixels (`rad_per_px` sensitivity): yaw about up, pitch about
    /// right, pitch kept within ±89° of the horizon.
    pub fn look(&mut self, dx_px: f32, dy_px: f32, rad_per_px: f32) {
        let (_, up, fwd) = self.basis();
        // Positive yaw about up turns forward towards image right (pbrt's left-handed camera),
        // towards image left when mirrored.
        let sign = if self.pose.mirror_x { -1.0 } else { 1.0 };
        let f = Quat::from_axis_angle(up, sign * dx_px * rad_per_px) * fwd;
        let limit = 89f32.to_radians();
        let current = f.dot(up).clamp(-1.0, 1.0).asin();
        let target = (current - dy_px * rad_per_px).clamp(-limit, limit);
        let horizontal = (f - up * f.dot(up)).normalize_or(f);
        self.pose.world_forward = (horizontal * target.cos() + up * target.sin()).normalize_or(fwd);
    }
}

#[cfg(test)]
mod tests;
