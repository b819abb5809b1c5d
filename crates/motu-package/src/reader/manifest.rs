//! Opening a package: the header, trailer and manifest validated in O(manifest), without
//! touching chunk or section bytes, into the chunk directory and section table.

use crate::format::{
    self, align_up, ChunkEntry, Codec, Header, ManifestHeader, SectionEntry, Trailer, CHUNK_ALIGN,
    CHUNK_ENTRY_LEN, FORMAT_MAJOR, FORMAT_MINOR, HEADER_CHECKSUMMED_LEN, HEADER_LEN, HEADER_MAGIC,
    MANIFEST_ALIGN, MANIFEST_HEADER_LEN, MAX_CHUNK_BYTES, SECTION_ALIGN, SECTION_ENTRY_LEN,
    TRAILER_LEN, TRAILER_MAGIC,
};
use bytemuck::Pod;

use crate::{ChunkId, FormatVersion, PackageError, Part, SectionKind};

use super::storage::Storage;
use super::{bitset, Package};

/// Required-feature bits this reader understands (none yet in format 1.0).
const KNOWN_REQUIRED_FEATURES: u64 = 0;

/// One chunk's directory entry, decoded.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
pub struct ChunkInfo {
    pub id: ChunkId,
    pub offset: u64,
    pub stored_len: u64,
    pub raw_len: u64,
    pub codec: Codec,
    pub checksum: u64,
    pub tag: u32,
    pub group: u32,
}

/// One section's table entry, decoded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SectionInfo {
    pub kind: SectionKind,
    pub name: String,
    pub element_size: u32,
    pub count: u64,
    pub offset: u64,
    pub len_bytes: u64,
    pub checksum: u64,
}

