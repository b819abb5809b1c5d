//! The scene compiler: turns a [`motu_scene::Scene`] (a DAG of prototypes) into the multi-level
//! traversal hierarchy of [`motu_abi`] (thesis ch. 4.2–4.5): TLASes at even levels, BLASes at
//! odd levels, programmable instances (PIs) where traversal continues in another TLAS.
//!
//! # The mapping
//! Every prototype `P` that is reached through a programmable instance (and the root) becomes
//! `TLAS(P)`. Its content is produced by a walk from `P` that **expands** some child edges into
//! the TLAS itself (composing transforms) and turns the others into PIs:
//! - `P`'s own meshes: one instance of the triangle BLAS `G(P)` (one geometry per mesh).
//!   `G(P)` is built once and shared by every TLAS that instances it.
//! - an edge to plain geometry `C` (meshes, no children): always expanded, i.e. an instance of
//!   `G(C)` placed directly in the TLAS: the **instance list** of thesis 4.4.4.
//! - an edge to a prototype with children: a PI, an AABB in an AABB BLAS of the TLAS (one per
//!   TLAS that needs PIs, instanced with identity) pointing at `TLAS(C)` with
//!   `child_from_parent = M⁻¹`. `TLAS(C)` is shared by all PIs that target it: the memory win
//!   of multi-level instancing. A prototype with meshes and children thus yields a triangle
//!   BLAS and an AABB BLAS (Vulkan forbids mixing: the "two BLASes").
//! - **identity collapse**: an edge with an identity transform to a prototype with exactly one
//!   incoming edge is expanded (it costs a PI level and saves no memory). This covers pbrt
//!   elements (each included once under the root) and applies at every level.
//! - [`Levels::N`] expands, at any level, the edges whose target's ML subtree would need more
//!   TLAS levels than remain (thesis "ML-RE": the top levels are inlined, the bottom kept);
//!   [`Levels::Sl`] expands everything into the root TLAS.
//!
//! All instance lists of one TLAS share its single acceleration structure, so the thesis's
//! merging of overlapping instance lists with the same parents (4.4.5) is implicit; the split
//! below then re-partitions them spatially.
//!
//! Subtrees without geometry are pruned, edges with non-invertible transforms are dropped
//! (counted in [`CompileReport::dropped_degenerate_instances`]). A composed transform that
//! underflows to singular where a PI needs its inverse is inlined instead (no inverse needed).
//!
//! # Elements
//! Every instance of the root TLAS carries the element it came from (the root edge's, or the
//! root mesh's: `G(root)` and the root's AABB BLASes are grouped per element), so `--subset`
//! can also filter at run time; instances below the root carry `NONE_U32`. A split root's pieces
//! mix elements (splitting per element made pieces that overlap wherever elements do), and
//! their instances keep their tags: `RootSubset` filters every tagged instance, pieces included.
//! [`CompileOptions::subset`] filters at compile time instead.
//!
//! # Memory and time
//! All passes are O(prototypes + edges + output) with per-prototype arrays, no per-edge
//! allocation or hashing. The instance table, the one large allocation, is reserved once from
//! an exact count made before emission (which also rejects tables over `u32` early); a TLAS
//! walk keeps one frame per graph level. LOD meshes go to the caller's sink as they are made.
//!
//! # Why no dummy nodes
//! The thesis assigns levels to *source* nodes and inserts identity dummies where a child has
//! the wrong parity. Here levels belong to *compiled* nodes, and the compiled graph is
//! bipartite by construction: a TLAS only instances BLASes and a BLAS only holds geometry or
//! PIs into TLASes (or LOD selectors whose levels are TLASes). With levels computed as
//! `level(child) = max over parents (level(parent) + 1)` from root level 0, every TLAS is even
//! and every BLAS odd by induction, whatever depth a shared `G(P)` is instanced at.
//! [`validate`] checks this anyway.
//!
//! # Splitting
//! A TLAS over the instance cap (or its scratch estimate over the budget) is split so that a
//! ray enters few pieces (issue 15): the instances large against the whole (terrain, ocean;
//! at most a quarter of the cap) stay in the TLAS itself, and the rest of its instance range
//! is partitioned in place by a binned SAH over instance bounds (each side at least 1/8 of the
//! range; an index split when centroids coincide, so it always terminates) into about 8
//! leaves of at most the cap; the leaves with the least box area per instance (the densest)
//! become pieces until the others fit in the TLAS beside the pieces' AABB instances, so only
//! rays entering a dense piece's box take a second trace (a TLAS still over the cap after
//! that is split again, all of it into pieces); the pieces become child TLASes (their instance ranges are sub-ranges of the original:
//! nothing is copied) reached through PIs of new AABB BLASes instanced by the original TLAS,
//! which traversal enters near-to-far, skipping those behind the best hit. AABB BLASes over
//! the primitive cap are split at the median PI centre. Split levels add TLAS levels below the
//! `Levels::N` budget. [`split_for_streaming`] makes the same split of a compiled hierarchy
//! when a streamer loads it (a package keeps its unsplit TLASes, which full builds trace
//! faster; a streamer rebuilds the pieces one at a time).
//!
//! # Partitioning
//! Triangle BLASes are bounded by [`CompileOptions::max_blas_triangles`] (see [`partition`]):
//! `G(P)`'s small meshes are grouped by location under the bound, and a mesh over it (or a LOD
//! level over it) is split into spatial clusters, each a compiled mesh of its own with
//! `source_mesh` = the original and a primitive map back to the source triangles (made from the
//! source data, loaded one mesh at a time and handed to the sink cluster by cluster). A caller
//! that cut a mesh already (`motu import` cuts while parsing) hands the clusters' shapes in
//! instead ([`compile_with_sources`], [`StoredClusters`]): the same records, no load.
//!
//! # Numbering
//! TLASes are numbered depth-first from the root, the children of a TLAS (PI targets, split
//! pieces, LOD levels) getting consecutive ids when the TLAS is emitted (thesis 2.6.3); BLASes
//! and mesh records are numbered in the same walk, so a subtree's records are close together.
//! All indices are 32-bit and every table is checked against `u32`.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! Scene → traversal hierarchy: TLAS on even levels, BLAS on odd, instance lists, programmable
//! instances, identity collapse, TLAS splits by binned SAH over instance bounds (`split.rs`'s
//! `sah_partition`: ranges of 64k+ instances split on rayon, the same ranges as serially;
//! `tlas_split.rs`: huge instances kept in the parent, and as many of the rest as the cap allows:
//! only the densest SAH leaves become pieces; the same split at load time for streaming,
//! `split_for_streaming`, on a package's view: TLASes over `STREAM_SPLIT_INSTANCES` moved to the
//! instance table's tail, split, finalized; `stored_stream_split`/`StreamSplit::from_stored`: the
//! split as a package stores it — tables whole, instances as a map into the package's — and rebuilt
//! in O(instances); `stream_split_taking_instances`/`StreamSplit::give_back`: the import's split,
//! holding the package's instance table while the proxy tables are made over it (no second
//! table); `tlas_split/stash.rs`: with `CompileOptions::split_scratch_dir` (the import's), a range
//! of 1M+ instances is split by key — its records in an unnamed file, the partition over indices,
//! the records put back in its order (a bucket of places per read when mapped): the same split,
//! without the table and the partition's arrays resident together; `instance_table.rs`:
//! `InstanceTable`, `CompiledScene::instances` on the heap or (with `split_scratch_dir`) in a
//! growable shared map of an unnamed file, its pages released behind every pass
//! (`tlas_split/order.rs`: the split's reorders a piece at a time); `instance_map.rs`:
//! `StreamSplit::park_instances` makes the import's split table a read-only map while the proxy
//! clusters read it (pages dropped after each batch, `StoredProxyClusters::of_view_then`); `split/tests/reference.rs` (tests only): the partitioners before their speed-ups,
//! which the fast ones must equal; `tables.rs` holds the table helpers emit, split and finalize
//! share), `ml`/`sl`/`N`/`auto` levels (`auto`, in `analyze.rs` `plan_auto_inlining`: grouping
//! levels of ≤ 256 entries inlined, and small instanced prototypes — ≤ 2^17 triangles with their
//! copies, no LOD below — *baked*: `emit.rs` `bake_for_proto` turns each source mesh's copies into
//! one mesh with a primitive map, so no hop reaches them; what would still be a hop is inlined when
//! its entries × uses ≤ 2^16, `auto_inline_max_instances`), LOD chains (meshopt), the
//! **partitioner** (`partition.rs`: triangle BLASes bounded by `max_blas_triangles`, which `motu
//! import` picks from the scene's size when not given — `auto_max_blas_triangles`: 2^16, or about a
//! 256th of a small build (under ~8.4M triangle-equivalents), never splitting heavily instanced
//! meshes; big meshes and LOD levels split into spatial clusters with a primitive map, small meshes
//! grouped by location), `validate()`, flatten for tests (placements; `testutil.rs` also compares
//! world-space triangles per source triangle, which baked compiles need), and `proxy_boxes.rs`:
//! the boxes inside a triangle BLAS a streamed render tests before building it, with the
//! `proxy_boxes` package section (`motu import` stores them; the streamer checks each BLAS's
//! entry by a hash of its records), and `proxy_clusters.rs`: the proxy clusters of a TLAS (binned
//! SAH over its triangle instances) with the `proxy_clusters` package section (stored at import
//! over the stream split; each TLAS's entry checked by a hash of its record and instances).
//!
//! Key types: `compile`, `compile_with_loader`, `CompiledScene`, `validate`, `split_for_streaming`,
//! `StreamSplit`.

