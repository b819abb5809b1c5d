//! The CPU reference traversal: walks motu's compiled multi-level hierarchy
//! ([`motu_abi::HierarchyView`]) with the same semantics as the GPU traversal shader, renders
//! the same views and AOV records, and compares any two AOVs pixel by pixel. Every GPU backend
//! is checked against it.
//!
//! # Semantics (mirrored by `shaders/`)
//! - Traversal starts in `root_tlas` with the world ray; the direction is unit length, and rays
//!   are moved between spaces with the affine 3×4 matrices **without renormalising the
//!   direction**, so every `t` anywhere is a world distance and hits compare across levels.
//! - A TLAS instance transforms the ray by the inverse of `tlas_from_blas` (computed once per
//!   instance, in f64, cached). Triangle BLASes use the watertight test of Woop, Benthin and
//!   Wald (2013): double-sided, edges inclusive, closest hit with strict `t < best`.
//! - An AABB BLAS holds programmable instances (PIs): the slab test in BLAS space gives
//!   `t_near = max(t_enter, t_min)`; the child continues with `child_from_parent` composed
//!   onto the current `object_from_world` (the composed matrix is what the payload carries).
//!   A LOD selector picks its level with [`motu_abi::lod::select_lod`] from the selector's
//!   radius, the length of the unit world direction in selector space, `t_near`,
//!   `CameraParams::pixels_per_unit_at_1`, the ray kind and `forced_lod`.
//! - PIs found during one TLAS walk are pushed on an explicit stack (unbounded on the CPU; its
//!   maximum depth is reported) farthest first, so the nearest is walked next; an entry whose
//!   `t_near >= best t` is skipped without a walk. Each TLAS walk counts as one trace (one
//!   `traceRayEXT` / ray query on the GPU).
//! - The hit reports `MeshRecord::source_mesh`, the triangle index within the hit compiled
//!   mesh, the world `t`, and the level of the innermost LOD selector on its path (else
//!   `MeshRecord::lod`).
//!
//! # `t_min`
//! Primary rays use `t_min = 0` from the camera eye. Shadow rays start at the hit point offset
//! along the face-forwarded geometric world normal by [`render::shadow_offset`] (a relative
//! epsilon of the point's magnitude, like the GPU's offset) and then use `t_min = 0` and
//! terminate on their first hit. `t_min` applies in every space unchanged because `t` is
//! invariant under the transforms.
//!
//! # Laziness and threads
//! [`Tracer`] builds each mesh BVH (binned SAH, 16 bins), TLAS instance BVH and BLAS item BVH
//! once: all reachable ones in parallel in [`Tracer::prepare`], or serially on first touch
//! during traversal. [`render::render`] runs `prepare` then traces rows in parallel with rayon,
//! one [`Scratch`] per worker so rays do not allocate.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! CPU reference traversal (binned-SAH BVHs, watertight triangles, multi-level walk with the GPU's
//! semantics), CPU renderer, AOV comparison. Files, lowest first: `ray.rs` (ray maths,
//! `shadow_offset`), `bvh.rs`, `mesh.rs`, `coverage.rs` (alpha coverage traversal asks),
//! `traverse.rs`, `options.rs` (`View`, `RenderOptions`), `shade.rs`, `render.rs`.
//!
//! Key types: `render`, `compare`.

pub mod bvh;
pub mod compare;
mod coverage;
pub mod mesh;
mod options;
pub mod ray;
pub mod render;
pub mod shade;
pub mod testutil;
mod traverse;

#[cfg(test)]
mod tests;

pub use compare::{compare, CompareError, CompareReport, DEFAULT_REL_EPS};
pub use mesh::{LoadError, MeshBvh, MeshError, MeshGeometry, MeshSource};
pub use render::{
    encode_png, render, render_with, write_png, RenderOptions, RenderOutput, RenderStats, View,
};
pub use traverse::{Hit, RayQuery, Scratch, Tracer};

/// Errors of the CPU tracer.
#[derive(Debug, thiserror::Error)]
pub enum TraceError {
    #[error(transparent)]
    Hierarchy(#[from] motu_abi::HierarchyError),
    #[error("hierarchy: TLAS {tlas} is reachable from itself through programmable instances")]
    Cycle { tlas: u32 },
    #[error("mesh record {mesh}: {source}")]
    Mesh {
        mesh: u32,
        #[source]
        source: MeshError,
    },
    #[error("camera: {0}")]
    Camera(String),
    #[error("PNG {path}: {reason}")]
    Png { path: String, reason: String },
    #[error("PNG {path}: {source}")]
    PngEncode {
        path: String,
        #[source]
        source: png::EncodingError,
    },
    #[error("PNG {path}: {source}")]
    PngWrite {
        path: String,
        #[source]
        source: std::io::Error,
    },
}
