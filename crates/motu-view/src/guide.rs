//! The denoiser's guide in the viewer: as `motu render --denoise`, a scene with textured
//! materials gets the frame's `albedo` view (the textured base colour at each primary hit,
//! rendered by the same source for the same camera) so the filter keeps texel edges; other
//! scenes use the materials' constants alone.

use motu_abi::camera::CameraParams;
use motu_gpu::{RenderOptions, RenderOutput, View};

use crate::FrameSource;

/// Filters `frame` (never its AOV) with the guide of `camera`'s frame; renders the albedo view
/// first when the source has textured materials.
pub(crate) fn denoise<S: FrameSource>(
    source: &mut S,
    frame: &mut RenderOutput,
    camera: &CameraParams,
    opts: &RenderOptions,
    elements_on: &[bool],
    lod_instance: bool,
) -> Result<(), String> {
    use motu_render::denoise::{
        add_texture_albedo, denoise_rgba8, guide_from_aov, pixel_footprint, DenoiseOptions,
    };
    let albedo = if source.textured() {
        let mut o = *opts;
        o.view = View::Albedo;
        o.shading.first_sample = 0;
        Some(source.render(camera, &o, elements_on, lod_instance)?.output)
    } else {
        None
    };
    let mut guide = guide_from_aov(&frame.aov, camera, |m| source.base_colour(m));
    if let Some(a) = &albedo {
        add_texture_albedo(&mut guide, &frame.aov, &a.rgba8, &a.aov);
    }
    denoise_rgba8(
        &mut frame.rgba8,
        frame.aov.width,
        frame.aov.height,
        &guide,
        pixel_footprint(camera),
        &DenoiseOptions::default(),
    );
    Ok(())
}
