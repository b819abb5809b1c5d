//! The LOD rule shared by every backend (mirrored in `shaders/lod.glsl`).
//!
//! A selector's level is chosen by the projected radius of its bounding sphere: level 0 while
//! the sphere covers at least `r_max_px` pixels of radius, one level coarser per halving
//! (each level has ~4× fewer triangles, i.e. half the linear resolution). Shadow rays may be
//! biased coarser, and may be forced to a level (the primary hit's), which prevents LOD
//! self-shadowing. Stochastic LOD dithers between the two nearest levels with a caller-given
//! uniform number.

use bytemuck::{Pod, Zeroable};

pub const RAY_PRIMARY: u32 = 0;
pub const RAY_SHADOW: u32 = 1;
/// `forced_lod` value meaning "not forced".
pub const LOD_NOT_FORCED: i32 = -1;

#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct LodParams {
    /// Projected radius (pixels) at and above which level 0 is used.
    pub r_max_px: f32,
    /// Levels added for shadow rays.
    pub shadow_bias: f32,
    /// 1 = dither between neighbouring levels.
    pub stochastic: u32,
    /// A level forced on every selector (`LOD_NOT_FORCED` = choose by size).
    pub forced_lod: i32,
}

impl Default for LodParams {
    fn default() -> Self {
        Self {
            r_max_px: 256.0,
            shadow_bias: 1.0,
            stochastic: 0,
            forced_lod: LOD_NOT_FORCED,
        }
    }
}

/// The level (0 = finest) for a selector whose bounding sphere has `radius_local` in its own
/// space, met at world distance `t_near` by a ray whose unit world direction has length
/// `dir_local_len` in the selector's space (so `radius_local / dir_local_len` is the radius in
/// world units). `u` in [0, 1) drives stochastic dithering.
#[allow(clippy::too_many_arguments)]
pub fn select_lod(
    p: &LodParams,
    pixels_per_unit_at_1: f32,
    radius_local: f32,
    dir_local_len: f32,
    t_near: f32,
    level_count: u32,
    ray_kind: u32,
    u: f32,
) -> u32 {
    let last = level_count.saturating_sub(1);
    if p.forced_lod >= 0 {
        return (p.forced_lod as u32).min(last);
    }
    let radius_world = radius_local / dir_local_len.max(1e-20);
    let projected_px = radius_world * pixels_per_unit_at_1 / t_near.max(1e-6);
    let mut level = (p.r_max_px / projected_px.max(1e-20)).log2().max(0.0);
    if ray_kind == RAY_SHADOW {
        level += p.shadow_bias;
    }
    let mut whole = level.floor();
    if p.stochastic != 0 && u < level - whole {
        whole += 1.0;
    }
    (whole.min(last as f32)) as u32
}

#[cfg(test)]
mod tests;
