//! Streaming, atomic package writer.
//!
//! Chunks are written as they fill, so memory stays at one open chunk per stream plus one
//! compression buffer; the manifest is written last. Everything goes to a temp file beside
//! the target that is renamed over it only by [`PackageWriter::finish`].

use std::path::{Path, PathBuf};

use crate::atomic::AtomicFile;
use crate::sink::{Sink, BLOCK_BYTES};

use crate::format::{
    self, align_up, ChunkEntry, Codec, Header, ManifestHeader, SectionEntry, Trailer, CHUNK_ALIGN,
    MANIFEST_ALIGN, MAX_CHUNK_BYTES, SECTION_ALIGN, TRAILER_MAGIC,
};
use crate::{ChunkId, PackageError, SectionKind};

mod chunk;
use chunk::{fill_error, OpenChunk, Put};

/// Default upper bound on one chunk's raw size.
pub const DEFAULT_TARGET_CHUNK_BYTES: u64 = 64 << 20;

/// Writer settings.
#[derive(Clone, Debug)]
pub struct WriterOptions {
    /// Upper bound on one chunk's raw size, at most [`MAX_CHUNK_BYTES`]. A chunk is sealed
    /// when the next append would not fit.
    pub target_chunk_bytes: u64,
    /// `Some(level)` compresses each chunk with zstd at that level (1..=22, negative levels
    /// are zstd's fast modes) and stores the compressed bytes only when they are smaller.
    pub zstd_level: Option<i32>,
    /// Writes past the page cache (`O_DIRECT`, staged in a reused aligned buffer) where the
    /// file system allows it: the same bytes for much less system time (`sink.rs`), but the
    /// finished file is not left in the page cache for a reader right after.
    pub direct_io: bool,
}

impl Default for WriterOptions {
    fn default() -> Self {
        WriterOptions {
            target_chunk_bytes: DEFAULT_TARGET_CHUNK_BYTES,
            zstd_level: None,
            direct_io: false,
        }
    }
}

/// Handle of one chunk stream of a [`PackageWriter`]: a sequence of chunks sharing a tag and a
/// group, filled independently of other streams (e.g. one stream per scene element).
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub struct StreamId(u32);

/// Where appended bytes live: `offset_in_chunk..offset_in_chunk + len_bytes` of the raw
/// (decompressed) bytes of `chunk`. Stable from the moment [`PackageWriter::append`] returns.
#[derive(Copy, Clone, Debug, PartialEq, Eq, Hash)]
pub struct Locator {
    pub chunk: ChunkId,
    pub offset_in_chunk: u64,
    pub len_bytes: u64,
}

/// What [`PackageWriter::finish`] wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WriteSummary {
    pub path: PathBuf,
    pub file_bytes: u64,
    pub chunk_count: u32,
    pub section_count: u32,
    /// Sum of raw chunk sizes.
    pub chunk_raw_bytes: u64,
    /// Sum of stored chunk sizes (smaller than raw where zstd paid off).
    pub chunk_stored_bytes: u64,
}

struct Stream {
    tag: u32,
    group: u32,
    open: Option<OpenChunk>,
}

/// Writes one package file. Dropping it without calling [`finish`](Self::finish) removes the
/// temp file and leaves the target untouched.
pub struct PackageWriter {
    target: PathBuf,
    temp: Option<AtomicFile>,
    options: WriterOptions,
    /// Bytes written to the temp file so far.
    pos: u64,
    /// Directory entries by chunk id; `None` while the chunk is still open.
    chunks: Vec<Option<ChunkEntry>>,
    sections: Vec<SectionEntry>,
    names: Vec<u8>,
    streams: Vec<Option<Stream>>,
    /// Capacity kept between chunks so a new chunk does not re-fault its buffer.
    spare: Vec<u8>,
    compressor: Option<zstd::bulk::Compressor<'static>>,
    compress_buf: Vec<u8>,
    /// Where `write_bytes` puts bytes and read-backs find them (`sink.rs`).
    sink: Sink,
    /// Set after an I/O error: the temp file's contents are unknown, so refuse more work.
    failed: bool,
    span: tracing::Span,
}

