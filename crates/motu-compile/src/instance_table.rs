//! [`CompiledScene::instances`](crate::CompiledScene::instances): the compile's instance table,
//! on the heap, or in a growable shared writable map of an unnamed file (issue 48 item 1: the
//! import's peak is the compile and the stream split, 64 bytes an instance on the heap, 1.8 GB
//! at island scale 1). Mapped, the table's pages count as resident only until they are
//! released: `MADV_DONTNEED` on a shared file map drops them from the resident set and keeps
//! their data in the page cache (dirty pages are written to the file, never lost), so a writer
//! that releases behind itself holds what it touched since its last release. [`push`] releases
//! every [`RELEASE_EVERY_RECORDS`] records written; whole-table passes ([`resize`],
//! [`extend_from_within`], [`InstanceTable::copy_within_released`]) release behind
//! themselves; readers call [`InstanceTable::release_range`].
//!
//! [`push`]: InstanceTable::push
//! [`resize`]: InstanceTable::resize
//! [`extend_from_within`]: InstanceTable::extend_from_within

use crate::instance_map::RELEASE_EVERY_RECORDS;
use crate::CompileError;
use motu_abi::InstanceRecord;
use std::fs::File;
use std::ops::{Deref, DerefMut, Range};
use std::path::{Path, PathBuf};

const RECORD_BYTES: usize = std::mem::size_of::<InstanceRecord>();

/// The smallest capacity a mapped table grows to (1 MiB of records).
const MIN_FILE_RECORDS: usize = 1 << 14;

/// An instance table: a `Vec` by default ([`InstanceTable::new`]), or records in an unnamed
/// file mapped shared and writable ([`InstanceTable::in_file`]), grown by doubling.
#[derive(Default)]
pub struct InstanceTable {
    store: Store,
}

enum Store {
    Heap(Vec<InstanceRecord>),
    File(FileTable),
}

impl Default for Store {
    fn default() -> Self {
        Store::Heap(Vec::new())
    }
}

struct FileTable {
    file: File,
    dir: PathBuf,
    /// `None` while the capacity is 0.
    map: Option<memmap2::MmapMut>,
    len: usize,
    capacity: usize,
    /// [`InstanceTable::push`] released the pages of the records below this index last.
    released_to: usize,
}

impl FileTable {
    fn err(&self, source: std::io::Error) -> CompileError {
        CompileError::Scratch {
            dir: self.dir.clone(),
            source,
        }
    }

    /// Grows the file (its blocks allocated, so a full disk is an error here, not a fault on a
    /// later write) and maps it again: the old map's pages go from the resident set with it.
    fn grow_to(&mut self, capacity: usize) -> Result<(), CompileError> {
        if capacity <= self.capacity {
            return Ok(());
        }
        let bytes = capacity
            .checked_mul(RECORD_BYTES)
            .ok_or_else(|| CompileError::TooMany {
                what: "instances",
                count: capacity as u64,
            })?;
        self.map = None;
        let (from, add) = (
            self.capacity * RECORD_BYTES,
            bytes - self.capacity * RECORD_BYTES,
        );
        match rustix::fs::fallocate(
            &self.file,
            rustix::fs::FallocateFlags::empty(),
            from as u64,
            add as u64,
        ) {
            Ok(()) => {}
            // A file system without `fallocate`: a sparse file, as `set_len` makes.
            Err(rustix::io::Errno::OPNOTSUPP) => {
                self.file.set_len(bytes as u64).map_err(|e| self.err(e))?
            }
            Err(e) => return Err(self.err(e.into())),
        }
        // SAFETY: the file is unnamed (O_TMPFILE or unlinked at creation) and only this table
        // holds it: nobody else can truncate or write it under the map, and the table never
        // shrinks the file while mapped.
        let map = unsafe { memmap2::MmapMut::map_mut(&self.file) }.map_err(|e| self.err(e))?;
        if map.len() != bytes {
            return Err(self.err(std::io::Error::other(format!(
                "instance file maps {} bytes, {bytes} allocated",
                map.len()
            ))));
        }
        self.map = Some(map);
        self.capacity = capacity;
        self.released_to = 0;
        Ok(())
    }

    fn release_range(&self, begin: usize, end: usize) -> std::io::Result<()> {
        let (Some(m), end) = (&self.map, end.min(self.capacity)) else {
            return Ok(());
        };
        if begin >= end {
            return Ok(());
        }
        // SAFETY: a shared map of a file only this table writes: MADV_DONTNEED drops the pages
        // from this process's page tables, their data (written or not) stays in the page cache
        // and file, and a later access faults the same bytes back in (memmap2 aligns the start
        // down to a page; the range is inside the map).
        unsafe {
            m.unchecked_advise_range(
                memmap2::UncheckedAdvice::DontNeed,
                begin * RECORD_BYTES,
                (end - begin) * RECORD_BYTES,
            )
        }
    }

    fn records(&self) -> &[InstanceRecord] {
        match &self.map {
            Some(m) => bytemuck::cast_slice(&m[..self.len * RECORD_BYTES]),
            None => &[],
        }
    }

