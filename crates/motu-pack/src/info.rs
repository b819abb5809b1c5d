//! `motu info --json`: a package's structure and sizes as one typed object (shared/CLI.md
//! names the keys it must have; keys are added, never renamed or removed).

use crate::{ElementMeta, ScenePackage};
use motu_abi::HierarchyView;
use serde::Serialize;

/// A package's structure and sizes: the meta's counts, the compiled tables', the file's.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PackageInfo {
    /// `major.minor` of the file format.
    pub format_version: String,
    pub schema: String,
    /// The imported file, as given.
    pub source: String,
    /// TLAS levels as compiled, and `--levels` as given (`ml`, `sl`, a number).
    pub levels: u64,
    pub levels_setting: String,
    /// Instance edges in the source graph, and leaf instances after full flattening.
    pub instances: u64,
    pub flattened_instances: u64,
    pub unique_triangles: u64,
    pub instanced_triangles: u64,
    pub meshes: u64,
    pub compiled_meshes: usize,
    pub prototypes: u64,
    /// TLASes plus BLASes.
    pub nodes: usize,
    pub tlas_count: usize,
    pub blas_count: usize,
    pub tlas_instances: usize,
    pub programmable_instances: usize,
    pub lod_selectors: usize,
    /// The most instances of one TLAS, and the cap they were compiled under.
    pub max_instances_per_tlas: u32,
    pub max_instances_cap: u32,
    pub split_tlases: u64,
    pub max_blas_triangles: u64,
    pub max_triangles_per_blas: u32,
    pub partitioned_meshes: u64,
    pub partition_clusters: u64,
    pub baked_prototypes: u64,
    pub inlined_prototypes: u64,
    pub chunks: usize,
    pub chunk_raw_bytes: u64,
    pub chunk_stored_bytes: u64,
    pub file_bytes: u64,
    /// Camera and element names.
    pub cameras: Vec<String>,
    pub elements: Vec<String>,
    pub lights: usize,
    pub materials: usize,
    pub warnings: usize,
    pub curves: u64,
    pub curve_ribbons: u64,
    pub curve_ribbon_triangles: u64,
    /// Materials whose base colour is a Ptex file, the Ptex textures read (with a face), their
    /// faces and texel bytes.
    pub ptex_materials: usize,
    pub ptex_textures: usize,
    pub ptex_faces: u64,
    pub ptex_bytes: u64,
    /// The cap `motu import --stream-split-instances` stored its stream split, proxy boxes and
    /// clusters for (`motu render --stream` splits at it unless told otherwise; 0: no split),
    /// the TLASes over it and the pieces they were split into. `null` and 0: a package written
    /// before the cap was recorded (streamed renders split at 1,000,000).
    pub stream_split_instances: Option<u32>,
    pub stream_split_tlases: u64,
    pub stream_split_pieces: u64,
}

impl PackageInfo {
    /// `pkg`'s info; `view` is its hierarchy (`pkg.view()`).
    pub fn new(pkg: &ScenePackage, view: &HierarchyView<'_>) -> Self {
        let meta = pkg.meta();
        let p = pkg.package();
        let v = p.format_version();
        // The compiler's report is kept verbatim (JSON) in the meta.
        let num = |k: &str| meta.compile.get(k).and_then(|v| v.as_u64()).unwrap_or(0);
        // Ptex textures read with at least one face (a file that could not be read has none).
        let ptex = || {
            view.textures
                .iter()
                .filter(|t| motu_abi::ptex::is_ptex(t) && t.height > 0)
        };
        Self {
            format_version: format!("{}.{}", v.major, v.minor),
            schema: meta.schema.clone(),
            source: meta.source.clone(),
            levels: num("tlas_levels"),
            levels_setting: meta.levels.clone(),
            instances: meta.scene.instances,
            flattened_instances: meta.scene.flattened_instances,
            unique_triangles: meta.scene.unique_triangles,
            instanced_triangles: meta.scene.instanced_triangles,
            meshes: meta.scene.meshes,
            compiled_meshes: view.meshes.len(),
            prototypes: meta.scene.prototypes,
            nodes: view.tlases.len() + view.blases.len(),
            tlas_count: view.tlases.len(),
            blas_count: view.blases.len(),
            tlas_instances: view.instances.len(),
            programmable_instances: view.pis.len(),
            lod_selectors: view.lod_selectors.len(),
            max_instances_per_tlas: view
                .tlases
                .iter()
                .map(|t| t.instance_count)
                .max()
                .unwrap_or(0),
            max_instances_cap: meta.max_instances_per_tlas,
            split_tlases: num("split_tlases"),
            max_blas_triangles: num("max_blas_triangles"),
            max_triangles_per_blas: view
                .blases
                .iter()
                .filter(|b| b.kind == motu_abi::BLAS_TRIANGLES)
                .map(|b| b.primitive_count)
                .max()
                .unwrap_or(0),
            partitioned_meshes: num("partitioned_meshes"),
            partition_clusters: num("partition_clusters"),
            baked_prototypes: num("baked_prototypes"),
            inlined_prototypes: num("inlined_prototypes"),
            chunks: p.chunks().len(),
            chunk_raw_bytes: p.chunks().iter().map(|c| c.raw_len).sum(),
            chunk_stored_bytes: p.chunks().iter().map(|c| c.stored_len).sum(),
            file_bytes: p.file_bytes(),
            cameras: meta.cameras.iter().map(|c| c.name.clone()).collect(),
            elements: meta.elements.iter().map(|e| e.name.clone()).collect(),
            lights: meta.lights.len(),
            materials: meta.material_names.len(),
            warnings: meta.warnings.len(),
            curves: meta.curves.curves,
            curve_ribbons: meta.curves.ribbons,
            curve_ribbon_triangles: meta.curves.ribbon_triangles,
            ptex_materials: meta.material_ptex.iter().filter(|p| p.is_some()).count(),
            ptex_textures: ptex().count(),
            ptex_faces: ptex().map(|t| u64::from(t.height)).sum(),
            ptex_bytes: ptex().map(|t| t.texel_count() * 4).sum(),
            stream_split_instances: meta.stream_split.as_ref().map(|m| m.cap_instances),
            stream_split_tlases: meta.stream_split.as_ref().map_or(0, |m| m.tlases_split),
            stream_split_pieces: meta.stream_split.as_ref().map_or(0, |m| m.pieces),
        }
    }
}

/// `motu info --elements --json`: the scene's elements with their counts (the meta's records).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ElementsInfo<'a> {
    pub elements: &'a [ElementMeta],
}
