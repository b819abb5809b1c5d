//! The motu scene package container: one file that opens instantly (memory map), validates
//! cheaply, and streams mesh data by chunk.
//!
//! A package is a header, page-aligned *chunks* (opaque blobs the caller fills, stored raw or
//! zstd-compressed, each checksummed), *sections* (named, typed tables such as nodes or
//! materials), a footer manifest (chunk directory and section table) and a fixed trailer.
//! `FORMAT.md` at the repository root specifies every byte. This crate decides nothing about
//! what the chunks and sections contain; the compiler does.
//!
//! ```no_run
//! use motu_package::{Package, PackageWriter, SectionKind, WriterOptions};
//! # fn main() -> Result<(), motu_package::PackageError> {
//! let mut writer = PackageWriter::create("scene.motu", WriterOptions::default())?;
//! let mut chunks = writer.chunk_writer(/* tag */ 0, /* group */ 0);
//! let vertices = chunks.append(&[0u8; 1024], 16)?; // a Locator: chunk id + offset
//! chunks.close()?;
//! writer.add_section_slice(SectionKind(1), "nodes", &[1u32, 2, 3])?;
//! writer.finish()?;
//!
//! let package = Package::open("scene.motu")?;
//! let nodes: &[u32] = package.section_as(SectionKind(1))?;
//! let chunk = package.chunk(vertices.chunk)?; // borrowed from the map when raw
//! # Ok(()) }
//! ```
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! The package container: header, page-aligned chunks (raw or zstd, xxh3 each), sections, footer
//! manifest, trailer; mmap reader validating in O(manifest); atomic writer (temp + fsync + rename;
//! `AtomicDir` for a directory written whole), the input check before opening
//! (`identity::check_input`). Knows nothing of scenes.
//!
//! Key types: `PackageWriter`, `Package`, `verify`.

pub mod atomic;
mod error;
pub mod format;
pub mod identity;
mod reader;
mod sink;
mod writer;

pub use error::{FormatVersion, PackageError, Part};
pub use format::Codec;
pub use reader::{
    AlignedBytes, ChunkBytes, ChunkInfo, Package, SectionInfo, VerifyReport, DECODED_CACHE_BYTES,
};
pub use writer::{
    ChunkWriter, Locator, PackageWriter, SectionWriter, StreamId, WriteSummary, WriterOptions,
    DEFAULT_TARGET_CHUNK_BYTES,
};

/// Index of a chunk in the package's chunk directory.
#[derive(Copy, Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ChunkId(pub u32);

/// Caller-defined id of a section type (the compiler assigns them; unique within a package).
#[derive(Copy, Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct SectionKind(pub u32);
