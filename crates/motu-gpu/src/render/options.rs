//! What a render is asked for: the traversal backend, the view and the options of a frame.

use motu_abi::lod::LodParams;
use motu_abi::shade::Shading;
use motu_vk::Context;

/// Which traversal backend traces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// Ray-tracing pipeline: raygen owns the stack (every RT device; the only one on the H200).
    Pipeline,
    /// Compute shader with ray queries (the thesis's form).
    Query,
}

impl Backend {
    /// `query` where the device has ray queries, else `pipeline`.
    pub fn best(ctx: &Context) -> Option<Backend> {
        if ctx.caps().ray_query {
            Some(Backend::Query)
        } else if ctx.caps().ray_pipeline {
            Some(Backend::Pipeline)
        } else {
            None
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Backend::Pipeline => "pipeline",
            Backend::Query => "query",
        }
    }
}

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "pipeline" => Ok(Backend::Pipeline),
            "query" => Ok(Backend::Query),
            _ => Err(format!(
                "unknown GPU backend {s:?} (expected pipeline or query)"
            )),
        }
    }
}

/// What the image shows (values match `VIEW_*` in `common.glsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum View {
    #[default]
    Shaded,
    Ids,
    Lod,
    /// Traces per pixel, blue (0) to red (the frame's maximum, `heatmap_max` in stats).
    Heatmap,
    /// The primary hit's textured base colour (sRGB-encoded; misses show the sky): the
    /// denoiser's material guide.
    Albedo,
}

impl View {
    /// The view's name (`--view`, `view` in `--stats`).
    pub fn name(self) -> &'static str {
        match self {
            View::Shaded => "shaded",
            View::Ids => "ids",
            View::Lod => "lod",
            View::Heatmap => "heatmap",
            View::Albedo => "albedo",
        }
    }

    pub(crate) fn code(self) -> u32 {
        match self {
            View::Shaded => 0,
            View::Ids => 1,
            View::Lod => 2,
            View::Heatmap => 3,
            View::Albedo => 4,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    pub backend: Backend,
    pub view: View,
    pub lod: LodParams,
    /// Traversal stack entries (a specialisation constant), 1..=[`MAX_STACK_SIZE`].
    pub stack_size: u32,
    /// TLAS walks a ray may make before it is cut short (a specialisation constant).
    pub max_traces_per_ray: u32,
    /// Frames traced (for timing); the outputs are the last frame's.
    pub frames: u32,
    /// World direction towards the sun (normalised here).
    pub sun_dir_world: [f32; 3],
    pub sun_intensity: f32,
    pub ambient: f32,
    pub shadows: bool,
    /// Shadow rays use the primary hit's LOD (prevents LOD self-shadowing).
    pub shadow_lod_from_primary: bool,
    /// Scene lights, sky, ambient occlusion, samples per pixel and exposure (shaded view).
    pub shading: Shading,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            backend: Backend::Pipeline,
            view: View::Shaded,
            lod: LodParams::default(),
            stack_size: 16,
            max_traces_per_ray: motu_abi::DEFAULT_MAX_TRACES_PER_RAY,
            frames: 1,
            sun_dir_world: [0.4, 0.8, 0.45],
            sun_intensity: 0.8,
            ambient: 0.25,
            shadows: true,
            shadow_lod_from_primary: true,
            shading: Shading::default(),
        }
    }
}