mod analyze;
pub mod blas_counts;
mod emit;
mod finalize;
mod flatten;
mod instance_map;
mod instance_table;
mod lod;
pub mod partition;
pub mod proxy_boxes;
pub mod proxy_clusters;
mod split;
mod tables;
mod tlas_split;
mod validate;
mod xform;

#[cfg(test)]
mod testutil;

#[cfg(test)]
mod tests;

pub use flatten::{flatten_compiled, flatten_compiled_records, flatten_source};
pub use instance_map::{park_table, InstanceMap, PARK_MIN_INSTANCES};
pub use instance_table::InstanceTable;
pub use partition::{
    auto_bound, auto_bound_settles_at_triangles, auto_max_blas_triangles,
    DEFAULT_MAX_BLAS_TRIANGLES, MIN_AUTO_MAX_BLAS_TRIANGLES,
};
pub use split::sah_partition;

pub use tlas_split::{
    split_for_streaming, stored_stream_split, stored_stream_split_in_place,
    stream_split_taking_instances, stream_split_taking_instances_in, StoredStreamSplit,
    StreamSplit, STREAM_SPLIT_INSTANCES,
};
pub use validate::{validate, validate_with, Limits, ValidateError};

use motu_abi::{
    BlasRecord, GeometryRecord, HierarchyView, LodSelectorRecord, MaterialRecord, MeshRecord,
    PiRecord, TlasRecord,
};
use motu_scene::{ElementId, MeshData, Scene};

