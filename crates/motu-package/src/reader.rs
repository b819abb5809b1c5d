//! Package reader: instant open over a memory map, lazy per-chunk validation, full `verify`.

use std::fmt;
use std::ops::Deref;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

use bytemuck::{Pod, Zeroable};

use crate::format::{
    self, align_up, ChunkEntry, Codec, Header, ManifestHeader, SectionEntry, Trailer, CHUNK_ALIGN,
    CHUNK_ENTRY_LEN, FORMAT_MAJOR, FORMAT_MINOR, HEADER_CHECKSUMMED_LEN, HEADER_LEN, HEADER_MAGIC,
    MANIFEST_ALIGN, MANIFEST_HEADER_LEN, MAX_CHUNK_BYTES, SECTION_ALIGN, SECTION_ENTRY_LEN,
    TRAILER_LEN, TRAILER_MAGIC,
};
use crate::{ChunkId, FormatVersion, PackageError, Part, SectionKind};

/// Required-feature bits this reader understands (none yet in format 1.0).
const KNOWN_REQUIRED_FEATURES: u64 = 0;

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
    fn zeroed(len: usize) -> AlignedBytes {
        let blocks = bytemuck::allocation::zeroed_vec(len.div_ceil(64));
        AlignedBytes { blocks, len }
    }

    fn as_mut_slice(&mut self) -> &mut [u8] {
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
        }
    }
}

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

enum Storage {
    Mapped(memmap2::Mmap),
    Owned(AlignedBytes),
}

impl Storage {
    fn bytes(&self) -> &[u8] {
        match self {
            Storage::Mapped(map) => map,
            Storage::Owned(bytes) => bytes,
        }
    }
}

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
    /// chunk or section bytes.
    ///
    /// This is the crate's one `unsafe` construct. A memory map is only sound while no one
    /// else modifies the file; motu never modifies a package in place (writers rename a new
    /// file over the old, which leaves existing maps intact), but another program could. What
    /// that can cause is bounded: every byte read goes through bounds-checked, checksummed
    /// paths, so a concurrent modification shows up as a checksum error or as inconsistent
    /// bytes, not as out-of-bounds access. Truncating a mapped file makes later accesses to the
    /// lost pages raise SIGBUS; that risk is inherent to mmap and is accepted (ripgrep does
    /// the same).
    pub fn open(path: impl AsRef<Path>) -> Result<Package, PackageError> {
        let path = path.as_ref();
        let span = tracing::info_span!("package_open", path = %path.display());
        let _entered = span.enter();
        // A FIFO, device, directory or symlink loop is named as such, never opened or mapped.
        let (file, len) = crate::identity::open_input(path, None)
            .map_err(|e| PackageError::io("open", path, e))?;
        check_min_len(len)?;
        // SAFETY: the map is read-only and private to this `Package`; see the doc comment above
        // for why a concurrent writer cannot cause out-of-bounds reads here (all offsets are
        // validated against the mapped length, all contents are checksummed before use).
        let map = unsafe { memmap2::Mmap::map(&file) }
            .map_err(|e| PackageError::io("memory-map", path, e))?;
        let mut package = Package::parse(Storage::Mapped(map))?;
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

    fn parse(storage: Storage) -> Result<Package, PackageError> {
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
        }
        decode_chunk(&info, stored)
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
            Codec::Zstd => decompress_exact(&info, stored, dst)?,
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
        bytemuck::try_cast_slice(bytes).map_err(|e| type_error(e.to_string()))
    }

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

    /// Bytes at a range that `parse` validated against the file length.
    fn range(&self, offset: u64, len: u64) -> &[u8] {
        &self.storage.bytes()[offset as usize..(offset + len) as usize]
    }
}

fn is_newer_minor(minor: u16) -> bool {
    minor > FORMAT_MINOR
}

fn check_min_len(len: u64) -> Result<(), PackageError> {
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

fn section_part(info: &SectionInfo) -> Part {
    Part::Section {
        kind: info.kind,
        name: info.name.clone(),
    }
}

fn check_chunk_checksum(info: &ChunkInfo, stored: &[u8]) -> Result<(), PackageError> {
    if format::checksum(stored) != info.checksum {
        return Err(PackageError::corrupt(
            Part::Chunk(info.id),
            "checksum mismatch",
        ));
    }
    Ok(())
}

fn check_section_checksum(info: &SectionInfo, bytes: &[u8]) -> Result<(), PackageError> {
    if format::checksum(bytes) != info.checksum {
        return Err(PackageError::corrupt(
            section_part(info),
            "checksum mismatch",
        ));
    }
    Ok(())
}

fn decode_chunk<'a>(info: &ChunkInfo, stored: &'a [u8]) -> Result<ChunkBytes<'a>, PackageError> {
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
fn decompress_exact(info: &ChunkInfo, stored: &[u8], dst: &mut [u8]) -> Result<(), PackageError> {
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
mod tests {
    use super::*;

    #[test]
    fn package_is_shareable_across_threads() {
        fn assert_send_sync<T: Send + Sync>() {}
        assert_send_sync::<Package>();
    }

    #[test]
    fn aligned_bytes_are_64_byte_aligned() {
        for len in [0, 1, 63, 64, 65, 4097] {
            let bytes = AlignedBytes::zeroed(len);
            assert_eq!(bytes.len(), len);
            assert_eq!(bytes.as_ptr() as usize % 64, 0);
        }
    }

    #[test]
    fn bitset_marks_individual_bits() {
        let bits = bitset(130);
        assert_eq!(bits.len(), 3);
        set(&bits, 129);
        assert!(is_set(&bits, 129));
        assert!(!is_set(&bits, 128));
        assert!(!is_set(&bits, 0));
    }

    #[test]
    fn check_zero_reports_first_nonzero_byte() {
        let mut bytes = vec![0u8; 32];
        assert_eq!(check_zero(&bytes, 4, 20).unwrap(), 16);
        bytes[10] = 7;
        let err = check_zero(&bytes, 4, 20).unwrap_err();
        assert!(err.to_string().contains("byte 10 is 0x07"), "{err}");
    }
}
