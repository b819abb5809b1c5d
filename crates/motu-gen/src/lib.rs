//! Procedural pbrt scenes for stress tests, demos and benchmarks.
//!
//! `generate` writes `DIR/scene.pbrt` plus binary little-endian PLY files and
//! included pbrt files beside it (the island can also be written in the layout of Moana's
//! JSON+OBJ base package, [`IslandFormat::MoanaJson`]). Every generator is deterministic (same
//! options → byte-identical files, on the same platform), streams its output
//! (memory does not grow with the scene: meshes are computed vertex by vertex,
//! placements line by line) and depends on no other motu crate.
//!
//! | kind | dialect | instancing |
//! |---|---|---|
//! | [`GenKind::Forest`] | pbrt-v4 | nested (extension) unless `flat` |
//! | [`GenKind::Sphereflake`] | pbrt-v4 | nested (extension) unless `flat` |
//! | [`GenKind::LodGrid`] | pbrt-v4 | single level (standard) |
//! | [`GenKind::Island`] | pbrt-v3 | single level (standard, Moana-like) |
//!
//! # The nested-instancing extension
//!
//! pbrt (v3 and v4) allows only shapes inside `ObjectBegin`/`ObjectEnd` and
//! rejects `ObjectInstance` there. motu accepts it and reads it as an instance
//! edge from the enclosing object to the named one, with the transform current
//! at the `ObjectInstance` statement (relative to the enclosing object's
//! space), so objects form a DAG:
//!
//! ```text
//! ObjectBegin "tree"
//!   Shape "plymesh" "string filename" [ "trunk.ply" ]
//!   AttributeBegin Transform [ ... ] ObjectInstance "leaf" AttributeEnd   # extension
//! ObjectEnd
//! ```
//!
//! An object must be defined before it is instanced, so cycles cannot be
//! written. `forest` and `sphereflake` use this unless their `flat` option
//! asks for standard single-level pbrt (every leaf instance at world level
//! with composed transforms: the same picture, many more instance lines).
//!
//! # Counts in [`GenSummary`]
//!
//! * `object_instances`: `ObjectInstance` statements written (instance edges).
//! * `flattened_instances`: (object, world transform) pairs with directly
//!   owned shapes after expanding every nested instance: the BLAS instances a
//!   single-level compile produces. Equal to `object_instances` for standard
//!   single-level files; a `flat` forest writes exactly the nested forest's
//!   `flattened_instances` as lines.
//! * `unique_triangles`: triangles of every shape written once (objects and
//!   world-level shapes); `instanced_triangles`: triangles after full
//!   flattening (world-level shapes count once).

mod courtyard;
mod forest;
mod island;
mod lod_grid;
mod math;
mod mesh;
mod pbrt;
mod rng;
mod run;
mod sphereflake;
#[cfg(test)]
mod testutil;
mod text;

use std::fmt;
use std::path::{Path, PathBuf};
use std::str::FromStr;

pub use courtyard::CourtyardOptions;
pub use forest::ForestOptions;
pub use island::{IslandFormat, IslandOptions, ISLAND_CAMERAS, ISLAND_ELEMENTS};
pub use lod_grid::LodGridOptions;
pub use pbrt::Syntax;
pub use sphereflake::SphereflakeOptions;

/// Which scene to generate, with its options.
#[derive(Clone, Debug)]
pub enum GenKind {
    Forest(ForestOptions),
    Sphereflake(SphereflakeOptions),
    LodGrid(LodGridOptions),
    Island(IslandOptions),
    Courtyard(CourtyardOptions),
}

impl GenKind {
    /// The CLI name of the kind (`forest`, `sphereflake`, `lod-grid`, `island`).
    pub fn name(&self) -> &'static str {
        match self {
            GenKind::Forest(_) => "forest",
            GenKind::Sphereflake(_) => "sphereflake",
            GenKind::LodGrid(_) => "lod-grid",
            GenKind::Island(_) => "island",
            GenKind::Courtyard(_) => "courtyard",
        }
    }
}

