//! The on-disk entry: where it lives and its header, byte by byte.
//!
//! ```text
//! DIR/v1/ab/<64 hex digits of the key>.as       one entry (ab = the key's first byte)
//! DIR/v1/ab/.<hex>.<pid>.<random>.tmp           an entry being written by process <pid>
//!
//! offset size  field (little-endian)
//!      0    8  magic b"motu-AS\0"
//!      8    4  format version (ENTRY_FORMAT_VERSION = 1)
//!     12    4  header size in bytes (72)
//!     16   32  the key (must equal the file name's)
//!     48    8  blob length in bytes
//!     56    8  XXH3-64 of the blob
//!     64    8  XXH3-64 of bytes 0..64 (a flipped length is corruption, not truncation)
//!     72    …  the blob: Vulkan's serialized structure, starting with its 32-byte header
//! ```
//! A file is exactly `72 + blob length` bytes. A new format goes to a new `vN` directory, so
//! two motu versions sharing a cache directory never read each other's entries.

use std::path::{Path, PathBuf};

use xxhash_rust::xxh3::xxh3_64;

use crate::key::CacheKey;
use crate::stats::WarningReason;

/// The first bytes of every entry.
pub const ENTRY_MAGIC: [u8; 8] = *b"motu-AS\0";
/// The entry format this crate writes and reads.
pub const ENTRY_FORMAT_VERSION: u32 = 1;
/// Bytes before the blob.
pub const ENTRY_HEADER_BYTES: usize = 72;
/// The directory under the cache directory that holds this format's entries.
pub const VERSION_DIR: &str = "v1";
/// The extension of an entry's file.
pub const ENTRY_EXTENSION: &str = "as";
/// The suffix of a temp file.
pub const TEMP_SUFFIX: &str = ".tmp";

/// What an entry's header says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct EntryHeader {
    pub key: CacheKey,
    pub blob_bytes: u64,
    pub blob_xxh3: u64,
}

/// Why an entry cannot be used; each maps to a [`WarningReason`].
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum EntryError {
    #[error("bad magic {0:02x?} (not a motu cache entry)")]
    Magic([u8; 8]),
    #[error("entry format {found}, header size {header_bytes}; this motu reads format {ENTRY_FORMAT_VERSION}")]
    Version { found: u32, header_bytes: u32 },
    #[error("header checksum {stored:016x} does not match its bytes ({computed:016x})")]
    HeaderChecksum { stored: u64, computed: u64 },
    #[error("the header names key {found}, the file name another")]
    Foreign { found: CacheKey },
    #[error("{file_bytes} bytes, the header says {expected_bytes}")]
    Truncated {
        file_bytes: u64,
        expected_bytes: u64,
    },
    #[error("{file_bytes} bytes, the header says {expected_bytes} (trailing bytes)")]
    Trailing {
        file_bytes: u64,
        expected_bytes: u64,
    },
    #[error("blob checksum {stored:016x} does not match its bytes ({computed:016x})")]
    BlobChecksum { stored: u64, computed: u64 },
    #[error("the blob's {0} bytes hold no serialization header")]
    NoSerializationHeader(u64),
    #[error("the device cannot use it (serialized by another driver or device)")]
    Incompatible,
}

impl EntryError {
    /// The warning this counts as.
    pub fn reason(&self) -> WarningReason {
        match self {
            EntryError::Magic(_)
            | EntryError::Version { .. }
            | EntryError::HeaderChecksum { .. }
            | EntryError::Trailing { .. }
            | EntryError::BlobChecksum { .. }
            | EntryError::NoSerializationHeader(_) => WarningReason::Corrupt,
            EntryError::Truncated { .. } => WarningReason::Truncated,
            EntryError::Foreign { .. } => WarningReason::Foreign,
            EntryError::Incompatible => WarningReason::Incompatible,
        }
    }
}

/// The header of an entry holding `blob` under `key`.
pub fn encode_header(key: &CacheKey, blob: &[u8]) -> [u8; ENTRY_HEADER_BYTES] {
    let mut h = [0u8; ENTRY_HEADER_BYTES];
    h[0..8].copy_from_slice(&ENTRY_MAGIC);
    h[8..12].copy_from_slice(&ENTRY_FORMAT_VERSION.to_le_bytes());
    h[12..16].copy_from_slice(&(ENTRY_HEADER_BYTES as u32).to_le_bytes());
    h[16..48].copy_from_slice(&key.0);
    h[48..56].copy_from_slice(&(blob.len() as u64).to_le_bytes());
    h[56..64].copy_from_slice(&xxh3_64(blob).to_le_bytes());
    let header_xxh3 = xxh3_64(&h[..64]);
    h[64..72].copy_from_slice(&header_xxh3.to_le_bytes());
    h
}

