//! The compiler's report as JSON: the package meta keeps it (`compile`, FORMAT.md; `motu info`
//! reads its keys) and `motu import --json` prints its phases (`compile_phases`). These types
//! own those keys; `motu_compile`'s report is not `Serialize`, so renaming one of its fields
//! cannot change a stored or printed key.

use serde::Serialize;

/// `motu_compile::CompileReport` as stored in the package meta.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CompileReport {
    pub levels: String,
    pub tlas_count: u64,
    pub blas_count: u64,
    pub triangle_blas_count: u64,
    pub aabb_blas_count: u64,
    pub instance_count: u64,
    pub geometry_count: u64,
    pub pi_count: u64,
    pub lod_selector_count: u64,
    pub mesh_count: u64,
    pub material_count: u64,
    pub max_level: u32,
    pub tlas_levels: u32,
    pub max_instances_per_tlas: u64,
    pub max_primitives_per_blas: u64,
    pub split_tlases: u64,
    pub split_pieces: u64,
    pub split_aabb_blases: u64,
    pub max_blas_triangles: u64,
    pub max_triangles_per_blas: u64,
    pub partitioned_meshes: u64,
    pub partition_clusters: u64,
    pub dropped_degenerate_instances: u64,
    pub collapsed_prototypes: u64,
    pub baked_prototypes: u64,
    pub inlined_prototypes: u64,
    pub lod_source_meshes: u64,
    pub lod_meshes_made: u64,
    pub flattened_instances: u64,
    pub time_ms: f64,
    pub phases: CompilePhases,
}

/// `motu_compile::CompilePhases` as JSON, in milliseconds.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CompilePhases {
    pub analyze_ms: f64,
    pub emit_ms: f64,
    pub load_ms: f64,
    pub partition_ms: f64,
    pub sink_ms: f64,
    pub finalize_ms: f64,
}

impl From<&motu_compile::CompileReport> for CompileReport {
    fn from(r: &motu_compile::CompileReport) -> Self {
        // Every field named: one added to the compiler's report fails here until it has a key.
        let motu_compile::CompileReport {
            levels,
            tlas_count,
            blas_count,
            triangle_blas_count,
            aabb_blas_count,
            instance_count,
            geometry_count,
            pi_count,
            lod_selector_count,
            mesh_count,
            material_count,
            max_level,
            tlas_levels,
            max_instances_per_tlas,
            max_primitives_per_blas,
            split_tlases,
            split_pieces,
            split_aabb_blases,
            max_blas_triangles,
            max_triangles_per_blas,
            partitioned_meshes,
            partition_clusters,
            dropped_degenerate_instances,
            collapsed_prototypes,
            baked_prototypes,
            inlined_prototypes,
            lod_source_meshes,
            lod_meshes_made,
            flattened_instances,
            time_ms,
            phases,
        } = r;
        Self {
            levels: levels.clone(),
            tlas_count: *tlas_count,
            blas_count: *blas_count,
            triangle_blas_count: *triangle_blas_count,
            aabb_blas_count: *aabb_blas_count,
            instance_count: *instance_count,
            geometry_count: *geometry_count,
            pi_count: *pi_count,
            lod_selector_count: *lod_selector_count,
            mesh_count: *mesh_count,
            material_count: *material_count,
            max_level: *max_level,
            tlas_levels: *tlas_levels,
            max_instances_per_tlas: *max_instances_per_tlas,
            max_primitives_per_blas: *max_primitives_per_blas,
            split_tlases: *split_tlases,
            split_pieces: *split_pieces,
            split_aabb_blases: *split_aabb_blases,
            max_blas_triangles: *max_blas_triangles,
            max_triangles_per_blas: *max_triangles_per_blas,
            partitioned_meshes: *partitioned_meshes,
            partition_clusters: *partition_clusters,
            dropped_degenerate_instances: *dropped_degenerate_instances,
            collapsed_prototypes: *collapsed_prototypes,
            baked_prototypes: *baked_prototypes,
            inlined_prototypes: *inlined_prototypes,
            lod_source_meshes: *lod_source_meshes,
            lod_meshes_made: *lod_meshes_made,
            flattened_instances: *flattened_instances,
            time_ms: *time_ms,
            phases: phases.into(),
        }
    }
}

impl From<&motu_compile::CompilePhases> for CompilePhases {
    fn from(r: &motu_compile::CompilePhases) -> Self {
        // Every field named: one added to the compiler's report fails here until it has a key.
        let motu_compile::CompilePhases {
            analyze_ms,
            emit_ms,
            load_ms,
            partition_ms,
            sink_ms,
            finalize_ms,
        } = r;
        Self {
            analyze_ms: *analyze_ms,
            emit_ms: *emit_ms,
            load_ms: *load_ms,
            partition_ms: *partition_ms,
            sink_ms: *sink_ms,
            finalize_ms: *finalize_ms,
        }
    }
}

#[cfg(test)]
mod tests;
