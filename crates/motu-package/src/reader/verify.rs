//! The full integrity pass over a package: every checksum, offset and padding byte.

use crate::format::{
    align_up, Codec, CHUNK_ALIGN, HEADER_LEN, MANIFEST_ALIGN, SECTION_ALIGN, TRAILER_LEN,
};
use crate::{ChunkId, PackageError, Part};

use super::decode::{check_chunk_checksum, check_section_checksum, decode_chunk, section_part};
use super::{set, Package};

/// What [`Package::verify`] checked.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct VerifyReport {
    pub file_bytes: u64,
    pub chunks: u32,
    pub sections: u32,
    /// Bytes hashed (every byte of the file except padding, which is compared to zero).
    pub checksummed_bytes: u64,
    pub padding_bytes: u64,
}

impl Package {
    /// The full integrity pass: every checksum, every offset, every padding byte zero, no
    /// overlaps, every byte of the file accounted for, every zstd chunk decompressible to its
    /// raw length. Reports the first problem in file order.
    pub fn verify(&self) -> Result<VerifyReport, PackageError> {
        let span = tracing::info_span!("package_verify", file_bytes = self.file_bytes());
        let _entered = span.enter();
        let bytes = self.storage.bytes();
        let file_len = bytes.len() as u64;

        #[derive(Clone, Copy)]
        enum Region {
            Chunk(usize),
            Section(usize),
        }
        let mut regions: Vec<(u64, u64, u64, Region)> = Vec::new();
        for (index, chunk) in self.chunks.iter().enumerate() {
            regions.push((
                chunk.offset,
                chunk.stored_len,
                CHUNK_ALIGN,
                Region::Chunk(index),
            ));
        }
        for (index, section) in self.sections.iter().enumerate() {
            regions.push((
                section.offset,
                section.len_bytes,
                SECTION_ALIGN,
                Region::Section(index),
            ));
        }
        regions.sort_by_key(|&(offset, len, ..)| (offset, len));

        let mut report = VerifyReport {
            file_bytes: file_len,
            chunks: self.chunk_count(),
            sections: self.sections.len() as u32,
            checksummed_bytes: HEADER_LEN + self.manifest_len + TRAILER_LEN,
            padding_bytes: 0,
        };
        // The header page: header, then zeros up to the data area.
        report.padding_bytes += check_zero(bytes, HEADER_LEN, CHUNK_ALIGN)?;
        let mut cursor = CHUNK_ALIGN;
        for (offset, len, align, region) in regions {
            let part = match region {
                Region::Chunk(index) => Part::Chunk(ChunkId(index as u32)),
                Region::Section(index) => section_part(&self.sections[index]),
            };
            // The writer places each region at the first aligned offset after the previous
            // one; anything else is an overlap or an unaccounted gap.
            let expected = align_up(cursor, align).unwrap_or(u64::MAX);
            if offset != expected {
                let what = if offset < expected {
                    "overlaps the previous part"
                } else {
                    "leaves a gap"
                };
                return Err(PackageError::corrupt(
                    part,
                    format!("starts at byte {offset}, expected {expected}: {what}"),
                ));
            }
            report.padding_bytes += check_zero(bytes, cursor, offset)?;
            let data = self.range(offset, len);
            match region {
                Region::Chunk(index) => {
                    let info = &self.chunks[index];
                    check_chunk_checksum(info, data)?;
                    set(&self.chunk_verified, index);
                    if info.codec == Codec::Zstd {
                        decode_chunk(info, data)?;
                    }
                }
                Region::Section(index) => {
                    check_section_checksum(&self.sections[index], data)?;
                    set(&self.section_verified, index);
                }
            }
            report.checksummed_bytes += len;
            cursor = offset + len;
        }
        let expected_manifest = align_up(cursor, MANIFEST_ALIGN).unwrap_or(u64::MAX);
        if self.manifest_offset != expected_manifest {
            return Err(PackageError::corrupt(
                Part::Manifest,
                format!(
                    "starts at byte {}, expected {expected_manifest} after the last data",
                    self.manifest_offset
                ),
            ));
        }
        report.padding_bytes += check_zero(bytes, cursor, self.manifest_offset)?;
        let manifest_end = self.manifest_offset + self.manifest_len;
        report.padding_bytes += check_zero(bytes, manifest_end, file_len - TRAILER_LEN)?;
        debug_assert_eq!(report.checksummed_bytes + report.padding_bytes, file_len);
        tracing::info!(
            checksummed_bytes = report.checksummed_bytes,
            padding_bytes = report.padding_bytes,
            "package verified"
        );
        Ok(report)
    }
}

/// Checks that `bytes[start..end]` are zero; returns their count.
fn check_zero(bytes: &[u8], start: u64, end: u64) -> Result<u64, PackageError> {
    let padding = &bytes[start as usize..end as usize];
    match padding.iter().position(|&b| b != 0) {
        None => Ok(end - start),
        Some(at) => Err(PackageError::corrupt(
            Part::Padding { offset: start },
            format!(
                "byte {} is {:#04x}, padding must be zero",
                start + at as u64,
                padding[at]
            ),
        )),
    }
}

#[cfg(test)]
mod tests;