fn u32_at(h: &[u8], at: usize) -> u32 {
    let mut b = [0u8; 4];
    b.copy_from_slice(&h[at..at + 4]);
    u32::from_le_bytes(b)
}

fn u64_at(h: &[u8], at: usize) -> u64 {
    let mut b = [0u8; 8];
    b.copy_from_slice(&h[at..at + 8]);
    u64::from_le_bytes(b)
}

/// Checks a header read from the file of `expected` whose length is `file_bytes`.
pub fn decode_header(
    h: &[u8; ENTRY_HEADER_BYTES],
    expected: &CacheKey,
    file_bytes: u64,
) -> Result<EntryHeader, EntryError> {
    let mut magic = [0u8; 8];
    magic.copy_from_slice(&h[0..8]);
    if magic != ENTRY_MAGIC {
        return Err(EntryError::Magic(magic));
    }
    let (version, header_bytes) = (u32_at(h, 8), u32_at(h, 12));
    if version != ENTRY_FORMAT_VERSION || header_bytes as usize != ENTRY_HEADER_BYTES {
        return Err(EntryError::Version {
            found: version,
            header_bytes,
        });
    }
    let (stored, computed) = (u64_at(h, 64), xxh3_64(&h[..64]));
    if stored != computed {
        return Err(EntryError::HeaderChecksum { stored, computed });
    }
    let mut key = [0u8; 32];
    key.copy_from_slice(&h[16..48]);
    let key = CacheKey(key);
    if key != *expected {
        return Err(EntryError::Foreign { found: key });
    }
    let blob_bytes = u64_at(h, 48);
    let expected_bytes = blob_bytes.saturating_add(ENTRY_HEADER_BYTES as u64);
    if file_bytes < expected_bytes {
        return Err(EntryError::Truncated {
            file_bytes,
            expected_bytes,
        });
    }
    if file_bytes > expected_bytes {
        return Err(EntryError::Trailing {
            file_bytes,
            expected_bytes,
        });
    }
    Ok(EntryHeader {
        key,
        blob_bytes,
        blob_xxh3: u64_at(h, 56),
    })
}

/// `DIR/v1/ab`: the shard directory of `key` under the cache directory `root`.
pub fn shard_dir(root: &Path, key: &CacheKey) -> PathBuf {
    let hex = key.to_hex();
    root.join(VERSION_DIR).join(&hex[..2])
}

/// `DIR/v1/ab/<hex>.as`: the file of `key`'s entry.
pub fn entry_path(root: &Path, key: &CacheKey) -> PathBuf {
    shard_dir(root, key).join(format!("{}.{ENTRY_EXTENSION}", key.to_hex()))
}

/// The key an entry's file name stands for (`<64 hex>.as` in the shard of its first byte).
pub fn entry_key(shard: &str, file_name: &str) -> Option<CacheKey> {
    let stem = file_name.strip_suffix(".as")?;
    let key = CacheKey::from_hex(stem).ok()?;
    (stem.get(..2) == Some(shard)).then_some(key)
}

/// The prefix of this process's temp files for `key`: `.<hex>.<pid>.`
pub fn temp_prefix(key: &CacheKey, pid: u32) -> String {
    format!(".{}.{pid}.", key.to_hex())
}

/// The writer's pid in a temp file name (`.<64 hex>.<pid>.<random>.tmp`), if it is one.
pub fn temp_owner(file_name: &str) -> Option<u32> {
    let middle = file_name.strip_prefix('.')?.strip_suffix(TEMP_SUFFIX)?;
    let mut parts = middle.split('.');
    let (hex, pid, random) = (parts.next()?, parts.next()?, parts.next()?);
    if parts.next().is_some() || random.is_empty() || CacheKey::from_hex(hex).is_err() {
        return None;
    }
    pid.parse().ok()
}

#[cfg(test)]
mod tests;