    fn records_mut(&mut self) -> &mut [InstanceRecord] {
        match &mut self.map {
            Some(m) => bytemuck::cast_slice_mut(&mut m[..self.len * RECORD_BYTES]),
            None => &mut [],
        }
    }
}

impl InstanceTable {
    /// An empty table on the heap.
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty table in a new unnamed file in `dir` (gone with the table, whatever ends the
    /// process).
    pub fn in_file(dir: &Path) -> Result<Self, CompileError> {
        let file = tempfile::tempfile_in(dir).map_err(|source| CompileError::Scratch {
            dir: dir.to_path_buf(),
            source,
        })?;
        Ok(Self {
            store: Store::File(FileTable {
                file,
                dir: dir.to_path_buf(),
                map: None,
                len: 0,
                capacity: 0,
                released_to: 0,
            }),
        })
    }

    /// Whether the records are in a mapped file.
    pub fn is_mapped(&self) -> bool {
        matches!(self.store, Store::File(_))
    }

    /// How many records the table can hold before it grows.
    pub fn capacity(&self) -> usize {
        match &self.store {
            Store::Heap(v) => v.capacity(),
            Store::File(f) => f.capacity,
        }
    }

    /// Room for at least `additional` more records, exactly (a mapped table's file grows to
    /// it: disk blocks, no memory), or an error (out of memory, or the file's).
    pub fn try_reserve_exact(&mut self, additional: usize) -> Result<(), CompileError> {
        let need = self.len().saturating_add(additional);
        match &mut self.store {
            Store::Heap(v) => {
                v.try_reserve_exact(additional)
                    .map_err(|_| CompileError::OutOfMemory {
                        what: "instances",
                        bytes: (need * RECORD_BYTES) as u64,
                    })
            }
            Store::File(f) => f.grow_to(need),
        }
    }

    /// Room for `additional` more records: a mapped table at least doubles.
    fn reserve(&mut self, additional: usize) -> Result<(), CompileError> {
        match &mut self.store {
            Store::Heap(v) => v
                .try_reserve(additional)
                .map_err(|_| CompileError::OutOfMemory {
                    what: "instances",
                    bytes: ((v.len() + additional) * RECORD_BYTES) as u64,
                }),
            Store::File(f) => {
                let need = f.len.saturating_add(additional);
                if need <= f.capacity {
                    return Ok(());
                }
                f.grow_to(need.max(f.capacity * 2).max(MIN_FILE_RECORDS))
            }
        }
    }

    /// Appends `record`; a mapped table releases the pages written every
    /// [`RELEASE_EVERY_RECORDS`] records.
    pub fn push(&mut self, record: InstanceRecord) -> Result<(), CompileError> {
        self.reserve(1)?;
        match &mut self.store {
            Store::Heap(v) => v.push(record),
            Store::File(f) => {
                f.len += 1;
                let len = f.len;
                f.records_mut()[len - 1] = record;
                if len - f.released_to >= RELEASE_EVERY_RECORDS {
                    // A failed hint leaves pages resident; the records are the same.
                    let _ = f.release_range(f.released_to, len);
                    f.released_to = len;
                }
            }
        }
        Ok(())
    }

    /// Keeps the first `len` records (a mapped file keeps its size).
    pub fn truncate(&mut self, len: usize) {
        match &mut self.store {
            Store::Heap(v) => v.truncate(len),
            Store::File(f) => {
                f.len = f.len.min(len);
                f.released_to = f.released_to.min(f.len);
            }
        }
    }

    /// Frees a heap table's spare capacity (a mapped table keeps its file).
    pub fn shrink_to_fit(&mut self) {
        if let Store::Heap(v) = &mut self.store {
            v.shrink_to_fit();
        }
    }

    /// Grows or truncates the table to `len` records, new ones `value`.
    pub fn resize(&mut self, len: usize, value: InstanceRecord) -> Result<(), CompileError> {
        let old = self.len();
        if len <= old {
            self.truncate(len);
            return Ok(());
        }
        self.reserve(len - old)?;
        match &mut self.store {
            Store::Heap(v) => v.resize(len, value),
            Store::File(f) => {
                f.len = len;
                let mut at = old;
                while at < len {
                    let end = (at + RELEASE_EVERY_RECORDS).min(len);
                    f.records_mut()[at..end].fill(value);
                    let _ = f.release_range(at, end);
                    at = end;
                }
            }
        }
        Ok(())
    }

    /// Appends a copy of records `range`.
    pub fn extend_from_within(&mut self, range: Range<usize>) -> Result<(), CompileError> {
        let (begin, end) = (range.start, range.end);
        assert!(begin <= end && end <= self.len(), "range out of the table");
        self.reserve(end - begin)?;
        let old = self.len();
        match &mut self.store {
            Store::Heap(v) => v.extend_from_within(begin..end),
            Store::File(f) => {
                f.len = old + (end - begin);
                f.released_to = f.len;
                copy_released(f, begin..end, old);
            }
        }
        Ok(())
    }

    /// `copy_within(src, dest)` a piece at a time, a mapped table's pages released behind
    /// (the whole-table moves of a stream split). Overlapping ranges copy as `copy_within`.
    pub fn copy_within_released(&mut self, src: Range<usize>, dest: usize) {
        assert!(
            src.start <= src.end && src.end <= self.len(),
            "range out of the table"
        );
        assert!(
            dest + src.len() <= self.len(),
            "destination out of the table"
        );
        match &mut self.store {
            Store::Heap(v) => v.copy_within(src, dest),
            Store::File(f) => copy_released(f, src, dest),
        }
    }

    /// Drops the pages of records `begin..end` of a mapped table from the resident set (a
    /// no-op on the heap; a failed hint costs only memory).
    pub fn release_range(&self, begin: usize, end: usize) {
        if let Store::File(f) = &self.store {
            let _ = f.release_range(begin, end);
        }
    }

    /// Drops every page of a mapped table from the resident set.
    pub fn release_pages(&self) {
        if let Store::File(f) = &self.store {
            let _ = f.release_range(0, f.capacity);
        }
    }

    /// A mapped table as a read-only [`crate::InstanceMap`] of its records, with no copy (the
    /// table stops writing); a heap table is given back (`Err`).
    pub(crate) fn into_map(self) -> Result<Result<crate::InstanceMap, CompileError>, Self> {
        match self.store {
            Store::Heap(v) => Err(v.into()),
            Store::File(f) => Ok(match f.map {
                None => Ok(crate::InstanceMap::from_map_empty()),
                Some(m) => m
                    .make_read_only()
                    .map(|m| crate::InstanceMap::from_map(m, f.len))
                    .map_err(|source| CompileError::Scratch { dir: f.dir, source }),
            }),
        }
    }

    /// The records as a `Vec` (a heap table's own; a mapped one's copied).
    pub fn into_vec(self) -> Vec<InstanceRecord> {
        match self.store {
            Store::Heap(v) => v,
            Store::File(f) => f.records().to_vec(),
        }
    }

    /// The map's first byte (tests: its resident size in `/proc/self/smaps`).
    #[cfg(test)]
    pub(crate) fn map_addr(&self) -> Option<usize> {
        match &self.store {
            Store::File(FileTable { map: Some(m), .. }) => Some(m.as_ptr() as usize),
            _ => None,
        }
    }
}

/// `copy_within` in pieces of [`RELEASE_EVERY_RECORDS`], in the order that never overwrites a
/// record before it is copied, each piece's pages released after it.
fn copy_released(f: &mut FileTable, src: Range<usize>, dest: usize) {
    let n = src.len();
    let piece = RELEASE_EVERY_RECORDS;
    let mut copy = |k: usize, len: usize| {
        let (s, d) = (src.start + k, dest + k);
        f.records_mut().copy_within(s..s + len, d);
        let _ = f.release_range(s, s + len);
        let _ = f.release_range(d, d + len);
    };
    if dest <= src.start {
        let mut k = 0;
        while k < n {
            let len = piece.min(n - k);
            copy(k, len);
            k += len;
        }
    } else {
        let mut k = n;
        while k > 0 {
            let len = piece.min(k);
            k -= len;
            copy(k, len);
        }
    }
}

impl Deref for InstanceTable {
    type Target = [InstanceRecord];
    fn deref(&self) -> &[InstanceRecord] {
        match &self.store {
            Store::Heap(v) => v,
            Store::File(f) => f.records(),
        }
    }
}

impl DerefMut for InstanceTable {
    fn deref_mut(&mut self) -> &mut [InstanceRecord] {
        match &mut self.store {
            Store::Heap(v) => v,
            Store::File(f) => f.records_mut(),
        }
    }
}

impl From<Vec<InstanceRecord>> for InstanceTable {
    fn from(v: Vec<InstanceRecord>) -> Self {
        Self {
            store: Store::Heap(v),
        }
    }
}

impl FromIterator<InstanceRecord> for InstanceTable {
    fn from_iter<I: IntoIterator<Item = InstanceRecord>>(iter: I) -> Self {
        Vec::from_iter(iter).into()
    }
}

/// A copy on the heap (a mapped table's file is its own).
impl Clone for InstanceTable {
    fn clone(&self) -> Self {
        self.to_vec().into()
    }
}

/// The same records, wherever they are.
impl PartialEq for InstanceTable {
    fn eq(&self, other: &Self) -> bool {
        self[..] == other[..]
    }
}

impl std::fmt::Debug for InstanceTable {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("InstanceTable")
            .field("len", &self.len())
            .field("mapped", &self.is_mapped())
            .finish()
    }
}

impl<'a> IntoIterator for &'a InstanceTable {
    type Item = &'a InstanceRecord;
    type IntoIter = std::slice::Iter<'a, InstanceRecord>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl<'a> IntoIterator for &'a mut InstanceTable {
    type Item = &'a mut InstanceRecord;
    type IntoIter = std::slice::IterMut<'a, InstanceRecord>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter_mut()
    }
}

#[cfg(test)]
mod tests;
