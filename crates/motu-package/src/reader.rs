//! Package reader: instant open over a memory map, lazy per-chunk validation, full `verify`.
//! By job: [`storage`] (the mapped or owned bytes), [`manifest`] (open-time validation),
//! [`decode`] (checksums and zstd), [`verify`] (the full pass); this file holds [`Package`]
//! and its reads.

mod decode;
mod decoded;
mod manifest;
mod storage;
mod verify;

use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use bytemuck::Pod;

use crate::format::Codec;
use crate::{ChunkId, FormatVersion, PackageError, SectionKind};

use decode::{check_chunk_checksum, check_section_checksum, decode_chunk, decompress_exact};
pub use decoded::DECODED_CACHE_BYTES;
use manifest::check_min_len;
pub use manifest::{ChunkInfo, SectionInfo};
use storage::Storage;
pub use storage::{AlignedBytes, ChunkBytes};
pub use verify::VerifyReport;

/// An open package. `Sync`: chunks can be read from many threads.
pub struct Package {
    storage: Storage,
    path: Option<PathBuf>,
    version: FormatVersion,
    optional_features: u64,
    manifest_offset: u64,
    manifest_len: u64,
    chunks: Vec<ChunkInfo>,
    sections: Vec<SectionInfo>,
    /// Bit `i` set once chunk `i`'s checksum has matched.
    chunk_verified: Vec<AtomicU64>,
    section_verified: Vec<AtomicU64>,
    /// Recently decoded zstd chunks ([`Package::chunk_shared`]) and the decode count.
    decoded: decoded::DecodedChunks,
    /// First-touch chunk checksums run by reads, and their stored bytes
    /// ([`Package::chunk_checks`]).
    chunk_checks: [AtomicU64; 2],
}

impl fmt::Debug for Package {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Package")
            .field("path", &self.path)
            .field("file_bytes", &self.file_bytes())
            .field("version", &self.version)
            .field("chunks", &self.chunks.len())
            .field("sections", &self.sections.len())
            .finish()
    }
}

impl Package {
    /// Maps `path` and validates header, trailer and manifest in O(manifest) without touching
    /// chunk or section bytes. What a memory map risks, and why it is accepted, is on
    /// [`Storage::map`].
    pub fn open(path: impl AsRef<Path>) -> Result<Package, PackageError> {
        let path = path.as_ref();
        let span = tracing::info_span!("package_open", path = %path.display());
        let _entered = span.enter();
        // A FIFO, device, directory or symlink loop is named as such, never opened or mapped.
        let (file, len) = crate::identity::open_input(path, None)
            .map_err(|e| PackageError::io("open", path, e))?;
        check_min_len(len)?;
        let storage = Storage::map(&file).map_err(|e| PackageError::io("memory-map", path, e))?;
        let mut package = Package::parse(storage)?;
        package.path = Some(path.to_path_buf());
        tracing::debug!(
            file_bytes = package.file_bytes(),
            chunks = package.chunks.len(),
            sections = package.sections.len(),
            "package opened"
        );
        Ok(package)
    }

    /// A package from bytes in memory (copied into an aligned buffer): for tests, fuzzing and
    /// packages received over a network.
    pub fn from_bytes(bytes: &[u8]) -> Result<Package, PackageError> {
        check_min_len(bytes.len() as u64)?;
        let mut owned = AlignedBytes::zeroed(bytes.len());
        owned.as_mut_slice().copy_from_slice(bytes);
        Package::parse(Storage::Owned(owned))
    }

    /// The path this package was opened from.
    pub fn path(&self) -> Option<&Path> {
        self.path.as_deref()
    }

    /// Size of the package file.
    pub fn file_bytes(&self) -> u64 {
        self.storage.bytes().len() as u64
    }

    /// Format version the file was written with.
    pub fn format_version(&self) -> FormatVersion {
        self.version
    }

    /// Optional-feature bits of the file (readers may ignore unknown ones).
    pub fn optional_features(&self) -> u64 {
        self.optional_features
    }