impl Package {
    pub(super) fn parse(storage: Storage) -> Result<Package, PackageError> {
        let bytes = storage.bytes();
        let file_len = bytes.len() as u64;

        // Header. Magic and version come first: they stay at these offsets in every major.
        let header: Header = read_pod(bytes, 0, Part::Header)?;
        if header.magic != HEADER_MAGIC {
            return Err(PackageError::corrupt(
                Part::Header,
                "bad magic: this is not a motu package",
            ));
        }
        let version = FormatVersion {
            major: header.version_major,
            minor: header.version_minor,
        };
        if version.major != FORMAT_MAJOR {
            return Err(PackageError::Version {
                found: version,
                supported: FormatVersion {
                    major: FORMAT_MAJOR,
                    minor: FORMAT_MINOR,
                },
            });
        }
        let header_bytes = &bytes[..HEADER_CHECKSUMMED_LEN];
        if format::checksum(header_bytes) != header.checksum {
            return Err(PackageError::corrupt(
                Part::Header,
                "header checksum mismatch",
            ));
        }
        let unknown = header.required_features & !KNOWN_REQUIRED_FEATURES;
        if unknown != 0 {
            return Err(PackageError::UnsupportedFeatures { bits: unknown });
        }
        // Reserved fields are checked only in files this reader fully understands: a later
        // minor may give them meaning.
        let same_minor_or_older = !is_newer_minor(version.minor);
        if header.header_len as u64 != HEADER_LEN
            || header.chunk_align as u64 != CHUNK_ALIGN
            || header.section_align as u64 != SECTION_ALIGN
            || (same_minor_or_older && header.reserved != [0; 2])
        {
            return Err(PackageError::corrupt(
                Part::Header,
                format!(
                    "unexpected layout fields (header_len {}, chunk_align {}, section_align {})",
                    header.header_len, header.chunk_align, header.section_align
                ),
            ));
        }

        // Trailer.
        let trailer_offset = file_len - TRAILER_LEN;
        let trailer: Trailer = read_pod(bytes, trailer_offset, Part::Trailer)?;
        if trailer.magic != TRAILER_MAGIC {
            return Err(PackageError::corrupt(
                Part::Trailer,
                "bad trailer magic: the file is truncated or was not finished",
            ));
        }
        if trailer.compute_checksum() != trailer.checksum {
            return Err(PackageError::corrupt(
                Part::Trailer,
                "trailer checksum mismatch",
            ));
        }
        if trailer.file_len != file_len {
            return Err(PackageError::corrupt(
                Part::File,
                format!(
                    "file is {file_len} bytes but its trailer says {} (truncated or appended to)",
                    trailer.file_len
                ),
            ));
        }
        let manifest_end = trailer.manifest_offset.checked_add(trailer.manifest_len);
        let expected_trailer = manifest_end.and_then(|end| align_up(end, MANIFEST_ALIGN));
        if trailer.manifest_offset < CHUNK_ALIGN
            || trailer.manifest_offset % MANIFEST_ALIGN != 0
            || expected_trailer != Some(trailer_offset)
        {
            return Err(PackageError::corrupt(
                Part::Trailer,
                format!(
                    "manifest range {}+{} does not end right before the trailer at {trailer_offset}",
                    trailer.manifest_offset, trailer.manifest_len
                ),
            ));
        }

        // Manifest.
        let manifest = &bytes[trailer.manifest_offset as usize..][..trailer.manifest_len as usize];
        if format::checksum(manifest) != trailer.manifest_checksum {
            return Err(PackageError::corrupt(
                Part::Manifest,
                "manifest checksum mismatch",
            ));
        }
        let manifest_header: ManifestHeader = read_pod(manifest, 0, Part::Manifest)?;
        let expected_len = manifest_header
            .chunk_count
            .checked_mul(CHUNK_ENTRY_LEN)
            .and_then(|c| {
                manifest_header
                    .section_count
                    .checked_mul(SECTION_ENTRY_LEN)?
                    .checked_add(c)
            })
            .and_then(|t| {
                t.checked_add(MANIFEST_HEADER_LEN)?
                    .checked_add(manifest_header.names_len)
            });
        if expected_len != Some(trailer.manifest_len)
            || manifest_header.chunk_count > u32::MAX as u64
            || (same_minor_or_older && manifest_header.reserved != 0)
        {
            return Err(PackageError::corrupt(
                Part::Manifest,
                format!(
                    "{} chunks, {} sections and {} name bytes do not add up to {} manifest bytes",
                    manifest_header.chunk_count,
                    manifest_header.section_count,
                    manifest_header.names_len,
                    trailer.manifest_len
                ),
            ));
        }
        let chunk_count = manifest_header.chunk_count as usize;
        let section_count = manifest_header.section_count as usize;
        let sections_start = MANIFEST_HEADER_LEN as usize + chunk_count * CHUNK_ENTRY_LEN as usize;
        let names_start = sections_start + section_count * SECTION_ENTRY_LEN as usize;
        let names = &manifest[names_start..];
        // Data lies strictly between the header page and the manifest.
        let data_end = trailer.manifest_offset;

        let mut chunks = Vec::with_capacity(chunk_count);
        for index in 0..chunk_count {
            let entry: ChunkEntry = read_pod(
                manifest,
                MANIFEST_HEADER_LEN + index as u64 * CHUNK_ENTRY_LEN,
                Part::Manifest,
            )?;
            let id = ChunkId(index as u32);
            chunks.push(validate_chunk_entry(
                id,
                &entry,
                data_end,
                same_minor_or_older,
            )?);
        }

        let mut sections = Vec::with_capacity(section_count);
        for index in 0..section_count {
            let entry: SectionEntry = read_pod(
                manifest,
                (sections_start + index * SECTION_ENTRY_LEN as usize) as u64,
                Part::Manifest,
            )?;
            sections.push(validate_section_entry(
                &entry,
                names,
                data_end,
                same_minor_or_older,
            )?);
        }
        let mut kinds: Vec<u32> = sections.iter().map(|s| s.kind.0).collect();
        kinds.sort_unstable();
        if let Some(pair) = kinds.windows(2).find(|pair| pair[0] == pair[1]) {
            return Err(PackageError::corrupt(
                Part::Manifest,
                format!("section kind {} appears twice", pair[0]),
            ));
        }

        Ok(Package {
            chunk_verified: bitset(chunks.len()),
            section_verified: bitset(sections.len()),
            decoded: Default::default(),
            chunk_checks: Default::default(),
            storage,
            path: None,
            version,
            optional_features: header.optional_features,
            manifest_offset: trailer.manifest_offset,
            manifest_len: trailer.manifest_len,
            chunks,
            sections,
        })
    }
}

fn is_newer_minor(minor: u16) -> bool {
    minor > FORMAT_MINOR
}