static ZEROS: [u8; CHUNK_ALIGN as usize] = [0; CHUNK_ALIGN as usize];

impl PackageWriter {
    /// Starts a package that [`finish`](Self::finish) will place at `path`.
    pub fn create(path: impl AsRef<Path>, options: WriterOptions) -> Result<Self, PackageError> {
        let target = path.as_ref().to_path_buf();
        if options.target_chunk_bytes == 0 || options.target_chunk_bytes > MAX_CHUNK_BYTES {
            return Err(PackageError::InvalidArgument(format!(
                "target chunk size {} bytes is outside 1..={MAX_CHUNK_BYTES}",
                options.target_chunk_bytes
            )));
        }
        let compressor = match options.zstd_level {
            Some(level) => Some(
                zstd::bulk::Compressor::new(level)
                    .map_err(|e| PackageError::io("set up zstd level for", &target, e))?,
            ),
            None => None,
        };
        let temp = AtomicFile::create(&target)?;
        let sink = Sink::new(temp.temp_path(), options.direct_io);
        let span = tracing::info_span!(
            "package_write",
            path = %target.display(),
            direct_io = sink.is_direct()
        );
        let mut writer = PackageWriter {
            target,
            temp: Some(temp),
            options,
            pos: 0,
            chunks: Vec::new(),
            sections: Vec::new(),
            names: Vec::new(),
            streams: Vec::new(),
            spare: Vec::new(),
            compressor,
            compress_buf: Vec::new(),
            sink,
            failed: false,
            span,
        };
        writer.write_bytes(bytemuck::bytes_of(&Header::current()))?;
        // The data area always starts on the second page, even in a package without chunks.
        writer.pad_to(CHUNK_ALIGN)?;
        Ok(writer)
    }

    /// Whether the writes go past the page cache (`WriterOptions::direct_io` asked for it and
    /// the file system took it).
    pub fn writes_direct(&self) -> bool {
        self.sink.is_direct()
    }

    /// Path of the temp file being written (removed on drop, renamed by `finish`).
    pub fn temp_path(&self) -> Option<&Path> {
        self.temp.as_ref().and_then(|t| t.temp_path())
    }

    /// Opens a new chunk stream whose chunks carry `tag` and `group` in the directory.
    pub fn open_stream(&mut self, tag: u32, group: u32) -> StreamId {
        let id = StreamId(self.streams.len() as u32);
        self.streams.push(Some(Stream {
            tag,
            group,
            open: None,
        }));
        id
    }

