//! The frame parameters every trace shader reads (`common.glsl` `FrameParams`): built from a
//! camera and the render options, written with the environment map's tables behind them.

use bytemuck::{Pod, Zeroable};
use motu_abi::camera::CameraParams;
use motu_abi::lod::LodParams;
use motu_abi::shade::{Shading, MAX_LIGHTS};
use motu_abi::LightRecord;
use motu_vk::HeapBuffer;

use super::{RenderOptions, View};
use crate::error::{GpuError, Result};

/// `FrameParams` of `common.glsl` (std430, 560 bytes).
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
#[repr(C)]
pub(crate) struct FrameParams {
    camera: CameraParams,
    lod: LodParams,
    sun_dir_intensity: [f32; 4],
    view: u32,
    shadows: u32,
    shadow_lod_from_primary: u32,
    ambient: f32,
    root_tlas: u32,
    light_count: u32,
    /// Address of the scene's shading tables (`shade.glsl`'s `ShadingRef`), 0 for none.
    shading: u64,
    sky: [f32; 4],
    ao_samples: u32,
    spp: u32,
    ao_distance: f32,
    exposure_scale: f32,
    lights: [LightRecord; MAX_LIGHTS],
    /// 1: an environment map's tables ([`motu_abi::env::Environment::gpu_words`]) follow the
    /// parameters, [`ENV_OFFSET_BYTES`] into their buffer (`shade.glsl` `env_base`).
    environment: u32,
    /// 1: shaded pixels are written as linear RGB9E5 and tone-mapped on the host
    /// ([`frame_outputs`], `motu_abi::shade::resolve_auto_exposure`).
    auto_exposure: u32,
    /// Diffuse bounces after each primary hit (`shade.glsl`).
    bounces: u32,
    /// The frame's first sample in the pixel's sequence (`Shading::first_sample`).
    first_sample: u32,
}

/// Where an environment map's tables start in the frame-parameter buffer (`shade.glsl`
/// `ENV_OFFSET_BYTES`): they are written with the parameters, so every renderer's frame
/// carries them without a table of its own.
pub(crate) const ENV_OFFSET_BYTES: u64 = 1024;

/// Bytes of the frame-parameter buffer for a frame shaded with `shading`.
pub(crate) fn params_bytes(shading: &Shading) -> u64 {
    let base = std::mem::size_of::<FrameParams>() as u64;
    match shading.environment {
        Some(e) => ENV_OFFSET_BYTES + 4 * e.gpu_words().len() as u64,
        None => base,
    }
}

/// Writes the frame's parameters (and its environment map's tables) into `buf`.
pub(crate) fn write_params(
    buf: &HeapBuffer,
    params: &FrameParams,
    shading: &Shading,
) -> Result<()> {
    buf.write(0, std::slice::from_ref(params))?;
    if let Some(e) = shading.environment {
        let words = e.gpu_words();
        if ENV_OFFSET_BYTES + 4 * words.len() as u64 > buf.size_bytes() {
            return Err(GpuError::InvalidRequest(
                "the frame's parameter buffer has no room for the environment map".into(),
            ));
        }
        buf.write(ENV_OFFSET_BYTES, &words)?;
    }
    Ok(())
}

impl FrameParams {
    /// What instance-level LOD's levels depend on: the camera and the LOD parameters.
    pub(crate) fn camera_and_lod(&self) -> (&CameraParams, &LodParams) {
        (&self.camera, &self.lod)
    }
}

/// The frame parameters of `common.glsl` for `camera` and `opts` over the scene whose root is
/// `root_tlas` and whose shading tables (textures, normals, uvs) start at `shading_address`
/// (0: none; every renderer over a scene with tables must pass them, or its frames lose
/// textures, shading normals and alpha cut-outs).
pub(crate) fn frame_params(
    camera: &CameraParams,
    opts: &RenderOptions,
    root_tlas: u32,
    shading_address: u64,
) -> FrameParams {
    let sun = {
        let s = opts.sun_dir_world;
        let l = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt().max(1e-20);
        [s[0] / l, s[1] / l, s[2] / l, opts.sun_intensity]
    };
    let sh = &opts.shading;
    let (lights, light_count) = sh.frame_lights(opts.sun_dir_world, opts.sun_intensity);
    let sky = sh.sky_radiance(opts.ambient);
    FrameParams {
        camera: *camera,
        lod: opts.lod,
        sun_dir_intensity: sun,
        view: opts.view.code(),
        shadows: u32::from(opts.shadows),
        shadow_lod_from_primary: u32::from(opts.shadow_lod_from_primary),
        ambient: opts.ambient,
        root_tlas,
        light_count,
        shading: shading_address,
        sky: [
            sky[0],
            sky[1],
            sky[2],
            if sh.sky.is_some() { 1.0 } else { 0.0 },
        ],
        ao_samples: sh.ao_samples,
        spp: sh.spp.max(1),
        // GLSL has no infinity literal here: T_INFINITY (3e38) stands for it.
        ao_distance: sh.ao_distance.min(3.0e38),
        exposure_scale: sh.exposure_scale(),
        lights,
        environment: u32::from(sh.environment.is_some()),
        auto_exposure: u32::from(sh.auto_exposure && opts.view == View::Shaded),
        bounces: sh.bounces,
        first_sample: sh.first_sample,
    }
}
