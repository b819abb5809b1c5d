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

/// Records of `T` in an unnamed file mapped shared and writable, grown by
/// [`FileTable::grow_to`] (the instance table's, and the keyed split's arrays: [`ScratchArray`]).
struct FileTable<T: bytemuck::Pod = InstanceRecord> {
    file: File,
    dir: PathBuf,
    /// `None` while the capacity is 0.
    map: Option<memmap2::MmapMut>,
    len: usize,
    capacity: usize,
    /// [`InstanceTable::push`] released the pages of the records below this index last.
    released_to: usize,
    _records: std::marker::PhantomData<T>,
}

impl<T: bytemuck::Pod> FileTable<T> {
    const ITEM_BYTES: usize = std::mem::size_of::<T>();

    /// An empty table in a new unnamed file in `dir`.
    fn create(dir: &Path) -> Result<Self, CompileError> {
        let file = tempfile::tempfile_in(dir).map_err(|source| CompileError::Scratch {
            dir: dir.to_path_buf(),
            source,
        })?;
        Ok(Self {
            file,
            dir: dir.to_path_buf(),
            map: None,
            len: 0,
            capacity: 0,
            released_to: 0,
            _records: std::marker::PhantomData,
        })
    }

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
        let bytes =
            capacity
                .checked_mul(Self::ITEM_BYTES)
                .ok_or_else(|| CompileError::TooMany {
                    what: "instances",
                    count: capacity as u64,
                })?;
        self.map = None;
        let (from, add) = (
            self.capacity * Self::ITEM_BYTES,
            bytes - self.capacity * Self::ITEM_BYTES,
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
                begin * Self::ITEM_BYTES,
                (end - begin) * Self::ITEM_BYTES,
            )
        }
    }

    fn records(&self) -> &[T] {
        match &self.map {
            Some(m) => bytemuck::cast_slice(&m[..self.len * Self::ITEM_BYTES]),
            None => &[],
        }
    }

    fn records_mut(&mut self) -> &mut [T] {
        match &mut self.map {
            Some(m) => bytemuck::cast_slice_mut(&mut m[..self.len * Self::ITEM_BYTES]),
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
        Ok(Self {
            store: Store::File(FileTable::create(dir)?),
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

/// Where a partition's arrays are: on the heap ([`Pages::HEAP`]), or in shared file maps
/// ([`ScratchArray::pages`]) whose pages its passes drop behind them, so a keyed split of tens
/// of millions of instances holds its bounds and indices in the page cache, not the resident
/// set (issue 48 item 1). Mapped pages may be handed only slices of mapped [`ScratchArray`]s
/// (the partition's items, bounds and scratch); on the heap a release would zero the items
/// (valid values, `Zeroable`, but not theirs).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Pages {
    mapped: bool,
}

impl Pages {
    /// Arrays on the heap: nothing is released.
    pub(crate) const HEAP: Self = Self { mapped: false };

    /// Drops the pages of `items` (a part of the partition's arrays) from the resident set.
    pub(crate) fn release<T: bytemuck::Zeroable>(self, items: &[T]) {
        if self.mapped {
            // SAFETY: mapped pages come from a mapped `ScratchArray` for arrays that all are
            // (see above): shared file maps.
            unsafe { release_mapped(items) }
        }
    }
}

/// A fixed-length array of `T` on the heap, or in an unnamed file mapped shared and writable
/// ([`FileTable`], the mapped instance table's store): the keyed split's per-instance bounds and
/// indices (issue 48 item 1: 28 bytes an instance on the heap while the root is partitioned).
/// Mapped, the passes over it drop their pages behind them ([`release_mapped`]).
pub(crate) struct ScratchArray<T: ScratchItem>(ScratchStore<T>);

enum ScratchStore<T: ScratchItem> {
    Heap(Vec<T>),
    /// `T`s as words (`len` of them).
    File(FileTable<u32>, usize),
}

/// An item a [`ScratchArray`] may hold in a file.
///
/// # Safety
/// Every bit pattern is a valid `T`, it has no padding, its alignment is at most 4 and its size
/// a multiple of 4 (so a file of words is a slice of `T`).
pub(crate) unsafe trait ScratchItem: Copy + bytemuck::Zeroable {}
// SAFETY: a word.
unsafe impl ScratchItem for u32 {}
// SAFETY: six `f32`s (any bits are a float) in 24 bytes, their sum: no padding (checked in
// `ScratchArray::zeroed`), aligned to 4.
unsafe impl ScratchItem for ([f32; 3], [f32; 3]) {}

impl<T: ScratchItem> ScratchArray<T> {
    const WORDS: usize = std::mem::size_of::<T>() / 4;

    /// `len` zeroed items: in a new unnamed file in `dir` (its blocks allocated) when given,
    /// else on the heap.
    pub(crate) fn zeroed(len: usize, dir: Option<&Path>) -> Result<Self, CompileError> {
        let Some(dir) = dir else {
            return Ok(Self(ScratchStore::Heap(vec![T::zeroed(); len])));
        };
        assert!(
            std::mem::size_of::<T>() % 4 == 0 && std::mem::align_of::<T>() <= 4,
            "not a scratch item"
        );
        let words = len.checked_mul(Self::WORDS).ok_or(CompileError::TooMany {
            what: "instances",
            count: len as u64,
        })?;
        let mut f = FileTable::<u32>::create(dir)?;
        f.grow_to(words.max(1))?;
        f.len = words;
        Ok(Self(ScratchStore::File(f, len)))
    }

    /// `v` on the heap.
    pub(crate) fn from_vec(v: Vec<T>) -> Self {
        Self(ScratchStore::Heap(v))
    }

    /// Whether the items are in a mapped file (passes may release their pages).
    pub(crate) fn is_mapped(&self) -> bool {
        matches!(self.0, ScratchStore::File(..))
    }

    /// The [`Pages`] of a partition over this array and others where it is: mapped ones only
    /// if every other array handed to it is a mapped `ScratchArray` too.
    pub(crate) fn pages(&self) -> Pages {
        Pages {
            mapped: self.is_mapped(),
        }
    }
}

impl<T: ScratchItem> Deref for ScratchArray<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        match &self.0 {
            ScratchStore::Heap(v) => v,
            ScratchStore::File(f, len) => {
                let words = f.records();
                assert_eq!(words.len(), len * Self::WORDS);
                // SAFETY: `ScratchItem`: `len` items are exactly these words, any bits valid,
                // aligned as words; the borrow of `self` keeps the map alive.
                unsafe { std::slice::from_raw_parts(words.as_ptr().cast::<T>(), *len) }
            }
        }
    }
}

impl<T: ScratchItem> DerefMut for ScratchArray<T> {
    fn deref_mut(&mut self) -> &mut [T] {
        match &mut self.0 {
            ScratchStore::Heap(v) => v,
            ScratchStore::File(f, len) => {
                let len = *len;
                let words = f.records_mut();
                assert_eq!(words.len(), len * Self::WORDS);
                // SAFETY: as in `deref`, borrowed mutably from `self`.
                unsafe { std::slice::from_raw_parts_mut(words.as_mut_ptr().cast::<T>(), len) }
            }
        }
    }
}

/// Drops the pages `items` touch from the resident set (`MADV_DONTNEED`, rounded out to whole
/// pages). A failed hint costs only memory.
///
/// # Safety
/// `items` must lie in a shared map of a file (a mapped [`ScratchArray`] or [`InstanceTable`]):
/// there the pages' data stays in the page cache and file and faults back in when read again
/// (even pages another thread is writing: its stores land in the page cache either way); on the
/// heap (a private anonymous map) the data would read back as zeros.
pub(crate) unsafe fn release_mapped<T>(items: &[T]) {
    if items.is_empty() {
        return;
    }
    let page = rustix::param::page_size();
    let start = items.as_ptr() as usize;
    let end = start + std::mem::size_of_val(items);
    let (first, last) = (start / page * page, end.div_ceil(page) * page);
    // SAFETY: a shared file map starts on a page and its last page is mapped whole, so the
    // rounded range stays inside it; MADV_DONTNEED there only unmaps the pages from this
    // process's page tables (their data stays in the page cache, dirty pages included).
    let _ = unsafe {
        rustix::mm::madvise(
            first as *mut std::ffi::c_void,
            last - first,
            rustix::mm::Advice::LinuxDontNeed,
        )
    };
}

#[cfg(test)]
mod tests;
