//! The bytes under a package: a read-only memory map or an owned, 64-byte aligned copy, and
//! the chunk bytes handed out (borrowed from the map, or decompressed and owned).

use std::fmt;
use std::fs::File;
use std::ops::Deref;

use bytemuck::{Pod, Zeroable};

/// A 64-byte aligned block: the unit of owned buffers, so decompressed chunks and
/// [`Package::from_bytes`] copies can be cast to any `Pod` type with alignment <= 64.
#[repr(C, align(64))]
#[derive(Copy, Clone, Pod, Zeroable)]
struct Block([u8; 64]);

/// Owned bytes with 64-byte alignment.
pub struct AlignedBytes {
    blocks: Vec<Block>,
    len: usize,
}

impl AlignedBytes {
    pub(super) fn zeroed(len: usize) -> AlignedBytes {
        let blocks = bytemuck::allocation::zeroed_vec(len.div_ceil(64));
        AlignedBytes { blocks, len }
    }

    pub(super) fn as_mut_slice(&mut self) -> &mut [u8] {
        &mut bytemuck::cast_slice_mut(&mut self.blocks)[..self.len]
    }
}

impl Deref for AlignedBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        &bytemuck::cast_slice(&self.blocks)[..self.len]
    }
}

impl fmt::Debug for AlignedBytes {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "AlignedBytes({} bytes)", self.len)
    }
}

/// A chunk's raw bytes: borrowed from the mapping for raw chunks (zero-copy, page aligned),
/// owned and 64-byte aligned for decompressed ones.
#[derive(Debug)]
pub enum ChunkBytes<'a> {
    Borrowed(&'a [u8]),
    Owned(AlignedBytes),
    /// A decoded chunk shared with the package's cache of them (`Package::chunk_shared`).
    Shared(std::sync::Arc<AlignedBytes>),
}

impl ChunkBytes<'_> {
    /// True when the bytes point into the mapped file.
    pub fn is_borrowed(&self) -> bool {
        matches!(self, ChunkBytes::Borrowed(_))
    }

    /// The bytes at `offset..offset + len` viewed as `T`s (checks bounds and alignment).
    pub fn slice_as<T: Pod>(&self, offset: u64, len_bytes: u64) -> Option<&[T]> {
        let start = usize::try_from(offset).ok()?;
        let end = start.checked_add(usize::try_from(len_bytes).ok()?)?;
        bytemuck::try_cast_slice(self.get(start..end)?).ok()
    }
}

impl Deref for ChunkBytes<'_> {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            ChunkBytes::Borrowed(bytes) => bytes,
            ChunkBytes::Owned(bytes) => bytes,
            ChunkBytes::Shared(bytes) => bytes,
        }
    }
}

pub(super) enum Storage {
    Mapped(memmap2::Mmap),
    Owned(AlignedBytes),
}

impl Storage {
    pub(super) fn bytes(&self) -> &[u8] {
        match self {
            Storage::Mapped(map) => map,
            Storage::Owned(bytes) => bytes,
        }
    }
}

impl Storage {
    /// Maps `file` read-only. This is the crate's one `unsafe` construct. A memory map is only
    /// sound while no one else modifies the file; motu never modifies a package in place
    /// (writers rename a new file over the old, which leaves existing maps intact), but another
    /// program could. What that can cause is bounded: every byte read goes through
    /// bounds-checked, checksummed paths, so a concurrent modification shows up as a checksum
    /// error or as inconsistent bytes, not as out-of-bounds access. Truncating a mapped file
    /// makes later accesses to the lost pages raise SIGBUS; that risk is inherent to mmap and
    /// is accepted (ripgrep does the same).
    pub(super) fn map(file: &File) -> std::io::Result<Storage> {
        // SAFETY: the map is read-only and private to its `Package`; see the doc comment above
        // for why a concurrent writer cannot cause out-of-bounds reads here (all offsets are
        // validated against the mapped length, all contents are checksummed before use).
        let map = unsafe { memmap2::Mmap::map(file) }?;
        Ok(Storage::Mapped(map))
    }
}
