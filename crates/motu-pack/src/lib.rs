//! The motu scene package schema, on top of the `motu-package` container: which sections a
//! package holds, how mesh data is laid out in chunks, and how to read a compiled hierarchy
//! back as a zero-copy [`motu_abi::HierarchyView`].
//!
//! Sections (kinds are stable; FORMAT.md "Sections defined by the compiler"):
//! the nine record tables of `motu-abi` (TLASes, instances, BLASes, geometries, PIs, LOD
//! selectors, LOD levels, meshes, materials) as `Pod` arrays, plus one JSON section, `meta`,
//! with everything that is not per-record (cameras, lights, elements, names, statistics).
//!
//! Mesh data: one **mesh blob** per compiled mesh, appended to a chunk: positions
//! (`[f32; 3]` × vertices), then `u32` indices (3 per triangle) at the next 16-byte boundary,
//! then optional normals likewise — GPU-upload-ready, readable in place from a raw chunk. A
//! cluster of a partitioned mesh adds its primitive map (`u32` per triangle) likewise.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! The scene schema on the container: section kinds, mesh blob layout, `meta` JSON,
//! `PackageGeometry` (a `GeometryStore` writing straight into chunks).
//!
//! Key types: `ScenePackage`, `write_hierarchy`.

mod blob;
mod info;
mod meta;
mod read;
mod sections;
mod store;
mod write;

pub use blob::{MeshBlobLayout, MESH_BLOB_ALIGN};
pub use info::{ElementsInfo, PackageInfo};
pub use meta::{
    CurveMeta, ElementMeta, MetaError, PackageMeta, StreamSplitMeta, SCHEMA, SCHEMA_READABLE,
};
pub use read::{read_mesh_blob, MeshGeometry, ScenePackage};
pub use sections::*;
pub use store::{place_mesh_record, PackageGeometry};
pub use write::{
    begin_texels, write_hierarchy, write_hierarchy_after_texels, write_hierarchy_after_texels_then,
    write_stream_split, StreamSplitTables, INSTANCE_PIECE_RECORDS,
};

/// Errors reading or writing the package schema.
#[derive(Debug, thiserror::Error)]
pub enum PackError {
    #[error(transparent)]
    Package(#[from] motu_package::PackageError),
    #[error("package {path}: {reason}")]
    Schema { path: String, reason: String },
    /// The `meta` section does not parse, or would not.
    #[error("package {path}: {source}")]
    Meta {
        path: String,
        #[source]
        source: meta::MetaError,
    },
    /// The tables reference out of range.
    #[error("package {path}: {source}")]
    References {
        path: String,
        #[source]
        source: motu_abi::HierarchyError,
    },
    #[error("mesh {mesh}: {reason}")]
    Mesh { mesh: u32, reason: String },
    /// A mesh's chunk is not in the package.
    #[error("mesh {mesh}: {source}")]
    MeshChunk {
        mesh: u32,
        #[source]
        source: motu_package::PackageError,
    },
    /// A mesh's bytes cannot be viewed as its element type (`what`: positions, indices, ...;
    /// `cast`: bytemuck's reason, typed, see `PackageError::SectionCast`).
    #[error("mesh {mesh}: {what}: {cast}")]
    MeshCast {
        mesh: u32,
        what: &'static str,
        cast: bytemuck::PodCastError,
    },
    /// The geometry store refused (it was finished, or a mesh was never stored).
    #[error("{0}")]
    Store(String),
}