/// The Vulkan-safe default for instances per TLAS and primitives per BLAS (2^24 − 1).
pub const DEFAULT_MAX_PER_NODE: u32 = (1 << 24) - 1;

/// How many instancing levels to keep.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Levels {
    /// Keep the graph (multi-level instancing).
    Ml,
    /// Flatten everything into one TLAS (the single-level baseline).
    Sl,
    /// At most this many TLAS levels on any root-to-leaf path (before splitting); `N(1)` is `Sl`.
    N(u32),
    /// `Ml`, plus inlining of levels that save no memory worth a trace: a prototype without
    /// meshes of its own whose TLAS would hold at most
    /// [`CompileOptions::auto_inline_max_entries`] entries (the thesis forest's group levels:
    /// 12 PIs each), and any prototype whose entries times its uses are at most
    /// [`CompileOptions::auto_inline_max_instances`] (a depth-4 sphereflake's flakes), is
    /// expanded into its parents; such levels cost every ray entering them one more
    /// `traceRayEXT`. Prototypes where instancing saves memory stay shared, and small ones
    /// are baked ([`CompileOptions::auto_bake_max_triangles`]).
    Auto,
}

#[derive(Clone, Debug)]
pub struct CompileOptions {
    pub levels: Levels,
    /// Instances per TLAS (Vulkan's `maxInstanceCount`; at least 2).
    pub max_instances_per_tlas: u32,
    /// Primitives per AABB BLAS (`maxPrimitiveCount`; at least 2).
    pub max_primitives_per_blas: u32,
    /// Triangles per triangle BLAS (the partitioner's bound, at least 1): meshes over it are
    /// split into spatial clusters, small meshes grouped by location under it.
    pub max_blas_triangles: u32,
    /// Estimated TLAS build scratch per instance, for `max_tlas_scratch_bytes`.
    pub scratch_bytes_per_instance: u64,
    /// A TLAS whose estimated scratch exceeds this is split.
    pub max_tlas_scratch_bytes: u64,
    /// Total LOD levels (level 0 included) for meshes over `lod_triangle_threshold`; `None` or
    /// fewer than 2 disables LOD.
    pub lod_levels: Option<u32>,
    pub lod_triangle_threshold: u32,
    /// Keep only root edges and root meshes tagged with these elements.
    pub subset: Option<Vec<ElementId>>,
    /// Tolerance for "identity" in identity collapse.
    pub identity_tolerance: f32,
    /// [`Levels::Auto`]: the largest TLAS (instances + PIs) of a mesh-less prototype that is
    /// still inlined into its parents.
    pub auto_inline_max_entries: u64,
    /// [`Levels::Auto`]: any prototype whose inlining puts at most this many entries into its
    /// parents' TLASes (its TLAS's entries times its uses) is inlined, meshes or not: a hop
    /// every ray entering it pays is dearer than a few thousand instance records. 0 turns it
    /// off.
    pub auto_inline_max_instances: u64,
    /// [`Levels::Auto`]: a prototype that would be a TLAS of instances (no LOD below it) and
    /// whose content, instanced copies included, is at most this many triangles is *baked*:
    /// its meshes' copies become triangle BLASes (with a primitive map to the source triangle),
    /// so a ray reaches it with no traversal-shader hop. 0 turns baking off.
    pub auto_bake_max_triangles: u64,
    /// A directory for unnamed scratch files: a TLAS over the cap of at least 2^20 instances
    /// is split by key there (its records in a file while the partition moves indices; the
    /// same split, without the table and the partition's arrays resident together), and an
    /// instance table of at least [`PARK_MIN_INSTANCES`] is an unnamed file there, mapped
    /// ([`InstanceTable::in_file`]). `None`: split in memory, the table on the heap.
    pub split_scratch_dir: Option<std::path::PathBuf>,
}