    /// A [`ChunkWriter`] over a new stream: the single-stream way to use the writer.
    pub fn chunk_writer(&mut self, tag: u32, group: u32) -> ChunkWriter<'_> {
        let stream = self.open_stream(tag, group);
        ChunkWriter {
            writer: self,
            stream,
        }
    }

    /// Appends `bytes` to the stream's open chunk at an offset that is a multiple of `align`
    /// (a power of two, at most 4096), sealing the chunk first if they would not fit.
    pub fn append(
        &mut self,
        stream: StreamId,
        bytes: &[u8],
        align: u64,
    ) -> Result<Locator, PackageError> {
        self.append_by(stream, bytes.len() as u64, align, Put::Bytes(bytes))
    }

    /// [`Self::append`] of `len_bytes` that `fill` pushes onto the chunk's buffer itself (it
    /// must push exactly that many): a blob encoded straight into its chunk, not into a buffer
    /// copied in after (an import's 1.2 GB of cluster blobs were zeroed, encoded and copied
    /// again). A fill that pushes another length fails the writer.
    pub fn append_with(
        &mut self,
        stream: StreamId,
        len_bytes: u64,
        align: u64,
        fill: &mut dyn FnMut(&mut Vec<u8>),
    ) -> Result<Locator, PackageError> {
        self.append_by(stream, len_bytes, align, Put::Fill(fill))
    }

    fn append_by(
        &mut self,
        stream: StreamId,
        len_bytes: u64,
        align: u64,
        mut put: Put<'_>,
    ) -> Result<Locator, PackageError> {
        self.check_usable()?;
        if !align.is_power_of_two() || align > CHUNK_ALIGN {
            return Err(PackageError::InvalidArgument(format!(
                "alignment {align} is not a power of two in 1..=4096"
            )));
        }
        let target = self.options.target_chunk_bytes;
        if len_bytes > target {
            // A blob larger than the target (one huge mesh) gets a chunk of its own, up to the
            // format's hard chunk limit.
            if len_bytes > MAX_CHUNK_BYTES {
                return Err(PackageError::InvalidArgument(format!(
                    "a {len_bytes}-byte blob exceeds the {MAX_CHUNK_BYTES}-byte chunk limit; split it"
                )));
            }
            self.seal_chunk(stream)?;
            let (tag, group) = {
                let state = self.stream_mut(stream)?;
                (state.tag, state.group)
            };
            let id = ChunkId(u32::try_from(self.chunks.len()).map_err(|_| {
                PackageError::InvalidArgument("more than 2^32 chunks in one package".into())
            })?);
            let entry = match put {
                Put::Bytes(bytes) => self.write_chunk(bytes, tag, group)?,
                Put::Fill(_) => {
                    let mut blob = Vec::with_capacity(len_bytes as usize);
                    self.put_checked(&mut put, &mut blob, len_bytes)?;
                    self.write_chunk(&blob, tag, group)?
                }
            };
            self.chunks.push(Some(entry));
            return Ok(Locator {
                chunk: id,
                offset_in_chunk: 0,
                len_bytes,
            });
        }
        let fits = {
            let state = self.stream_mut(stream)?;
            match &state.open {
                Some(open) => align_up(open.len() as u64, align)
                    .and_then(|start| start.checked_add(len_bytes))
                    .is_some_and(|end| end <= target),
                None => true,
            }
        };
        if !fits {
            self.seal_chunk(stream)?;
        }
        let next_id = ChunkId(u32::try_from(self.chunks.len()).map_err(|_| {
            PackageError::InvalidArgument("more than 2^32 chunks in one package".into())
        })?);
        let opened = self.stream_mut(stream)?.open.is_none();
        if opened {
            let mut data = std::mem::take(&mut self.spare);
            data.clear();
            // Virtual reservation only: pages are committed as they are written. The chunk
            // never outgrows it (`fits`), so the bytes stay where the pad put them.
            let pad_room = if self.sink.is_direct() {
                BLOCK_BYTES
            } else {
                0
            };
            data.reserve_exact(target as usize + pad_room);
            let pad = match data.as_ptr().align_offset(BLOCK_BYTES) {
                pad if pad < pad_room => pad,
                _ => 0,
            };
            data.resize(pad, 0);
            self.stream_mut(stream)?.open = Some(OpenChunk {
                id: next_id,
                data,
                pad,
            });
        }
        let open = self.stream_mut(stream)?.open.as_mut().ok_or_else(|| {
            PackageError::InvalidArgument("internal: stream has no open chunk".into())
        })?;
        // `fits` or a fresh chunk guarantee start + len <= target, which fits in usize.
        let start = align_up(open.len() as u64, align).unwrap_or(u64::MAX) as usize;
        open.data.resize(open.pad + start, 0);
        let pushed = put.onto(&mut open.data);
        if pushed != len_bytes {
            self.failed = true;
            return Err(fill_error(pushed, len_bytes));
        }
        let open = self.stream_mut(stream)?.open.as_mut().ok_or_else(|| {
            PackageError::InvalidArgument("internal: stream has no open chunk".into())
        })?;
        let chunk = open.id;
        if opened {
            self.chunks.push(None);
        }
        Ok(Locator {
            chunk,
            offset_in_chunk: start as u64,
            len_bytes,
        })
    }

    /// [`Put::onto`] `out` that fails the writer when the put pushed other than `len_bytes`.
    fn put_checked(
        &mut self,
        put: &mut Put<'_>,
        out: &mut Vec<u8>,
        len_bytes: u64,
    ) -> Result<(), PackageError> {
        let pushed = put.onto(out);
        if pushed != len_bytes {
            self.failed = true;
            return Err(fill_error(pushed, len_bytes));
        }
        Ok(())
    }

    /// Writes the stream's open chunk to the file; the next append starts a new chunk.
    /// Returns the sealed chunk's id, `None` if no chunk was open.
    pub fn seal_chunk(&mut self, stream: StreamId) -> Result<Option<ChunkId>, PackageError> {
        self.check_usable()?;
        let state = self.stream_mut(stream)?;
        let Some(open) = state.open.take() else {
            return Ok(None);
        };
        let (tag, group) = (state.tag, state.group);
        let result = self.write_chunk(open.bytes(), tag, group);
        let id = open.id;
        let mut data = open.data;
        data.clear();
        // One spare buffer for the whole writer, not one per stream: each kept buffer stays
        // resident (its pages were written), and an import has a stream per element.
        self.spare = data;
        if result.is_err() {
            // The chunk's directory entry is lost, so the package cannot be completed.
            self.failed = true;
        }
        self.chunks[id.0 as usize] = Some(result?);
        Ok(Some(id))
    }

    /// Reads back `len_bytes` at `offset_in_chunk` of a chunk written (or still being filled) by
    /// this writer — e.g. a mesh the compiler needs again while the import is running.
    pub fn read_back(
        &mut self,
        chunk: ChunkId,
        offset_in_chunk: u64,
        len_bytes: u64,
    ) -> Result<Vec<u8>, PackageError> {
        self.check_usable()?;
        let range = |len: usize| -> Result<std::ops::Range<usize>, PackageError> {
            let start = usize::try_from(offset_in_chunk).ok();
            let end = start.and_then(|s| s.checked_add(usize::try_from(len_bytes).ok()?));
            match (start, end) {
                (Some(s), Some(e)) if e <= len => Ok(s..e),
                _ => Err(PackageError::InvalidArgument(format!(
                    "read-back of {len_bytes} bytes at {offset_in_chunk} is outside chunk {} ({len} bytes)",
                    chunk.0
                ))),
            }
        };
        for open in self
            .streams
            .iter()
            .flatten()
            .filter_map(|s| s.open.as_ref())
        {
            if open.id == chunk {
                return Ok(open.bytes()[range(open.len())?].to_vec());
            }
        }
        let raw = self.read_back_chunk(chunk)?;
        Ok(raw[range(raw.len())?].to_vec())
    }

    /// The whole raw bytes of a chunk written (or still being filled) by this writer: one read
    /// (and decompression) per chunk for a pass over every mesh (an importer's proxy boxes).
    /// Takes `&self`, so several chunks may be read at once.
    pub fn read_back_chunk(&self, chunk: ChunkId) -> Result<Vec<u8>, PackageError> {
        let mut out = Vec::new();
        self.read_back_chunk_into(chunk, &mut out)?;
        Ok(out)
    }

    /// [`Self::read_back_chunk`] into `out` (replacing what it held): a buffer read into again
    /// is not faulted in and zeroed by the kernel again.
    pub fn read_back_chunk_into(
        &self,
        chunk: ChunkId,
        out: &mut Vec<u8>,
    ) -> Result<(), PackageError> {
        self.check_usable()?;
        for open in self
            .streams
            .iter()
            .flatten()
            .filter_map(|s| s.open.as_ref())
        {
            if open.id == chunk {
                out.clear();
                out.extend_from_slice(open.bytes());
                return Ok(());
            }
        }
        let entry = self.chunks.get(chunk.0 as usize).copied().flatten().ok_or(
            PackageError::NoSuchChunk {
                id: chunk,
                count: self.chunks.len() as u32,
            },
        )?;
        let temp = self.temp.as_ref().ok_or_else(|| {
            PackageError::InvalidArgument("the package writer is already finished".into())
        })?;
        // The read overwrites every byte: only room the buffer never held is zeroed (a
        // cleared buffer was zeroed whole before each read, the size of a package).
        out.truncate(entry.stored_len as usize);
        out.resize(entry.stored_len as usize, 0);
        {
            self.sink
                .read_exact_at(temp.file(), out, entry.offset)
                .map_err(|e| PackageError::io("read back a chunk of", &self.target, e))?;
        }
        if entry.codec == Codec::Zstd.id() {
            *out = zstd::bulk::decompress(out, entry.raw_len as usize)
                .map_err(|e| PackageError::io("decompress a chunk of", &self.target, e))?;
        }
        Ok(())
    }

    /// Bytes in the stream's open (not yet written) chunk: what the stream holds in memory.
    pub fn open_chunk_bytes(&self, stream: StreamId) -> u64 {
        self.streams
            .get(stream.0 as usize)
            .and_then(|s| s.as_ref())
            .and_then(|s| s.open.as_ref())
            .map_or(0, |o| o.len() as u64)
    }

    /// Seals the stream's open chunk and frees its buffer; the id becomes invalid.
    pub fn close_stream(&mut self, stream: StreamId) -> Result<(), PackageError> {
        self.seal_chunk(stream)?;
        self.streams[stream.0 as usize] = None;
        Ok(())
    }

    /// Adds a typed table of `bytes.len() / element_size` elements. Kinds are unique within
    /// a package; `name` is for messages and tools. Written immediately (memory stays bounded).
    pub fn add_section(
        &mut self,
        kind: SectionKind,
        name: &str,
        element_size: u32,
        bytes: &[u8],
    ) -> Result<(), PackageError> {
        // Checked before anything is written, so a refused section leaves the writer usable.
        if element_size == 0 || bytes.len() % element_size as usize != 0 {
            return Err(PackageError::InvalidArgument(format!(
                "section {name}: {} bytes is not a whole number of {element_size}-byte elements",
                bytes.len()
            )));
        }
        let mut section = self.begin_section(kind, name, element_size)?;
        section.write(bytes)?;
        section.finish()
    }

    /// Starts a section written piece by piece ([`SectionWriter::write`]), for a table too
    /// large to hold in memory at once (an importer's texels); same rules as
    /// [`add_section`](Self::add_section). The borrow keeps anything else from being written
    /// until [`SectionWriter::finish`]; dropping it unfinished fails the package.
    pub fn begin_section(
        &mut self,
        kind: SectionKind,
        name: &str,
        element_size: u32,
    ) -> Result<SectionWriter<'_>, PackageError> {
        self.check_usable()?;
        if element_size == 0 {
            return Err(PackageError::InvalidArgument(format!(
                "section {name}: element size 0"
            )));
        }
        if self.sections.iter().any(|s| s.kind == kind.0) {
            return Err(PackageError::InvalidArgument(format!(
                "section {name}: kind {} was already added",
                kind.0
            )));
        }
        let name_offset = u32::try_from(self.names.len()).ok();
        let name_len = u32::try_from(name.len()).ok();
        let (Some(name_offset), Some(name_len)) = (name_offset, name_len) else {
            return Err(PackageError::InvalidArgument(
                "section names exceed 4 GiB".into(),
            ));
        };
        let offset = self.pad_to(SECTION_ALIGN)?;
        Ok(SectionWriter {
            writer: self,
            entry: SectionEntry {
                kind: kind.0,
                element_size,
                offset,
                len: 0,
                checksum: 0,
                name_offset,
                name_len,
                reserved: 0,
            },
            name: name.to_string(),
            hasher: xxhash_rust::xxh3::Xxh3::new(),
            finished: false,
        })
    }

    /// [`add_section`](Self::add_section) for a slice of `Pod` elements.
    pub fn add_section_slice<T: bytemuck::Pod>(
        &mut self,
        kind: SectionKind,
        name: &str,
        elements: &[T],
    ) -> Result<(), PackageError> {
        let element_size = u32::try_from(size_of::<T>())
            .ok()
            .filter(|&size| size > 0)
            .ok_or_else(|| PackageError::InvalidArgument("element size must be 1..2^32".into()))?;
        self.add_section(kind, name, element_size, bytemuck::cast_slice(elements))
    }

    /// Seals every open chunk, writes the manifest and trailer, fsyncs, renames the temp file
    /// over the target and fsyncs the directory.
    pub fn finish(mut self) -> Result<WriteSummary, PackageError> {
        self.check_usable()?;
        let span = self.span.clone();
        let _entered = span.enter();
        for index in 0..self.streams.len() {
            if self.streams[index].is_some() {
                self.seal_chunk(StreamId(index as u32))?;
            }
        }
        // Every opened chunk belongs to a stream and was just sealed.
        let chunks: Vec<ChunkEntry> = self
            .chunks
            .iter()
            .copied()
            .collect::<Option<_>>()
            .ok_or_else(|| PackageError::InvalidArgument("a chunk was never sealed".into()))?;

        let manifest_header = ManifestHeader {
            chunk_count: chunks.len() as u64,
            section_count: self.sections.len() as u64,
            names_len: self.names.len() as u64,
            reserved: 0,
        };
        let mut manifest = Vec::new();
        manifest.extend_from_slice(bytemuck::bytes_of(&manifest_header));
        manifest.extend_from_slice(bytemuck::cast_slice(&chunks));
        manifest.extend_from_slice(bytemuck::cast_slice(&self.sections));
        manifest.extend_from_slice(&self.names);
        let manifest_offset = self.pad_to(MANIFEST_ALIGN)?;
        self.write_bytes(&manifest)?;
        self.pad_to(MANIFEST_ALIGN)?;
        let file_bytes = self.pos + format::TRAILER_LEN;
        let mut trailer = Trailer {
            manifest_offset,
            manifest_len: manifest.len() as u64,
            manifest_checksum: format::checksum(&manifest),
            file_len: file_bytes,
            checksum: 0,
            magic: TRAILER_MAGIC,
        };
        trailer.checksum = trailer.compute_checksum();
        self.write_bytes(bytemuck::bytes_of(&trailer))?;

        let temp = self
            .temp
            .take()
            .ok_or_else(|| PackageError::InvalidArgument("writer has no temp file".into()))?;
        self.sink
            .finish(temp.file())
            .map_err(|e| PackageError::io("write", &self.target, e))?;
        temp.commit()?;

        let summary = WriteSummary {
            path: self.target.clone(),
            file_bytes,
            chunk_count: chunks.len() as u32,
            section_count: self.sections.len() as u32,
            chunk_raw_bytes: chunks.iter().map(|c| c.raw_len).sum(),
            chunk_stored_bytes: chunks.iter().map(|c| c.stored_len).sum(),
        };
        tracing::info!(
            file_bytes,
            chunks = summary.chunk_count,
            sections = summary.section_count,
            chunk_raw_bytes = summary.chunk_raw_bytes,
            chunk_stored_bytes = summary.chunk_stored_bytes,
            "package written"
        );
        Ok(summary)
    }

    fn write_chunk(
        &mut self,
        raw: &[u8],
        tag: u32,
        group: u32,
    ) -> Result<ChunkEntry, PackageError> {
        let mut codec = Codec::Raw;
        if let Some(compressor) = &mut self.compressor {
            let bound = zstd::zstd_safe::compress_bound(raw.len());
            self.compress_buf.clear();
            self.compress_buf.reserve(bound);
            let compressed_len = compressor
                .compress_to_buffer(raw, &mut self.compress_buf)
                .map_err(|e| PackageError::io("zstd-compress a chunk for", &self.target, e))?;
            if compressed_len < raw.len() {
                codec = Codec::Zstd;
            }
        }
        let offset = self.pad_to(CHUNK_ALIGN)?;
        let mut compress_buf = std::mem::take(&mut self.compress_buf);
        let stored: &[u8] = match codec {
            Codec::Raw => raw,
            Codec::Zstd => &compress_buf,
        };
        let entry = ChunkEntry {
            offset,
            stored_len: stored.len() as u64,
            raw_len: raw.len() as u64,
            checksum: format::checksum(stored),
            codec: codec.id(),
            tag,
            group,
            reserved: 0,
        };
        let result = self.write_bytes(stored);
        compress_buf.clear();
        self.compress_buf = compress_buf;
        result?;
        tracing::debug!(
            parent: &self.span,
            chunk = self.chunks.len(),
            raw_bytes = entry.raw_len,
            stored_bytes = entry.stored_len,
            ?codec,
            "chunk sealed"
        );
        Ok(entry)
    }

    /// Writes zeros up to the next multiple of `align`; returns the new position.
    fn pad_to(&mut self, align: u64) -> Result<u64, PackageError> {
        let aligned = align_up(self.pos, align)
            .ok_or_else(|| PackageError::InvalidArgument("package exceeds 2^64 bytes".into()))?;
        let pad = (aligned - self.pos) as usize;
        self.write_bytes(&ZEROS[..pad])?;
        Ok(aligned)
    }

    fn write_bytes(&mut self, bytes: &[u8]) -> Result<(), PackageError> {
        let Some(temp) = &mut self.temp else {
            return Err(PackageError::InvalidArgument(
                "writer already finished".into(),
            ));
        };
        if let Err(e) = self.sink.write(temp.file(), self.pos, bytes) {
            self.failed = true;
            let at = temp.temp_path().unwrap_or(&self.target).to_path_buf();
            return Err(PackageError::io("write", &at, e));
        }
        self.pos += bytes.len() as u64;
        Ok(())
    }

    fn check_usable(&self) -> Result<(), PackageError> {
        if self.failed {
            return Err(PackageError::InvalidArgument(
                "an earlier write failed; this package cannot be finished".into(),
            ));
        }
        Ok(())
    }

    fn stream_mut(&mut self, stream: StreamId) -> Result<&mut Stream, PackageError> {
        self.streams
            .get_mut(stream.0 as usize)
            .and_then(Option::as_mut)
            .ok_or_else(|| PackageError::InvalidArgument(format!("stream {} is closed", stream.0)))
    }
}

