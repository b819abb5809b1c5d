//! On-disk structures of the package container. `FORMAT.md` at the repository root is the
//! byte-by-byte specification; every constant and struct here is named there.
//!
//! All structs are `#[repr(C)]`, little-endian on disk, free of implicit padding and read
//! through `bytemuck` (`pod_read_unaligned`), so a corrupt file can never produce an invalid
//! value, only a value that validation rejects.

use bytemuck::{Pod, Zeroable};

/// First 8 bytes of every package.
pub const HEADER_MAGIC: [u8; 8] = *b"MOTUPKG\0";
/// Last 8 bytes of every package.
pub const TRAILER_MAGIC: [u8; 8] = *b"MOTUEND\0";

/// Major format version written by this crate. Readers accept only their own major.
pub const FORMAT_MAJOR: u16 = 1;
/// Minor format version written by this crate. Readers accept any minor of their major.
pub const FORMAT_MINOR: u16 = 0;

/// Chunks start at multiples of this (file offset, hence also mapped address: mmaps are page
/// aligned). 4096 is the x86-64/aarch64 base page and satisfies every GPU upload alignment.
pub const CHUNK_ALIGN: u64 = 4096;
/// Section data starts at multiples of this, so `section_as::<T>` works for any `T` with
/// `align_of::<T>() <= 64` (cache line; covers SIMD-aligned `glam` types).
pub const SECTION_ALIGN: u64 = 64;
/// The manifest and the trailer start at multiples of this.
pub const MANIFEST_ALIGN: u64 = 8;

/// Largest raw (decompressed) chunk the format allows: bounds the allocation a reader makes
/// for a compressed chunk whatever the file says.
pub const MAX_CHUNK_BYTES: u64 = 1 << 30;

/// Size of [`Header`] on disk.
pub const HEADER_LEN: u64 = 64;
/// Size of [`Trailer`] on disk.
pub const TRAILER_LEN: u64 = 48;
/// Size of [`ManifestHeader`] on disk.
pub const MANIFEST_HEADER_LEN: u64 = 32;
/// Size of one [`ChunkEntry`] on disk.
pub const CHUNK_ENTRY_LEN: u64 = 48;
/// Size of one [`SectionEntry`] on disk.
pub const SECTION_ENTRY_LEN: u64 = 48;

/// Bytes of the header covered by `Header::checksum`.
pub const HEADER_CHECKSUMMED_LEN: usize = 56;
/// Bytes of the trailer covered by `Trailer::checksum`.
pub const TRAILER_CHECKSUMMED_LEN: usize = 32;

/// How a chunk's stored bytes encode its raw bytes.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub enum Codec {
    /// Stored bytes are the raw bytes: zero-copy from the mapping.
    Raw,
    /// Stored bytes are one or more zstd frames that decompress to exactly `raw_len` bytes.
    Zstd,
}

impl Codec {
    /// The codec id stored in [`ChunkEntry::codec`].
    pub const fn id(self) -> u32 {
        match self {
            Codec::Raw => 0,
            Codec::Zstd => 1,
        }
    }

    /// Codec for a stored id, `None` for ids this reader does not know.
    pub const fn from_id(id: u32) -> Option<Codec> {
        match id {
            0 => Some(Codec::Raw),
            1 => Some(Codec::Zstd),
            _ => None,
        }
    }
}

/// Fixed header at file offset 0, followed by zero padding up to [`CHUNK_ALIGN`].
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct Header {
    pub magic: [u8; 8],
    pub version_major: u16,
    pub version_minor: u16,
    /// Size of this header in bytes (64); lets a later minor grow it.
    pub header_len: u32,
    /// Features a reader must understand; a reader rejects a file with unknown bits set.
    pub required_features: u64,
    /// Features a reader may ignore.
    pub optional_features: u64,
    /// [`CHUNK_ALIGN`] as written; readers reject other values.
    pub chunk_align: u32,
    /// [`SECTION_ALIGN`] as written; readers reject other values.
    pub section_align: u32,
    pub reserved: [u64; 2],
    /// xxh3-64 of header bytes `0..56`.
    pub checksum: u64,
}

