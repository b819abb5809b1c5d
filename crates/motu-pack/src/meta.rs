//! The `meta` section: JSON for everything that is not a per-record table.

use motu_scene::{Camera, Light, SceneStats};
use serde::{Deserialize, Serialize};

/// Identifies the section layout this build writes; readers reject other schemas.
pub const SCHEMA: &str = "motu-scene/2";

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct ElementMeta {
    /// The element's id in the imported scene (what records' `element` fields hold).
    pub id: u32,
    pub name: String,
    /// Instance edges in the element's subtree (its root-level edges plus every edge of the
    /// prototypes it reaches, each prototype once).
    pub instances: u64,
    pub flattened_instances: u64,
    pub unique_triangles: u64,
    pub instanced_triangles: u64,
    pub meshes: u64,
    /// Bytes of chunk data (mesh blobs) owned by the element's meshes.
    pub mesh_bytes: u64,
}

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PackageMeta {
    pub schema: String,
    /// The imported file, as given.
    pub source: String,
    /// `ml`, `sl` or a number.
    pub levels: String,
    pub max_instances_per_tlas: u32,
    pub lod_levels: u32,
    pub root_tlas: u32,
    pub cameras: Vec<Camera>,
    pub lights: Vec<Light>,
    pub material_names: Vec<String>,
    pub mesh_names: Vec<String>,
    pub elements: Vec<ElementMeta>,
    /// Statistics of the source graph (before compiling).
    pub scene: SceneStats,
    /// The compiler's report, kept verbatim.
    pub compile: serde_json::Value,
    /// Import warnings (capped) for `motu info`.
    pub warnings: Vec<String>,
}
