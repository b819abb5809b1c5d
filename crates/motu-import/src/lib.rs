//! The import pipeline as a library: a pbrt or OBJ scene file → a streamed scene (mesh data goes
//! to package chunks as it is parsed) → the compiled traversal hierarchy → a finished package.
//! `motu import`, `motu demo`, `motu bench` and any embedding program call [`import`].

mod compile_report;
mod error;
mod memory;
mod pipeline;
mod split;
mod textures;

pub use error::ImportError;
pub use memory::peak_rss_bytes;
pub use pipeline::{
    element_stats, import, resolve_subset, ImportOptions, ImportProgress, ImportSummary, ProgressFn,
};
pub use textures::DEFAULT_PTEX_MAX;

#[cfg(test)]
mod tests;