/// One stream of a [`PackageWriter`], borrowed: append blobs, get locators back.
pub struct ChunkWriter<'w> {
    writer: &'w mut PackageWriter,
    stream: StreamId,
}

impl ChunkWriter<'_> {
    /// See [`PackageWriter::append`].
    pub fn append(&mut self, bytes: &[u8], align: u64) -> Result<Locator, PackageError> {
        self.writer.append(self.stream, bytes, align)
    }

    /// See [`PackageWriter::seal_chunk`].
    pub fn seal_chunk(&mut self) -> Result<Option<ChunkId>, PackageError> {
        self.writer.seal_chunk(self.stream)
    }

    /// Seals the open chunk and closes the stream.
    pub fn close(self) -> Result<(), PackageError> {
        self.writer.close_stream(self.stream)
    }
}

/// One section of a [`PackageWriter`] being written: see [`PackageWriter::begin_section`].
pub struct SectionWriter<'w> {
    writer: &'w mut PackageWriter,
    entry: SectionEntry,
    name: String,
    hasher: xxhash_rust::xxh3::Xxh3,
    finished: bool,
}

impl SectionWriter<'_> {
    /// Appends `bytes` to the section.
    pub fn write(&mut self, bytes: &[u8]) -> Result<(), PackageError> {
        self.writer.check_usable()?;
        self.writer.write_bytes(bytes)?;
        self.hasher.update(bytes);
        self.entry.len += bytes.len() as u64;
        Ok(())
    }

    /// Bytes written so far.
    pub fn len_bytes(&self) -> u64 {
        self.entry.len
    }

    /// Ends the section (its length must be a whole number of elements) and lists it.
    pub fn finish(mut self) -> Result<(), PackageError> {
        self.finished = true;
        let name = std::mem::take(&mut self.name);
        if self.entry.len % u64::from(self.entry.element_size) != 0 {
            self.writer.failed = true;
            return Err(PackageError::InvalidArgument(format!(
                "section {name}: {} bytes is not a whole number of {}-byte elements",
                self.entry.len, self.entry.element_size
            )));
        }
        self.entry.checksum = self.hasher.digest();
        self.writer.names.extend_from_slice(name.as_bytes());
        self.writer.sections.push(self.entry);
        tracing::debug!(
            parent: &self.writer.span,
            kind = self.entry.kind,
            name,
            bytes = self.entry.len,
            "section"
        );
        Ok(())
    }
}

impl Drop for SectionWriter<'_> {
    fn drop(&mut self) {
        if !self.finished {
            // Its bytes are in the file but it is not listed: the package cannot be finished.
            self.writer.failed = true;
        }
    }
}
