//! A chunk's or section's bytes checked against their checksum, and zstd chunks decoded.

use crate::format::{self, Codec};
use crate::{PackageError, Part};

use super::manifest::{ChunkInfo, SectionInfo};
use super::storage::{AlignedBytes, ChunkBytes};

pub(super) fn section_part(info: &SectionInfo) -> Part {
    Part::Section {
        kind: info.kind,
        name: info.name.clone(),
    }
}

pub(super) fn check_chunk_checksum(info: &ChunkInfo, stored: &[u8]) -> Result<(), PackageError> {
    if format::checksum(stored) != info.checksum {
        return Err(PackageError::corrupt(
            Part::Chunk(info.id),
            "checksum mismatch",
        ));
    }
    Ok(())
}

pub(super) fn check_section_checksum(info: &SectionInfo, bytes: &[u8]) -> Result<(), PackageError> {
    if format::checksum(bytes) != info.checksum {
        return Err(PackageError::corrupt(
            section_part(info),
            "checksum mismatch",
        ));
    }
    Ok(())
}

pub(super) fn decode_chunk<'a>(
    info: &ChunkInfo,
    stored: &'a [u8],
) -> Result<ChunkBytes<'a>, PackageError> {
    match info.codec {
        Codec::Raw => Ok(ChunkBytes::Borrowed(stored)),
        Codec::Zstd => {
            // raw_len <= MAX_CHUNK_BYTES was checked at open, bounding this allocation.
            let mut raw = AlignedBytes::zeroed(info.raw_len as usize);
            decompress_exact(info, stored, raw.as_mut_slice())?;
            Ok(ChunkBytes::Owned(raw))
        }
    }
}

/// Decompresses `stored` into `dst`, which must come out exactly full.
pub(super) fn decompress_exact(
    info: &ChunkInfo,
    stored: &[u8],
    dst: &mut [u8],
) -> Result<(), PackageError> {
    let written = zstd::zstd_safe::decompress(dst, stored).map_err(|code| {
        PackageError::corrupt(
            Part::Chunk(info.id),
            format!("zstd: {}", zstd::zstd_safe::get_error_name(code)),
        )
    })?;
    if written as u64 != info.raw_len {
        return Err(PackageError::corrupt(
            Part::Chunk(info.id),
            format!(
                "decompressed to {written} bytes, directory says {}",
                info.raw_len
            ),
        ));
    }
    Ok(())
}
