//! The import pipeline as a library: a pbrt or OBJ scene file → a streamed scene (mesh data goes
//! to package chunks as it is parsed) → the compiled traversal hierarchy → a finished package.
//! `motu import`, `motu demo`, `motu bench` and any embedding program call [`import`].
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! The import pipeline as a library (what `motu import`, `demo` and `bench` call): checks the scene
//! path, streams the scene into package chunks (a scratch package for `--subset`; meshes over the
//! BLAS bound are cut into clusters as they are stored once the bound is known, `precut.rs`;
//! before that, with the automatic bound, meshes over its least value go to a spill file until
//! 2^16 × 128 triangles were stored, when the bound is known to be 2^16: the spilled ones over
//! it are cut then, and those kept whole are copied into the package after compiling), refuses
//! an output the scene read, compiles (per-phase times:
//! `CompilePhases`), stores LOD meshes and clusters on a writer thread as they are made, loads
//! textures (`textures.rs`: image mip chains and Ptex faces with their meshes' face tables, written
//! to the texel store a batch at a time), makes and stores the stream split (`split.rs`, for `motu
//! report`) and the boxes inside triangle BLASes (`proxy_boxes.rs`, for streamed starts; a chunk
//! read once each), writes meta and finishes the package atomically; per-element statistics; peak RSS.
//!
//! Key types: `import`, `ImportOptions`, `ImportSummary`, `ImportError`, `ImportProgress`,
//! `resolve_subset`, `element_stats`, `peak_rss_bytes`.

mod compile_report;
mod error;
mod memory;
mod pipeline;
mod precut;
mod proxy_boxes;
mod split;
mod textures;

pub use error::ImportError;
pub use memory::{cap_malloc_arenas, peak_rss_bytes, IMPORT_MALLOC_ARENAS};
pub use pipeline::{
    element_stats, import, resolve_subset, ImportOptions, ImportProgress, ImportSummary, ProgressFn,
};
pub use precut::DEFAULT_CUT_QUEUE_BYTES;
pub use proxy_boxes::DEFAULT_PROXY_READBACK_BYTES;
pub use textures::DEFAULT_PTEX_MAX;

#[cfg(test)]
mod tests;
