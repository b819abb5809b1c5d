//! Streaming pbrt-v3/pbrt-v4 scene parser.
//!
//! `pbrt-import` reads pbrt scene text (memory-mapped, or `.gz`), resolves the
//! graphics state (transforms, materials, area lights, named coordinate systems,
//! object definitions) and hands the result to a caller-implemented
//! [`SceneSink`], one event at a time. Mesh data is never accumulated: each
//! [`ShapeEvent`] owns its geometry and is moved into the sink.
//!
//! ```no_run
//! use pbrt_import::{parse_file, CollectSink, ParseOptions};
//! let mut sink = CollectSink::default();
//! let stats = parse_file("scene.pbrt".as_ref(), &ParseOptions::default(), &mut sink)?;
//! println!("{} shapes, {} instances", stats.shapes, stats.instances);
//! # Ok::<(), pbrt_import::Error>(())
//! ```
//!
//! Depends on no other motu crate; an adapter maps events into the scene model.
//!
//! Paths in `Include`, `Import`, `plymesh` and spectrum files resolve relative to
//! the including file's directory first, then to the entry file's directory (what
//! pbrt itself does), so both layouts found in published scenes work.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! pbrt-v3/v4 tokenizer (zero-copy over mmap, `.gz`), parser with each version's semantics, PLY
//! reader (`ply.rs`: the API and mesh assembly; `ply/` the `header`, the `body` item reader, the
//! `write`r), a small pbrt writer. Streams [`SceneSink`] events; never accumulates mesh data.
//! `parser.rs` is the state and the directive dispatch; `parser/` holds one file per job (`args`,
//! `graphics`, `materials`, `shape`, `objects`, `includes`); `prescan.rs` the byte scanners the
//! parser and the parallel include workers (`parallel.rs`) share; `moana_json/` reads Moana's
//! JSON+OBJ base package into the same events (`json.rs` a pull reader over the mapped bytes, so
//! gigabyte archive and curve files stream in constant memory; `obj.rs` the OBJ subset; `moana_json.rs`
//! elements, copies, archives, curves, materials, cameras, lights in pbrt's document order).
//! **Depends on no workspace crate.**.
//!
//! Key types: `parse_file`, `SceneSink`, `ShapeEvent`, `Error` (file:line:column).

mod color;
mod error;
mod events;
pub mod lexer;
mod math;
pub mod moana_json;
mod parallel;
pub mod params;
mod parser;
pub mod ply;
mod prescan;
mod shapes;
mod source;
pub mod writer;

use std::path::{Path, PathBuf};

pub use error::{Error, Location, MissingFile, ParseError, ParseErrorKind, PlyError, SinkError};
pub use events::{
    AreaLight, CameraEvent, CollectSink, Curve, FileEvent, Geometry, InstanceEvent, LightEvent,
    Material, Mesh, ObjectEvent, SceneSink, ShapeEvent, Via, Warning, FACE_SECOND_HALF,
};
pub use lexer::Loc;
pub use math::Mat4;
pub use source::{check_input, classify, FileKind, SourceBytes};

/// Index of an input file in [`ParseStats::files`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct FileId(pub u32);

/// An object (`ObjectBegin` name), unique per definition.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ObjectId(pub u32);

/// A material; `MaterialId(0)` is the default material.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct MaterialId(pub u32);

/// An element: a file included from the entry file's world block, named by its stem.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ElementId(pub u32);

/// pbrt scene format version.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PbrtVersion {
    /// pbrt-v3.
    V3,
    /// pbrt-v4.
    V4,
}

/// Which version's semantics to apply.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum VersionOption {
    /// Start with pbrt-v3 semantics and switch to pbrt-v4 for the rest of the parse at the
    /// first v4-only construct (`Import`, `ColorSpace`, `Option`, `Attribute`, v4 type
    /// spellings such as `point3`, v4 material/film names). The entry file is pre-scanned.
    #[default]
    Auto,
    /// Force pbrt-v3.
    V3,
    /// Force pbrt-v4.
    V4,
}

/// How `plymesh` files are loaded.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyLoading {
    /// Load each PLY when its `Shape` is parsed; all events in document order.
    Sequential,
    /// Queue PLY shapes and load a batch in parallel (rayon) once the queued files
    /// reach `batch_bytes` (and at the end). PLY shapes then arrive after later
    /// events; [`ShapeEvent::seq`] gives their document order.
    Parallel {
        /// Queued PLY bytes that trigger a batch load (bounds memory).
        batch_bytes: u64,
    },
}

impl Default for PlyLoading {
    fn default() -> Self {
        PlyLoading::Parallel {
            batch_bytes: 256 << 20,
        }
    }
}

