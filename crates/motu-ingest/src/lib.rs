//! The adapter from `pbrt-import` (which knows nothing of motu) and from OBJ files (tobj) to the
//! scene model.
//!
//! Mapping rules:
//! - `ObjectBegin` → a prototype; `ObjectInstance` → an instance edge from the world (or, with
//!   motu's nested-instancing extension, from the object being defined) with the CTM as
//!   `parent_from_child`.
//! - A shape's own transform (`parent_from_shape`) is baked into its vertices (normals by the
//!   inverse transpose), since a mesh belongs to exactly one prototype; no instance edge is
//!   invented for it, so instance counts stay those of the file.
//! - Elements: each file included from the entry file's world block is an element named by its
//!   path stem; everything else is `main`.
//! - Cameras are named by the stem of the file holding the `Camera` directive (`_2`, `_3`… for
//!   repeats); the last one in the scene is the active one (pbrt's rule) and is listed first.
//! - Curves are counted and skipped, or (`curve_ribbons`) tessellated into flat ribbon meshes;
//!   unsupported shapes are counted and warned about. `ReverseOrientation` does not matter:
//!   shading is two-sided.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! Adapter: pbrt events (from pbrt or Moana's base package) and OBJ (tobj) → `SceneBuilder`; names
//! elements and cameras by file stem.
//!
//! Key types: `ingest_file`, `is_moana_json`.

mod curves;
mod obj;
mod pbrt;

pub use obj::ingest_obj;
pub use pbrt::{ingest_moana_json, ingest_pbrt};

/// Whether `path` is Moana's JSON+OBJ base package (a `.json` file or a folder of element JSON
/// files) rather than pbrt or OBJ.
pub fn is_moana_json(path: &Path) -> bool {
    pbrt_import::moana_json::is_moana_json(path)
}

use motu_scene::{GeometryStore, Scene};
use std::path::Path;

#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    #[error(transparent)]
    Pbrt(#[from] pbrt_import::Error),
    #[error("{path}: {reason}")]
    Obj { path: String, reason: String },
    /// tobj could not load the OBJ file (`detail`: what motu's line scan found there).
    #[error("{path}: {source}{}", detail.as_ref().map(|d| format!(": {d}")).unwrap_or_default())]
    ObjLoad {
        path: String,
        detail: Option<String>,
        #[source]
        source: tobj::LoadError,
    },
    /// A material library named by `mtllib` cannot be read.
    #[error("{path}: mtllib {}: {source}", lib.display())]
    MtlUnreadable {
        path: String,
        lib: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// tobj could not load the material libraries.
    #[error("{path}: materials not loaded from {libs}: {source}")]
    Materials {
        path: String,
        libs: String,
        #[source]
        source: tobj::LoadError,
    },
    #[error("{at}: {source}")]
    Scene {
        at: String,
        #[source]
        source: motu_scene::SceneError,
    },
    /// Converting the curves left at the end of the parse failed.
    #[error("{at}: {source}")]
    Curves {
        at: String,
        #[source]
        source: pbrt_import::SinkError,
    },
}

/// Called with (scene-text bytes entered so far, files entered so far) as the parse reaches
/// each file (PLY bytes are not counted: they load in parallel batches).
#[derive(Clone)]
pub struct ProgressFn(pub std::sync::Arc<dyn Fn(u64, u64) + Send + Sync>);

impl std::fmt::Debug for ProgressFn {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("ProgressFn")
    }
}

#[derive(Clone, Debug, Default)]
pub struct IngestOptions {
    /// Progress reports (the CLI's progress bar).
    pub progress: Option<ProgressFn>,
    pub allow_missing: bool,
    /// 3 or 4 forces a pbrt version; `None` detects it.
    pub pbrt_version: Option<u32>,
    /// Parallel PLY loading (rayon) when true.
    pub parallel: bool,
    /// Tessellate `curve` shapes into flat ribbons (otherwise they are counted and skipped).
    pub curve_ribbons: bool,
    /// Write the instance edges to an unnamed scratch file in this directory as they are
    /// parsed ([`motu_scene::SceneBuilder::spill_edges_to`]; an import's: its output's
    /// directory); `None` keeps them on the heap.
    pub edge_spill_dir: Option<std::path::PathBuf>,
}

/// What an import saw, for `motu import` and `motu info`.
#[derive(Clone, Debug, Default)]
pub struct IngestReport {
    pub files: u64,
    pub text_bytes: u64,
    pub ply_bytes: u64,
    pub shapes: u64,
    pub meshes: u64,
    pub curves: u64,
    /// Curves turned into ribbon meshes (`curve_ribbons`).
    pub curve_ribbons: u64,
    /// Triangles of those ribbons.
    pub curve_ribbon_triangles: u64,
    pub unsupported_shapes: u64,
    pub skipped_shapes: u64,
    pub degenerate_meshes: u64,
    pub warnings: Vec<String>,
    /// Every file the import read (scene text, PLY, OBJ, MTL): an output must not be one.
    pub input_files: Vec<std::path::PathBuf>,
}

/// Imports a pbrt scene (`.pbrt`, `.pbrt.gz`), an OBJ file (`.obj`) or Moana's JSON+OBJ base
/// package (a `.json` file or a folder, [`is_moana_json`]).
pub fn ingest_file(
    path: &Path,
    options: &IngestOptions,
    geometry: Box<dyn GeometryStore>,
) -> Result<(Scene, IngestReport), IngestError> {
    let is_obj = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("obj"));
    if is_obj {
        ingest_obj(path, options.allow_missing, geometry)
    } else if is_moana_json(path) {
        ingest_moana_json(path, options, geometry)
    } else {
        ingest_pbrt(path, options, geometry)
    }
}