/// Fixed trailer: the last [`TRAILER_LEN`] bytes of the file.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct Trailer {
    pub manifest_offset: u64,
    pub manifest_len: u64,
    /// xxh3-64 of the `manifest_len` manifest bytes.
    pub manifest_checksum: u64,
    /// Length of the whole file; catches truncation and appended bytes.
    pub file_len: u64,
    /// xxh3-64 of trailer bytes `0..32`.
    pub checksum: u64,
    pub magic: [u8; 8],
}

/// Start of the manifest.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct ManifestHeader {
    pub chunk_count: u64,
    pub section_count: u64,
    /// Length of the UTF-8 section-name blob that ends the manifest.
    pub names_len: u64,
    pub reserved: u64,
}

/// One chunk directory entry; entry `i` describes `ChunkId(i)`.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct ChunkEntry {
    pub offset: u64,
    pub stored_len: u64,
    pub raw_len: u64,
    /// xxh3-64 of the `stored_len` stored bytes.
    pub checksum: u64,
    pub codec: u32,
    pub tag: u32,
    pub group: u32,
    pub reserved: u32,
}

/// One section table entry.
#[repr(C)]
#[derive(Copy, Clone, Debug, PartialEq, Eq, Pod, Zeroable)]
pub struct SectionEntry {
    pub kind: u32,
    pub element_size: u32,
    pub offset: u64,
    pub len: u64,
    /// xxh3-64 of the `len` section bytes.
    pub checksum: u64,
    /// Byte range of the name within the manifest's name blob.
    pub name_offset: u32,
    pub name_len: u32,
    pub reserved: u64,
}

const _: () = {
    assert!(size_of::<Header>() as u64 == HEADER_LEN);
    assert!(size_of::<Trailer>() as u64 == TRAILER_LEN);
    assert!(size_of::<ManifestHeader>() as u64 == MANIFEST_HEADER_LEN);
    assert!(size_of::<ChunkEntry>() as u64 == CHUNK_ENTRY_LEN);
    assert!(size_of::<SectionEntry>() as u64 == SECTION_ENTRY_LEN);
    assert!(TRAILER_LEN % MANIFEST_ALIGN == 0);
    // The format is little-endian; this crate writes structs with their in-memory bytes.
    assert!(cfg!(target_endian = "little"));
};

/// Checksum used everywhere in the format.
pub fn checksum(bytes: &[u8]) -> u64 {
    xxhash_rust::xxh3::xxh3_64(bytes)
}

/// `value` rounded up to a multiple of `align` (a power of two); `None` on overflow.
pub fn align_up(value: u64, align: u64) -> Option<u64> {
    debug_assert!(align.is_power_of_two());
    Some(value.checked_add(align - 1)? & !(align - 1))
}

impl Header {
    /// The header this crate writes.
    pub fn current() -> Header {
        let mut header = Header {
            magic: HEADER_MAGIC,
            version_major: FORMAT_MAJOR,
            version_minor: FORMAT_MINOR,
            header_len: HEADER_LEN as u32,
            required_features: 0,
            optional_features: 0,
            chunk_align: CHUNK_ALIGN as u32,
            section_align: SECTION_ALIGN as u32,
            reserved: [0; 2],
            checksum: 0,
        };
        header.checksum = checksum(&bytemuck::bytes_of(&header)[..HEADER_CHECKSUMMED_LEN]);
        header
    }
}

impl Trailer {
    /// Computes the checksum of the first 32 bytes.
    pub fn compute_checksum(&self) -> u64 {
        checksum(&bytemuck::bytes_of(self)[..TRAILER_CHECKSUMMED_LEN])
    }
}

#[cfg(test)]
mod tests;