pub(super) fn check_min_len(len: u64) -> Result<(), PackageError> {
    let min = CHUNK_ALIGN + TRAILER_LEN;
    if len < min {
        let what = if len == 0 {
            "empty file".to_string()
        } else {
            format!("{len} bytes")
        };
        return Err(PackageError::corrupt(
            Part::File,
            format!("{what} is too short for a motu package (at least {min} bytes)"),
        ));
    }
    Ok(())
}

fn read_pod<T: Pod>(bytes: &[u8], offset: u64, part: Part) -> Result<T, PackageError> {
    let start = usize::try_from(offset).ok();
    let slice = start.and_then(|s| bytes.get(s..s.checked_add(size_of::<T>())?));
    match slice {
        Some(slice) => Ok(bytemuck::pod_read_unaligned(slice)),
        None => Err(PackageError::corrupt(
            part,
            format!("truncated at byte {offset}"),
        )),
    }
}

fn validate_chunk_entry(
    id: ChunkId,
    entry: &ChunkEntry,
    data_end: u64,
    check_reserved: bool,
) -> Result<ChunkInfo, PackageError> {
    let part = || Part::Chunk(id);
    let codec = Codec::from_id(entry.codec).ok_or_else(|| {
        PackageError::corrupt(part(), format!("unknown codec id {}", entry.codec))
    })?;
    let end = entry.offset.checked_add(entry.stored_len);
    if entry.offset < CHUNK_ALIGN
        || entry.offset % CHUNK_ALIGN != 0
        || end.is_none_or(|e| e > data_end)
    {
        return Err(PackageError::corrupt(
            part(),
            format!(
                "stored range {}+{} is not page aligned inside the data area 4096..{data_end}",
                entry.offset, entry.stored_len
            ),
        ));
    }
    if entry.raw_len > MAX_CHUNK_BYTES || (codec == Codec::Raw && entry.raw_len != entry.stored_len)
    {
        return Err(PackageError::corrupt(
            part(),
            format!(
                "raw length {} is invalid for a {codec:?} chunk",
                entry.raw_len
            ),
        ));
    }
    if check_reserved && entry.reserved != 0 {
        return Err(PackageError::corrupt(part(), "reserved field is not zero"));
    }
    Ok(ChunkInfo {
        id,
        offset: entry.offset,
        stored_len: entry.stored_len,
        raw_len: entry.raw_len,
        codec,
        checksum: entry.checksum,
        tag: entry.tag,
        group: entry.group,
    })
}

fn validate_section_entry(
    entry: &SectionEntry,
    names: &[u8],
    data_end: u64,
    check_reserved: bool,
) -> Result<SectionInfo, PackageError> {
    let kind = SectionKind(entry.kind);
    let name_start = entry.name_offset as usize;
    let name = name_start
        .checked_add(entry.name_len as usize)
        .and_then(|end| names.get(name_start..end))
        .and_then(|bytes| std::str::from_utf8(bytes).ok())
        .ok_or_else(|| {
            PackageError::corrupt(
                Part::Section {
                    kind,
                    name: String::new(),
                },
                "name is out of range or not UTF-8",
            )
        })?;
    let part = || Part::Section {
        kind,
        name: name.to_string(),
    };
    if entry.element_size == 0 || entry.len % entry.element_size as u64 != 0 {
        return Err(PackageError::corrupt(
            part(),
            format!(
                "{} bytes is not a whole number of {}-byte elements",
                entry.len, entry.element_size
            ),
        ));
    }
    let end = entry.offset.checked_add(entry.len);
    if entry.offset < CHUNK_ALIGN
        || entry.offset % SECTION_ALIGN != 0
        || end.is_none_or(|e| e > data_end)
    {
        return Err(PackageError::corrupt(
            part(),
            format!(
                "range {}+{} is not 64-byte aligned inside the data area 4096..{data_end}",
                entry.offset, entry.len
            ),
        ));
    }
    if check_reserved && entry.reserved != 0 {
        return Err(PackageError::corrupt(part(), "reserved field is not zero"));
    }
    Ok(SectionInfo {
        kind,
        name: name.to_string(),
        element_size: entry.element_size,
        count: entry.len / entry.element_size as u64,
        offset: entry.offset,
        len_bytes: entry.len,
        checksum: entry.checksum,
    })
}