/// A `W×H` grid (parsed from `"4x3"`): `width` copies along x, `height` along z.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GridSize {
    pub width: u32,
    pub height: u32,
}

impl GridSize {
    pub const fn new(width: u32, height: u32) -> Self {
        Self { width, height }
    }

    /// Cells in the grid.
    pub fn count(&self) -> u64 {
        u64::from(self.width) * u64::from(self.height)
    }
}

impl fmt::Display for GridSize {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

impl FromStr for GridSize {
    type Err = GenError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let invalid = || GenError::InvalidOption {
            option: "grid",
            reason: format!("`{s}` is not WxH with W, H ≥ 1 (e.g. 4x3)"),
        };
        let (w, h) = s.split_once(['x', 'X', '×']).ok_or_else(invalid)?;
        let width: u32 = w.trim().parse().map_err(|_| invalid())?;
        let height: u32 = h.trim().parse().map_err(|_| invalid())?;
        if width == 0 || height == 0 {
            return Err(invalid());
        }
        Ok(Self { width, height })
    }
}

/// Reported about every 100 ms while generating, and once at the end.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct GenProgress {
    pub files_written: u64,
    pub files_total: u64,
    pub bytes_written: u64,
}

/// What was written.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct GenSummary {
    /// `DIR/scene.pbrt` (`DIR/json/island.json` for the island's base-package layout), the
    /// file to import.
    pub scene_path: PathBuf,
    pub files_written: u64,
    pub bytes_written: u64,
    /// `ObjectInstance` statements written.
    pub object_instances: u64,
    /// Instances with geometry after full flattening (see the crate docs).
    pub flattened_instances: u64,
    pub unique_triangles: u64,
    pub instanced_triangles: u64,
    /// Element names (top-level `Include`s of the world block; `main` for
    /// single-file scenes), in file order.
    pub elements: Vec<String>,
    /// Camera names (`default` for single-camera scenes); the active camera last.
    pub cameras: Vec<String>,
    /// True when the output uses the nested-instancing extension.
    pub nested_instancing: bool,
    pub syntax: Option<Syntax>,
}

/// Generation failures.
#[derive(Debug, thiserror::Error)]
pub enum GenError {
    #[error("cannot write {}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("invalid option `{option}`: {reason}")]
    InvalidOption {
        option: &'static str,
        reason: String,
    },
    #[error("the scene is too large: {0}")]
    TooLarge(String),
    #[error("a generator thread failed: {0}")]
    Worker(String),
    #[error("a generator thread failed: {0}")]
    ThreadPool(#[source] rayon::ThreadPoolBuildError),
}

/// Writes the scene described by `kind` into `out_dir` (created if missing;
/// existing files with the same names are overwritten).
pub fn generate(
    kind: &GenKind,
    out_dir: &Path,
    progress: &mut dyn FnMut(GenProgress),
) -> Result<GenSummary, GenError> {
    let _span = tracing::info_span!("gen", kind = kind.name(), dir = %out_dir.display()).entered();
    std::fs::create_dir_all(out_dir).map_err(|source| GenError::Io {
        path: out_dir.to_path_buf(),
        source,
    })?;
    let summary = match kind {
        GenKind::Forest(o) => forest::generate(o, out_dir, progress),
        GenKind::Sphereflake(o) => sphereflake::generate(o, out_dir, progress),
        GenKind::LodGrid(o) => lod_grid::generate(o, out_dir, progress),
        GenKind::Island(o) => island::generate(o, out_dir, progress),
        GenKind::Courtyard(o) => courtyard::generate(o, out_dir, progress),
    }?;
    tracing::info!(
        files = summary.files_written,
        bytes = summary.bytes_written,
        object_instances = summary.object_instances,
        flattened_instances = summary.flattened_instances,
        unique_triangles = summary.unique_triangles,
        instanced_triangles = summary.instanced_triangles,
        "scene generated"
    );
    Ok(summary)
}

#[cfg(test)]
mod tests;