    /// Number of chunks; ids are `0..chunk_count()`.
    pub fn chunk_count(&self) -> u32 {
        self.chunks.len() as u32
    }

    /// The chunk directory.
    pub fn chunks(&self) -> &[ChunkInfo] {
        &self.chunks
    }

    /// One chunk's directory entry.
    pub fn chunk_info(&self, id: ChunkId) -> Result<&ChunkInfo, PackageError> {
        self.chunks
            .get(id.0 as usize)
            .ok_or(PackageError::NoSuchChunk {
                id,
                count: self.chunk_count(),
            })
    }

    /// A chunk's raw bytes: zero-copy for raw chunks, decompressed for zstd ones. The stored
    /// bytes' checksum is checked on the first access to each chunk only.
    pub fn chunk(&self, id: ChunkId) -> Result<ChunkBytes<'_>, PackageError> {
        let info = *self.chunk_info(id)?;
        let stored = self.range(info.offset, info.stored_len);
        if !is_set(&self.chunk_verified, id.0 as usize) {
            check_chunk_checksum(&info, stored)?;
            set(&self.chunk_verified, id.0 as usize);
            self.chunk_checks[0].fetch_add(1, Ordering::Relaxed);
            self.chunk_checks[1].fetch_add(info.stored_len, Ordering::Relaxed);
        }
        if info.codec == Codec::Zstd {
            self.decoded.counted();
        }
        decode_chunk(&info, stored)
    }

    /// [`chunk`](Self::chunk), but a zstd chunk is decoded once and shared while it stays among
    /// the recently decoded ([`DECODED_CACHE_BYTES`]): for readers that take many small pieces
    /// of one chunk (a streamed build group's meshes), from many threads.
    pub fn chunk_shared(&self, id: ChunkId) -> Result<ChunkBytes<'_>, PackageError> {
        let info = *self.chunk_info(id)?;
        if info.codec != Codec::Zstd {
            return self.chunk(id);
        }
        let stored = self.chunk_stored(id)?;
        let bytes = self.decoded.get_or_decode(id.0, info.raw_len, || {
            let mut raw = AlignedBytes::zeroed(info.raw_len as usize);
            decompress_exact(&info, stored, raw.as_mut_slice())?;
            Ok(raw)
        })?;
        Ok(ChunkBytes::Shared(bytes))
    }

    /// First-touch chunk checksums reads ran so far, and the stored bytes they read (a chunk
    /// is checked whole, however little of it a read wants).
    pub fn chunk_checks(&self) -> (u64, u64) {
        (
            self.chunk_checks[0].load(Ordering::Relaxed),
            self.chunk_checks[1].load(Ordering::Relaxed),
        )
    }

    /// Chunks decompressed so far by [`chunk`](Self::chunk) and
    /// [`chunk_shared`](Self::chunk_shared) (the latter's reuses not counted).
    pub fn chunk_decodes(&self) -> u64 {
        self.decoded.decodes()
    }

    /// Decodes a chunk into `dst` (e.g. a mapped staging buffer), avoiding the allocation of
    /// [`chunk`](Self::chunk) for zstd chunks; returns the raw length. `dst` must hold at
    /// least `raw_len` bytes.
    pub fn read_chunk_into(&self, id: ChunkId, dst: &mut [u8]) -> Result<usize, PackageError> {
        let info = *self.chunk_info(id)?;
        let raw_len = info.raw_len as usize;
        if dst.len() < raw_len {
            return Err(PackageError::InvalidArgument(format!(
                "destination holds {} bytes, chunk {} needs {raw_len}",
                dst.len(),
                id.0
            )));
        }
        let stored = self.chunk_stored(id)?;
        let dst = &mut dst[..raw_len];
        match info.codec {
            Codec::Raw => dst.copy_from_slice(stored),
            Codec::Zstd => {
                self.decoded.counted();
                decompress_exact(&info, stored, dst)?
            }
        }
        Ok(raw_len)
    }

    /// The chunk's stored bytes as they lie in the file (compressed for zstd chunks), after
    /// the first-touch checksum: for callers that decompress on their own path (e.g. GPU).
    pub fn chunk_stored(&self, id: ChunkId) -> Result<&[u8], PackageError> {
        let info = *self.chunk_info(id)?;
        let stored = self.range(info.offset, info.stored_len);
        if !is_set(&self.chunk_verified, id.0 as usize) {
            check_chunk_checksum(&info, stored)?;
            set(&self.chunk_verified, id.0 as usize);
            self.chunk_checks[0].fetch_add(1, Ordering::Relaxed);
            self.chunk_checks[1].fetch_add(info.stored_len, Ordering::Relaxed);
        }
        Ok(stored)
    }

    /// Hints the OS to start reading a chunk's pages (streaming prefetch); a no-op where
    /// unsupported or for in-memory packages.
    pub fn prefetch_chunk(&self, id: ChunkId) -> Result<(), PackageError> {
        let info = *self.chunk_info(id)?;
        #[cfg(unix)]
        if let Storage::Mapped(map) = &self.storage {
            if info.stored_len > 0 {
                // Advice only; failure changes nothing observable.
                let _ = map.advise_range(
                    memmap2::Advice::WillNeed,
                    info.offset as usize,
                    info.stored_len as usize,
                );
            }
        }
        let _ = info;
        Ok(())
    }

    /// The section table.
    pub fn sections(&self) -> &[SectionInfo] {
        &self.sections
    }

    /// The table entry of the section of `kind`, if present.
    pub fn section_info(&self, kind: SectionKind) -> Option<&SectionInfo> {
        self.sections.iter().find(|s| s.kind == kind)
    }

    /// A section's bytes (checksum checked on first access; 64-byte aligned).
    pub fn section_bytes(&self, kind: SectionKind) -> Result<&[u8], PackageError> {
        let index = self
            .sections
            .iter()
            .position(|s| s.kind == kind)
            .ok_or(PackageError::NoSuchSection { kind })?;
        let info = &self.sections[index];
        let bytes = self.range(info.offset, info.len_bytes);
        if !is_set(&self.section_verified, index) {
            check_section_checksum(info, bytes)?;
            set(&self.section_verified, index);
        }
        Ok(bytes)
    }

    /// A section viewed as a slice of `T`: checks that `T`'s size is the stored element size
    /// and that the data is aligned for `T`.
    pub fn section_as<T: Pod>(&self, kind: SectionKind) -> Result<&[T], PackageError> {
        let bytes = self.section_bytes(kind)?;
        let info = self
            .section_info(kind)
            .ok_or(PackageError::NoSuchSection { kind })?;
        let type_error = |reason: String| PackageError::SectionType {
            kind,
            name: info.name.clone(),
            type_name: std::any::type_name::<T>(),
            reason,
        };
        if size_of::<T>() != info.element_size as usize {
            return Err(type_error(format!(
                "element size is {} bytes, the type has {}",
                info.element_size,
                size_of::<T>()
            )));
        }
        bytemuck::try_cast_slice(bytes).map_err(|cast| PackageError::SectionCast {
            kind,
            name: info.name.clone(),
            type_name: std::any::type_name::<T>(),
            cast,
        })
    }

    /// Bytes at a range that `parse` validated against the file length.
    fn range(&self, offset: u64, len: u64) -> &[u8] {
        &self.storage.bytes()[offset as usize..(offset + len) as usize]
    }
}

fn bitset(len: usize) -> Vec<AtomicU64> {
    (0..len.div_ceil(64)).map(|_| AtomicU64::new(0)).collect()
}

fn is_set(bits: &[AtomicU64], index: usize) -> bool {
    // Acquire pairs with the Release in `set`: a set bit means a completed check.
    bits[index / 64].load(Ordering::Acquire) & (1 << (index % 64)) != 0
}

fn set(bits: &[AtomicU64], index: usize) {
    bits[index / 64].fetch_or(1 << (index % 64), Ordering::Release);
}

#[cfg(test)]
mod tests;
