//! What things look like: materials and lights (base colours only; motu shades simply).

use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Material {
    pub name: String,
    /// Linear RGB reflectance in [0, 1].
    pub base_color: [f32; 3],
    /// 1 = opaque. Alpha-textured materials record their texture name as well.
    pub opacity: f32,
    pub alpha_texture: Option<String>,
}

impl Default for Material {
    fn default() -> Self {
        Self {
            name: "default".into(),
            base_color: [0.5; 3],
            opacity: 1.0,
            alpha_texture: None,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LightKind {
    Distant,
    Point,
    Spot,
    Infinite,
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
    /// World-space position (point, spot); zero if none.
    pub world_position: [f32; 3],
}
