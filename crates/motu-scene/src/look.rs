//! What things look like: materials (a base colour, roughness, metalness, emission, image
//! textures by index), image textures (files read when the package is written) and lights.

use serde::{Deserialize, Serialize};
use std::path::PathBuf;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub name: String,
    /// Linear RGB reflectance in [0, 1] (multiplied by the base-colour texture, if any).
    pub base_color: [f32; 3],
    /// Constant coverage; 1 = opaque.
    pub opacity: f32,
    /// Coverage texture (index into [`crate::Scene::textures`]): the material is alpha-tested.
    pub alpha_texture: Option<u32>,
    /// Base-colour texture (index into [`crate::Scene::textures`]).
    pub base_color_texture: Option<u32>,
    /// Perceptual roughness in [0, 1].
    pub roughness: f32,
    /// 0 dielectric, 1 metal.
    pub metallic: f32,
    /// Emitted radiance, linear RGB (area lights).
    pub emission: [f32; 3],
    /// The Ptex file the base colour comes from (also `base_color_texture`, a Ptex texture,
    /// whose sample replaces `base_color`; kept here for `meta.material_ptex`).
    #[serde(default)]
    pub ptex: Option<std::path::PathBuf>,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: "default".into(),
            base_color: [0.5; 3],
            opacity: 1.0,
            alpha_texture: None,
            base_color_texture: None,
            roughness: 0.5,
            metallic: 0.0,
            emission: [0.0; 3],
            ptex: None,
        }
    }
}

/// An image texture file a material uses; read (and reduced to a capped mip chain) when the
/// package is written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Texture {
    /// The file, resolved against the scene file that named it.
    pub path: PathBuf,
    /// Used as coverage (alpha) rather than colour.
    pub is_alpha: bool,
    /// A Ptex file (`.ptx`): sampled by face id and face uv, not by texture coordinates.
    #[serde(default)]
    pub ptex: bool,
}

/// How a mesh's triangles map to the faces of its material's Ptex texture, where they are not
/// one face each (triangle `t` is face `t` without an entry).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum PtexFaces {
    /// Every face a quad split in two: triangle `t` is face `t / 2`, odd `t` its second half
    /// (vertices 0, 2, 3 of the quad).
    Quads,
    /// Per triangle: the face id, with bit 31 set on a quad's second half.
    Table(Vec<u32>),
}

impl PtexFaces {
    /// The compact form of per-triangle face ids (bit 31: a quad's second half): `None` when
    /// triangle `t` is face `t`, [`PtexFaces::Quads`] for the quad pattern.
    pub fn from_ids(ids: &[u32]) -> Option<PtexFaces> {
        const HALF: u32 = 1 << 31;
        let t = |i: usize| i as u32;
        if ids.iter().enumerate().all(|(i, &f)| f == t(i)) {
            return None;
        }
        let quads = ids.len() % 2 == 0
            && ids
                .iter()
                .enumerate()
                .all(|(i, &f)| f == t(i / 2) | if i % 2 == 1 { HALF } else { 0 });
        Some(if quads {
            PtexFaces::Quads
        } else {
            PtexFaces::Table(ids.to_vec())
        })
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightKind {
    Distant,
    Point,
    Spot,
    Infinite,
    /// An emitting shape, lit as a point light at its centre with its power.
    Area,
    Other,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Light {
    pub kind: LightKind,
    /// Linear RGB colour.
    pub color: [f32; 3],
    pub intensity: f32,
    /// World-space direction the light travels (distant, spot), normalised; zero if none.
    pub world_direction: [f32; 3],
    /// World-space position (point, spot, area); zero if none.
    pub world_position: [f32; 3],
    /// Spot: full cone angle and falloff start, in degrees (pbrt `coneangle`, `conedelta`).
    #[serde(default)]
    pub cone_deg: Option<[f32; 2]>,
    /// Area: the emitter's bounding radius about `world_position`.
    #[serde(default)]
    pub radius: f32,
    /// Infinite: its image, when it has one (then `color` × `intensity` is the image's mean).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map: Option<EnvironmentMap>,
}

/// An `infinite` light's image as the package keeps it: latitude-longitude (row 0 at the light
/// space's +z pole, `u = φ / 2π`), linear radiance with the light's `L` × `scale` applied,
/// halved at import until it is at most `motu_abi`'s `ENV_MAX_WIDTH` wide.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvironmentMap {
    pub width: u32,
    pub height: u32,
    /// Row-major texels.
    pub radiance: Vec<[f32; 3]>,
    /// Rows of the light's rotation (the CTM at its `LightSource`).
    pub world_from_light: [[f32; 3]; 3],
}
