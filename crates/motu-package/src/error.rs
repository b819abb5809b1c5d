//! Errors of the package reader and writer.

use std::fmt;
use std::path::PathBuf;

use crate::{ChunkId, SectionKind};

/// Which part of a package an error is about. Displays as `header`, `chunk 17`,
/// `section nodes`, ... so messages read naturally.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Part {
    /// The file as a whole (too short, wrong length).
    File,
    /// The fixed header at offset 0.
    Header,
    /// The fixed trailer at the end of the file.
    Trailer,
    /// The footer manifest (chunk directory, section table, names).
    Manifest,
    /// One chunk's directory entry or bytes.
    Chunk(ChunkId),
    /// One section's table entry or bytes.
    Section { kind: SectionKind, name: String },
    /// Bytes between two parts that must be zero, starting at this file offset.
    Padding { offset: u64 },
}

impl fmt::Display for Part {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Part::File => f.write_str("file"),
            Part::Header => f.write_str("header"),
            Part::Trailer => f.write_str("trailer"),
            Part::Manifest => f.write_str("manifest"),
            Part::Chunk(id) => write!(f, "chunk {}", id.0),
            Part::Section { kind, name } if name.is_empty() => write!(f, "section #{}", kind.0),
            Part::Section { name, .. } => write!(f, "section {name}"),
            Part::Padding { offset } => write!(f, "padding at byte {offset}"),
        }
    }
}

/// A package format version: readers accept files of their own major and any minor.
#[derive(Copy, Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FormatVersion {
    pub major: u16,
    pub minor: u16,
}

impl fmt::Display for FormatVersion {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}", self.major, self.minor)
    }
}

/// Everything that can go wrong reading or writing a package.
#[derive(Debug, thiserror::Error)]
pub enum PackageError {
    /// An operating-system error on `path`.
    #[error("{action} {}: {source}", path.display())]
    Io {
        action: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The file is damaged, truncated, or not a motu package.
    #[error("corrupt package ({part}): {reason}")]
    Corrupt { part: Part, reason: String },
    /// The file was written by an incompatible format version.
    #[error(
        "package format version {found} is not supported (this build reads {}.x); \
         re-import the scene with this build of motu",
        supported.major
    )]
    Version {
        found: FormatVersion,
        supported: FormatVersion,
    },
    /// The file needs features (required-feature bits) this reader does not know.
    #[error("package needs unknown features (required-feature bits {bits:#x}); use a newer motu")]
    UnsupportedFeatures { bits: u64 },
    /// A chunk id past the end of the chunk directory.
    #[error("no chunk {} in this package (it has {count})", id.0)]
    NoSuchChunk { id: ChunkId, count: u32 },
    /// No section of this kind in the package.
    #[error("no section of kind {} in this package", kind.0)]
    NoSuchSection { kind: SectionKind },
    /// The section exists but cannot be viewed as the requested element type.
    #[error("section {name} (kind {}) cannot be read as {type_name}: {reason}", kind.0)]
    SectionType {
        kind: SectionKind,
        name: String,
        type_name: &'static str,
        reason: String,
    },
    /// The section's bytes cannot be viewed as the requested type (length or alignment).
    /// `cast` is bytemuck's reason, kept typed (bytemuck implements `Error` only with a
    /// feature this workspace does not enable, so it cannot be the `source`).
    #[error("section {name} (kind {}) cannot be read as {type_name}: {cast}", kind.0)]
    SectionCast {
        kind: SectionKind,
        name: String,
        type_name: &'static str,
        cast: bytemuck::PodCastError,
    },
    /// The writer was used wrongly (caller bug or option out of range).
    #[error("invalid package writer use: {0}")]
    InvalidArgument(String),
}

impl PackageError {
    pub(crate) fn corrupt(part: Part, reason: impl Into<String>) -> PackageError {
        PackageError::Corrupt {
            part,
            reason: reason.into(),
        }
    }

    pub(crate) fn io(
        action: &'static str,
        path: impl Into<PathBuf>,
        source: std::io::Error,
    ) -> Self {
        PackageError::Io {
            action,
            path: path.into(),
            source,
        }
    }
}

#[cfg(test)]
mod tests;
