//! The `meta` section: JSON for everything that is not a per-record table.

use motu_scene::{Camera, Light, SceneStats};
use serde::{Deserialize, Serialize};

/// Identifies the section layout this build writes; readers reject other schemas.
/// `motu-scene/2` added partitioned meshes (clusters with a primitive map, `FLAG_PRIMITIVE_MAP`);
/// `motu-scene/3` added shading data (texture coordinates in mesh blobs, `MeshRecord::uvs_offset`
/// which grew the mesh record to 112 bytes, material parameters, lights, textures and texels).
/// Older packages have the 96-byte mesh record, so they are refused with a re-import hint.
pub const SCHEMA: &str = "motu-scene/3";
/// Schemas this build reads.
pub const SCHEMA_READABLE: &[&str] = &[SCHEMA];

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
    /// The source's curve shapes and what became of them (absent in packages written before
    /// it was added: zeros).
    #[serde(default)]
    pub curves: CurveMeta,
    /// Per material (by id): the Ptex file its base colour comes from, if any (absent in
    /// packages written before it was added).
    #[serde(default)]
    pub material_ptex: Vec<Option<String>>,
    /// The split `motu render --stream` makes of TLASes over `cap_instances` instances, made
    /// once at import and stored (`SECTION_SPLIT_*`) so readers need not redo it (`motu
    /// report`). Absent in packages written before it was added (readers split themselves);
    /// present with `tlases_split == 0` (and no sections) when no TLAS is over the cap.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub stream_split: Option<StreamSplitMeta>,
}

/// See [`PackageMeta::stream_split`].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct StreamSplitMeta {
    pub cap_instances: u32,
    pub tlases_split: u64,
    pub pieces: u64,
}

/// Curve shapes at import: all of them, those tessellated into ribbons, and the ribbons'
/// triangles (the rest were counted and skipped, `--curves skip`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CurveMeta {
    pub curves: u64,
    pub ribbons: u64,
    pub ribbon_triangles: u64,
}

/// Why the `meta` section does not parse (or, when writing, would not).
#[derive(Debug, thiserror::Error)]
pub enum MetaError {
    #[error("meta section is not valid: {0}")]
    Json(#[source] serde_json::Error),
    #[error(
        "schema '{found}' is not supported (this build reads '{SCHEMA}'): re-import the scene with this build"
    )]
    Schema { found: String },
    #[error("meta does not serialise: {0}")]
    Serialise(#[source] serde_json::Error),
    #[error("meta would not be readable ({0}); a camera or light value is probably not finite")]
    Unreadable(#[source] Box<MetaError>),
}

/// Parses the `meta` section as every reader does: valid JSON of this schema.
pub(crate) fn parse_meta(bytes: &[u8]) -> Result<PackageMeta, MetaError> {
    // The schema first: an older package's meta lacks newer fields, and "missing field" would
    // hide the real reason.
    let value: serde_json::Value = serde_json::from_slice(bytes).map_err(MetaError::Json)?;
    let schema = value.get("schema").and_then(|s| s.as_str()).unwrap_or("");
    if !SCHEMA_READABLE.contains(&schema) {
        return Err(MetaError::Schema {
            found: schema.to_string(),
        });
    }
    serde_json::from_value(value).map_err(MetaError::Json)
}

/// Serialises `meta` and proves the reader accepts it: JSON has no NaN or infinity (serde
/// writes them as `null`, which the reader then refuses), so a writer that skipped this check
/// could produce a package nothing can open.
pub(crate) fn serialise_meta(meta: &PackageMeta) -> Result<Vec<u8>, MetaError> {
    let json = serde_json::to_vec(meta).map_err(MetaError::Serialise)?;
    parse_meta(&json).map_err(|e| MetaError::Unreadable(Box::new(e)))?;
    Ok(json)
}

#[cfg(test)]
mod tests;