impl Default for CompileOptions {
    fn default() -> Self {
        Self {
            levels: Levels::Ml,
            max_instances_per_tlas: DEFAULT_MAX_PER_NODE,
            max_primitives_per_blas: DEFAULT_MAX_PER_NODE,
            max_blas_triangles: DEFAULT_MAX_BLAS_TRIANGLES,
            scratch_bytes_per_instance: 128,
            max_tlas_scratch_bytes: u64::MAX,
            lod_levels: None,
            lod_triangle_threshold: 100_000,
            subset: None,
            identity_tolerance: 1e-6,
            auto_inline_max_entries: 256,
            // 2^16 instances are 4 MiB of instance records, little beside any scene that needs
            // a GPU: a depth-4 sphereflake's flake3 (820 entries × 9 uses) and the thesis
            // forest's tree groups (2,592 × 12) inline; a depth-5 sphereflake's flake4 (7,381 ×
            // 9) and Moana's instanced plants (thousands of uses each) stay shared.
            auto_inline_max_instances: 1 << 16,
            // A forest tree of 8,732 eight-triangle leaves (70k triangles, ~5 MB of BLAS) bakes;
            // the flake levels of a depth-4 sphereflake (787k) and Moana's plants do not.
            auto_bake_max_triangles: 1 << 17,
            split_scratch_dir: None,
        }
    }
}

impl CompileOptions {
    /// Triangles per triangle BLAS: the partitioner's bound within the primitive cap.
    pub(crate) fn blas_triangle_bound(&self) -> u32 {
        self.max_blas_triangles
            .min(self.max_primitives_per_blas)
            .max(1)
    }

