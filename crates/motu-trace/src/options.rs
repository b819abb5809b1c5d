//! What a CPU render draws and how: the view and the render options (shared by the shading and
//! the renderer, so it sits below both).

use motu_abi::lod::LodParams;
use motu_abi::shade::Shading;

/// What the PNG shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum View {
    /// Materials and image textures lit by the scene's lights (or a key light) with shadow
    /// rays, plus a sky term with ambient occlusion (`shade.rs`).
    #[default]
    Shaded,
    /// A hashed colour per (mesh, primitive).
    Ids,
    /// A colour per LOD level.
    Lod,
    /// Traces per pixel, blue (0) to red (the frame's maximum, reported in stats).
    Heatmap,
    /// The primary hit's textured base colour, sRGB-encoded (misses show the sky): the
    /// denoiser's material guide.
    Albedo,
}

impl View {
    /// The view's name (`--view`, `view` in `--stats`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Shaded => "shaded",
            Self::Ids => "ids",
            Self::Lod => "lod",
            Self::Heatmap => "heatmap",
            Self::Albedo => "albedo",
        }
    }
}

impl std::str::FromStr for View {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "shaded" => Ok(Self::Shaded),
            "ids" => Ok(Self::Ids),
            "lod" => Ok(Self::Lod),
            "heatmap" => Ok(Self::Heatmap),
            "albedo" => Ok(Self::Albedo),
            _ => Err(format!(
                "unknown view {s:?} (expected shaded, ids, lod, heatmap or albedo)"
            )),
        }
    }
}

#[derive(Clone, Copy, Debug)]
pub struct RenderOptions {
    pub view: View,
    /// World direction towards the sun (normalised here).
    pub sun_dir_world: [f32; 3],
    pub sun_intensity: f32,
    pub ambient: f32,
    /// Trace shadow rays in the shaded view.
    pub shadows: bool,
    /// LOD rule for primary rays (and shadow rays, with `RAY_SHADOW` bias).
    pub lod: LodParams,
    /// Force shadow rays to the primary hit's LOD (prevents LOD self-shadowing).
    pub shadow_lod_from_primary: bool,
    /// Build every reachable acceleration structure in parallel before tracing.
    pub prepare: bool,
    /// TLAS walks one ray may make before it is cut short (counted in `truncated_rays`).
    pub max_traces_per_ray: u32,
    /// Scene lights, sky, ambient occlusion, samples per pixel and exposure (shaded view).
    pub shading: Shading,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            view: View::Shaded,
            sun_dir_world: [0.4, 0.8, 0.45],
            sun_intensity: 0.8,
            ambient: 0.25,
            shadows: true,
            lod: LodParams::default(),
            shadow_lod_from_primary: true,
            prepare: true,
            max_traces_per_ray: motu_abi::DEFAULT_MAX_TRACES_PER_RAY,
            shading: Shading::default(),
        }
    }
}