/// Parse options.
#[derive(Clone, Debug)]
pub struct ParseOptions {
    /// Version semantics.
    pub version: VersionOption,
    /// Missing `Include`/`Import`/PLY files become warnings and are skipped.
    /// Otherwise the parse fails with [`Error::MissingFiles`] listing all of them.
    pub allow_missing: bool,
    /// PLY loading strategy.
    pub ply_loading: PlyLoading,
    /// Segments around the axis for tessellated spheres, disks and cylinders (>= 3).
    pub tessellation_segments: u32,
    /// Maximum `Include`/`Import` nesting (guards against cycles and stack overflow).
    pub max_include_depth: u32,
    /// Turn a file that one file includes (or imports) several times into a shared object
    /// instead of a copy per inclusion (Moana places element copies this way).
    ///
    /// When on, the first inclusion of such a file emits `object_begin` for a synthesized
    /// object (named by the file's stem, not reachable by `ObjectInstance`), the file's
    /// shapes and instances in the include's frame (`parent_from_shape` relative to the CTM
    /// at the `Include`), `object_end`, then an `object_instance` with the CTM at the
    /// `Include` as `parent_from_instance`; each later inclusion emits only another
    /// `object_instance` and is not read again. Flattening gives the same world-space
    /// geometry as re-parsing. Only files that cannot leak or depend on other state qualify
    /// (only shapes, instances and, inside balanced blocks, relative transforms and
    /// materials), and only inclusions in the world block, outside object definitions,
    /// without motion or area light, under the same material and orientation as the
    /// first; everything else is parsed as before. Known limit: a named material or object
    /// redefined (pbrt-v3) between two inclusions keeps its first meaning for the copies.
    pub share_repeated_includes: bool,
    /// Parse *state-neutral* `Include`d/`Import`ed files on the rayon pool (when it has
    /// more than one thread) and replay their events in document order, so sinks see
    /// exactly the events of a sequential parse. A file qualifies when, included in the
    /// world block outside object definitions and motion, it only places shapes
    /// (`trianglemesh`, `loopsubdiv`, quadrics, `curve`, v4 `bilinearmesh`) and
    /// `ObjectInstance`s, with transforms and `ReverseOrientation` only inside balanced
    /// blocks (Moana's and `motu gen island`'s placement files); anything else, and any
    /// error, is parsed sequentially (same messages and positions). Runs of consecutive
    /// includes are processed as a sliding window of 4 pieces of input per pool thread (16 to
    /// 32 pieces: 64 to 128 MiB at the default pieces, whatever the thread count); files are cut into pieces of about [`ParseOptions::parallel_chunk_bytes`] at
    /// directive lines, one worker each; files over 128 MiB (and `.gz`) are parsed sequentially.
    pub parallel_includes: bool,
    /// Target size of the pieces a file is cut into for [`ParseOptions::parallel_includes`].
    pub parallel_chunk_bytes: usize,
}

impl Default for ParseOptions {
    fn default() -> Self {
        ParseOptions {
            version: VersionOption::Auto,
            allow_missing: false,
            ply_loading: PlyLoading::default(),
            tessellation_segments: 32,
            max_include_depth: 64,
            share_repeated_includes: false,
            parallel_includes: true,
            parallel_chunk_bytes: 4 << 20,
        }
    }
}

/// Counts from one parse.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParseStats {
    /// Version whose semantics were in effect at the end.
    pub version: Option<PbrtVersion>,
    /// Files read; index = [`FileId`]. PLY files are not included.
    pub files: Vec<PathBuf>,
    /// Bytes of scene text read (decompressed).
    pub text_bytes: u64,
    /// Bytes of PLY files read.
    pub ply_bytes: u64,
    /// Shape events delivered (including unsupported).
    pub shapes: u64,
    /// Triangles across all mesh shapes.
    pub triangles: u64,
    /// `curve` shapes.
    pub curves: u64,
    /// Shapes of unsupported types.
    pub unsupported_shapes: u64,
    /// Shapes skipped (missing file with `allow_missing`, invalid data).
    pub skipped_shapes: u64,
    /// `ObjectBegin` definitions.
    pub objects: u64,
    /// `ObjectInstance` directives.
    pub instances: u64,
    /// Cameras.
    pub cameras: u64,
    /// Light sources (not counting area lights).
    pub lights: u64,
    /// Warnings emitted.
    pub warnings: u64,
    /// Files turned into shared objects ([`ParseOptions::share_repeated_includes`]).
    pub shared_includes: u64,
    /// Inclusions placed as instances of a shared object (first inclusions included).
    pub include_instances: u64,
    /// Included files whose events came from a worker thread
    /// ([`ParseOptions::parallel_includes`]).
    pub parallel_files: u64,
    /// The most input bytes a parallel include run held in its window at once (files admitted,
    /// not yet replayed); 0 without parallel runs.
    pub parallel_window_peak_bytes: u64,
    /// Missing files (only non-empty with `allow_missing`).
    pub missing: Vec<MissingFile>,
}

impl ParseStats {
    /// Path of a file id.
    pub fn path(&self, file: FileId) -> Option<&Path> {
        self.files.get(file.0 as usize).map(PathBuf::as_path)
    }
}

/// Parse the scene starting at `path`, streaming it into `sink`.
pub fn parse_file(
    path: &Path,
    options: &ParseOptions,
    sink: &mut dyn SceneSink,
) -> Result<ParseStats, Error> {
    parser::parse_entry(parser::Entry::Path(path), options, sink)
}

/// Parse scene text held in memory; relative paths resolve against `base_dir`.
pub fn parse_str(
    text: &str,
    base_dir: &Path,
    options: &ParseOptions,
    sink: &mut dyn SceneSink,
) -> Result<ParseStats, Error> {
    parser::parse_entry(
        parser::Entry::Text {
            text: text.as_bytes(),
            base_dir,
        },
        options,
        sink,
    )
}

/// Parse scene bytes held in memory; relative paths resolve against `base_dir`.
pub fn parse_bytes(
    bytes: &[u8],
    base_dir: &Path,
    options: &ParseOptions,
    sink: &mut dyn SceneSink,
) -> Result<ParseStats, Error> {
    parser::parse_entry(
        parser::Entry::Text {
            text: bytes,
            base_dir,
        },
        options,
        sink,
    )
}

#[cfg(test)]
mod tests;
