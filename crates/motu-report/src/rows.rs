//! The rows a report is made of: one per element, one per whole-scene variant. Below both the
//! budget planner (which reads them) and the report assembly (which fills them).

use serde::Serialize;

use crate::cost::Cost;

/// One row of the per-element table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ElementReport {
    pub name: String,
    /// The element id (`None` for the `shared` row).
    pub id: Option<u32>,
    /// `element`, `shared` (nodes used by several elements, plus global tables) or `untagged`
    /// (root instances without an element; always needed).
    pub kind: String,
    /// Instances of the element in the root TLAS.
    pub root_instances: u64,
    /// Triangle-BLAS placements after full flattening.
    pub flattened_instances: u64,
    /// Triangles after full flattening (visible geometry; LOD selectors at their finest level).
    pub instanced_triangles: u64,
    /// Triangles in the BLASes the element owns.
    pub unique_triangles: u64,
    pub meshes: u64,
    /// The element's costs as compiled (owned nodes + its share of the root TLAS). The shared
    /// row holds what several elements use.
    pub ml: Cost,
    /// Its flattened instances as one TLAS (split at `maxInstanceCount`), AS + instance buffer.
    pub sl_tlas_bytes: u64,
    /// Rendering this element alone (`--subset NAME`): owned + the shared nodes it uses + its
    /// own root TLAS + global tables. Not set on the shared row.
    pub alone: Option<Cost>,
}

/// A whole-scene variant: as compiled, `--levels 2`, `sl`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct VariantReport {
    /// `as_compiled`, `levels_2` or `sl`.
    pub name: String,
    /// The `--levels` value this corresponds to.
    pub levels: String,
    /// Instances in the top-level TLAS (before splitting).
    pub top_instances: u64,
    /// TLASes the top level needs at `maxInstanceCount` (1 = no split).
    pub top_tlas_pieces: u64,
    pub exceeds_max_instance_count: bool,
    pub cost: Cost,
}