    /// The instance cap after the scratch budget.
    pub fn effective_instance_cap(&self) -> u64 {
        let by_scratch = self
            .max_tlas_scratch_bytes
            .checked_div(self.scratch_bytes_per_instance.max(1))
            .unwrap_or(u64::MAX);
        (self.max_instances_per_tlas as u64).min(by_scratch)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum CompileError {
    #[error("invalid compile options: {0}")]
    InvalidOptions(String),
    #[error("too many {what} for 32-bit indices: {count}; use fewer flattened levels (--levels ml) or a subset")]
    TooMany { what: &'static str, count: u64 },
    #[error("cannot allocate {bytes} bytes for the {what} table; use fewer flattened levels (--levels ml) or a subset")]
    OutOfMemory { what: &'static str, bytes: u64 },
    #[error("mesh {mesh}: {reason}")]
    Mesh { mesh: u32, reason: String },
    /// The mesh loader could not read a source mesh.
    #[error("mesh {mesh}: {source}")]
    MeshLoad {
        mesh: u32,
        #[source]
        source: motu_scene::StoreError,
    },
    /// meshopt refused the simplifier's input.
    #[error("mesh {mesh}: simplifier input: {source}")]
    Simplifier {
        mesh: u32,
        #[source]
        source: meshopt::Error,
    },
    #[error("mesh sink rejected compiled mesh record {mesh_record}: {source}")]
    Sink {
        mesh_record: u32,
        #[source]
        source: motu_scene::StoreError,
    },
    #[error("internal compiler error: {0}")]
    Internal(String),
    /// A split's scratch file (`CompileOptions::split_scratch_dir`) could not be written or
    /// read back.
    #[error("TLAS split scratch file in {dir}: {source}")]
    Scratch {
        dir: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The compiled hierarchy references out of range (a compiler bug, not bad input).
    #[error("internal compiler error: {0}")]
    References(#[source] motu_abi::HierarchyError),
    /// A stored stream split that does not fit the hierarchy it was stored with.
    #[error("internal compiler error: stored stream split: {0}")]
    StoredSplit(#[source] motu_abi::HierarchyError),
}

/// What a compile did, for `motu import`/`motu info` and benchmarks (its JSON, stored in the
/// package meta, is `motu-import`'s `compile_report::CompileReport`).
#[derive(Clone, Debug, Default, PartialEq)]
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
    /// Highest node level (root TLAS = 0).
    pub max_level: u32,
    /// TLASes on the longest root-to-leaf path.
    pub tlas_levels: u32,
    pub max_instances_per_tlas: u64,
    pub max_primitives_per_blas: u64,
    /// TLASes that were split, and the pieces made.
    pub split_tlases: u64,
    pub split_pieces: u64,
    /// AABB BLASes over the primitive cap that were split into groups.
    pub split_aabb_blases: u64,
    /// The partitioner's bound ([`CompileOptions::max_blas_triangles`]), the largest triangle
    /// BLAS made, the meshes (source meshes and LOD levels) split into clusters, and the
    /// clusters made.
    pub max_blas_triangles: u64,
    pub max_triangles_per_blas: u64,
    pub partitioned_meshes: u64,
    pub partition_clusters: u64,
    pub dropped_degenerate_instances: u64,
    /// Prototypes inlined by identity collapse (single parent, identity transform).
    pub collapsed_prototypes: u64,
    /// Prototypes baked into triangle BLASes (`--levels auto`,
    /// [`CompileOptions::auto_bake_max_triangles`]).
    pub baked_prototypes: u64,
    /// Prototypes `--levels auto` inlined into their parents (grouping levels of a few
    /// entries, and levels whose entries × uses are at most
    /// [`CompileOptions::auto_inline_max_instances`]).
    pub inlined_prototypes: u64,
    /// Source meshes given a LOD chain, and the simplified meshes made.
    pub lod_source_meshes: u64,
    pub lod_meshes_made: u64,
    /// Leaf placements after full flattening (root-to-prototype paths to prototypes with
    /// meshes, root excluded), within the subset. Saturating.
    pub flattened_instances: u64,
    pub time_ms: f64,
    /// Where `time_ms` went.
    pub phases: CompilePhases,
}

/// The phases of a compile, in milliseconds (`motu import --json`'s `compile_phases`).
/// `emit_ms` holds `load_ms`, `partition_ms` and `sink_ms`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CompilePhases {
    /// The per-prototype plan (`analyze`).
    pub analyze_ms: f64,
    /// The walk that writes the tables, with everything below.
    pub emit_ms: f64,
    /// Reading source meshes back (LOD chains, the partitioner).
    pub load_ms: f64,
    /// Cutting meshes over the bound into clusters (without storing them).
    pub partition_ms: f64,
    /// Handing the meshes the compiler made (LOD levels, clusters) to the caller's sink
    /// (`motu import` stores them on a writer thread: this is the wait for its queue).
    pub sink_ms: f64,
    /// Levels and exact bounds (`finalize`).
    pub finalize_ms: f64,
}

/// The compiled hierarchy: the tables of [`motu_abi`], owned.
#[derive(Clone, Debug, Default)]
pub struct CompiledScene {
    pub root_tlas: u32,
    pub tlases: Vec<TlasRecord>,
    pub instances: InstanceTable,
    pub blases: Vec<BlasRecord>,
    pub geometries: Vec<GeometryRecord>,
    pub pis: Vec<PiRecord>,
    pub lod_selectors: Vec<LodSelectorRecord>,
    pub lod_levels: Vec<u32>,
    pub meshes: Vec<MeshRecord>,
    pub materials: Vec<MaterialRecord>,
    /// One record per scene texture (filled by the packer, which reads the images; the
    /// compiler leaves both empty and materials refer to scene texture indices).
    pub textures: Vec<motu_abi::TextureRecord>,
    pub texels: Vec<u32>,
    pub report: CompileReport,
}

impl CompiledScene {
    pub fn view(&self) -> HierarchyView<'_> {
        HierarchyView {
            root_tlas: self.root_tlas,
            tlases: &self.tlases,
            instances: &self.instances,
            blases: &self.blases,
            geometries: &self.geometries,
            pis: &self.pis,
            lod_selectors: &self.lod_selectors,
            lod_levels: &self.lod_levels,
            meshes: &self.meshes,
            materials: &self.materials,
            textures: &self.textures,
            texels: &self.texels,
        }
    }
}

/// Receives each mesh the compiler makes, once, with its index in [`CompiledScene::meshes`], as
/// soon as it is made; the compiler keeps no such data. These are simplified LOD meshes
/// (`lod > 0`) and the clusters of partitioned meshes (with their primitive map, the
/// record's `FLAG_PRIMITIVE_MAP`). Whole source meshes (`lod == 0`, no map) are not passed:
/// their data is in the scene's geometry store.
pub type MeshSink<'a> =
    dyn FnMut(u32, &MeshData, Option<&[u32]>) -> Result<(), motu_scene::StoreError> + 'a;

/// Loads a source mesh's data (for LOD chains and partitioning), one mesh at a time.
pub type MeshLoader<'a> =
    dyn Fn(motu_scene::MeshId) -> Result<MeshData, motu_scene::StoreError> + 'a;

/// The shape of one cluster of a mesh partitioned before compiling (an import cuts meshes over
/// the bound while parsing, [`partition::partition_mesh`] as the compiler would, and stores
/// the clusters itself): what the compiler's mesh record needs, the data stays with the caller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ClusterShape {
    pub vertex_count: u32,
    pub triangle_count: u32,
    pub has_normals: bool,
    pub bounds: motu_scene::Aabb,
}

/// Asked for the clusters of source mesh `m` before the compiler loads and partitions it:
/// `(m, bound, first_record)` → the clusters of `partition_mesh(m's data, bound)` in order,
/// whose mesh records will be `first_record..first_record + n` (the caller stores their
/// data), or `None` to have the compiler partition the mesh itself.
pub type StoredClusters<'a> =
    dyn FnMut(motu_scene::MeshId, u32, u32) -> Option<Vec<ClusterShape>> + 'a;

/// Compiles `scene`, loading source meshes from its geometry store. Mesh records' `chunk` and
/// `*_offset` fields are left `NONE` for the packer to fill.
pub fn compile(
    scene: &Scene,
    opts: &CompileOptions,
    sink: &mut MeshSink<'_>,
) -> Result<CompiledScene, CompileError> {
    let load = |m| scene.mesh_data(m).map_err(motu_scene::StoreError::from);
    compile_with_loader(scene, opts, &load, sink)
}

/// [`compile`] with source meshes read by `load` (e.g. from a finished scratch package).
pub fn compile_with_loader(
    scene: &Scene,
    opts: &CompileOptions,
    load: &MeshLoader<'_>,
    sink: &mut MeshSink<'_>,
) -> Result<CompiledScene, CompileError> {
    compile_with_sources(scene, opts, load, &mut |_, _, _| None, sink)
}

/// [`compile_with_loader`] where meshes over the bound may have been partitioned already
/// (`stored`, see [`StoredClusters`]): their records are made from the cluster shapes, with
/// no load and no sink call. The records are those the compiler would make itself.
pub fn compile_with_sources(
    scene: &Scene,
    opts: &CompileOptions,
    load: &MeshLoader<'_>,
    stored: &mut StoredClusters<'_>,
    sink: &mut MeshSink<'_>,
) -> Result<CompiledScene, CompileError> {
    let _span = tracing::info_span!(
        "compile",
        edges = scene.all_edges().len(),
        prototypes = scene.prototypes().len(),
        levels = ?opts.levels
    )
    .entered();
    let start = std::time::Instant::now();
    check_options(opts)?;
    let plan = analyze::Plan::new(scene, opts)?;
    let analyze_ms = start.elapsed().as_secs_f64() * 1e3;
    let mut out = emit::Emitter::new(&plan, load, stored, sink).run()?;
    let emitted = std::time::Instant::now();
    out.report.phases.analyze_ms = analyze_ms;
    out.report.phases.emit_ms = (emitted - start).as_secs_f64() * 1e3 - analyze_ms;
    // A neutral 1×1 texture per scene texture until the packer reads the images
    // (`CompiledScene::textures`): the hierarchy is complete without them.
    out.textures = (0..scene.textures().len() as u32)
        .map(|i| motu_abi::TextureRecord {
            texel_offset: i,
            width: 1,
            height: 1,
            mip_count: 1,
        })
        .collect();
    out.texels = vec![u32::MAX; scene.textures().len()];
    finalize::finalize(&mut out)?;
    out.report.phases.finalize_ms = emitted.elapsed().as_secs_f64() * 1e3;
    out.report.time_ms = start.elapsed().as_secs_f64() * 1e3;
    tracing::info!(
        tlases = out.tlases.len(),
        blases = out.blases.len(),
        instances = out.instances.len(),
        pis = out.pis.len(),
        time_ms = out.report.time_ms,
        "compiled"
    );
    Ok(out)
}

/// [`HierarchyView::check_references`] of `out`, a mapped instance table's pages dropped
/// behind the check.
fn check_references(out: &CompiledScene) -> Result<(), motu_abi::HierarchyError> {
    out.view()
        .check_references_then(&mut |b, e| out.instances.release_range(b, e))
}

/// Drops file-held edge pages from the resident set ([`Scene::release_edge_pages`]); a failed
/// hint costs only memory, so it is logged, not returned.
fn release_edge_pages(scene: &Scene) {
    if let Err(error) = scene.release_edge_pages() {
        tracing::debug!(%error, "could not release the edge map's pages");
    }
}

fn check_options(opts: &CompileOptions) -> Result<(), CompileError> {
    if opts.effective_instance_cap() < 2 {
        return Err(CompileError::InvalidOptions(format!(
            "at most {} instances per TLAS (after the scratch budget); need at least 2",
            opts.effective_instance_cap()
        )));
    }
    if opts.max_primitives_per_blas < 2 {
        return Err(CompileError::InvalidOptions(
            "max_primitives_per_blas must be at least 2".into(),
        ));
    }
    if opts.max_blas_triangles == 0 {
        return Err(CompileError::InvalidOptions(
            "max_blas_triangles must be at least 1".into(),
        ));
    }
    if opts.levels == Levels::N(0) {
        return Err(CompileError::InvalidOptions(
            "--levels 0: at least one TLAS level is needed".into(),
        ));
    }
    Ok(())
}
