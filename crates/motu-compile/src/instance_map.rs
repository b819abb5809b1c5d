//! An instance table moved off the heap into an unnamed file, mapped read-only (issue 48 item 1:
//! an import's peak memory; the crate's one `unsafe`): the stream split's (split order) while
//! the import makes the proxy clusters over it, and the package's own ([`park_table`]) from the
//! stream split to the end of the import. On the heap either would sit beside the clusters'
//! tables (64 bytes an instance, 1.1 GB at island 0.63); mapped, its pages count as resident
//! only until [`InstanceMap::release_pages`] drops them (they stay in the page cache and fault
//! back in unchanged when read again), so the import keeps only the piece it is reading.

use motu_abi::InstanceRecord;
use std::fs::File;
use std::io::Write;
use std::path::Path;

/// Records read between two drops of the pages passed (2 MiB) in a sequential walk: the
/// gather back into the package's order runs at the import's post-parse peak, where a wider
/// window showed (16 MiB on island 0.05 and the grid at 2^18 records).
pub(crate) const RELEASE_EVERY_RECORDS: usize = 1 << 15;

/// Tables of fewer records stay on the heap ([`park_table`]): 4 MiB, the size below which the
/// file and its writes cost more than the memory they free.
#[cfg(not(test))]
pub const PARK_MIN_INSTANCES: usize = 1 << 16;
/// Every table in tests, so small scenes take the mapped path.
#[cfg(test)]
pub const PARK_MIN_INSTANCES: usize = 1;

/// Instance records in an unnamed file (gone with the map, whatever ends the process).
pub struct InstanceMap {
    /// `None` for an empty table (nothing to map).
    map: Option<memmap2::Mmap>,
    len: usize,
}

impl std::fmt::Debug for InstanceMap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("InstanceMap")
            .field("len", &self.len)
            .finish()
    }
}

/// Writes `records` to a new unnamed file in `dir` (through a short buffer, so the dirty page
/// cache flows to disk as it is written) and returns it: an [`InstanceMap`]'s, and a keyed
/// split's stash (`tlas_split/stash.rs`). Calls `release(begin, end)` after records
/// `begin..end` are written, every [`RELEASE_EVERY_RECORDS`] (`records` in a mapped table:
/// its pages dropped behind).
pub(crate) fn write_scratch_then(
    records: &[InstanceRecord],
    dir: &Path,
    release: &mut dyn FnMut(usize, usize),
) -> std::io::Result<File> {
    let file = tempfile::tempfile_in(dir)?;
    {
        let mut w = std::io::BufWriter::with_capacity(1 << 20, &file);
        for (k, piece) in records.chunks(RELEASE_EVERY_RECORDS).enumerate() {
            w.write_all(bytemuck::cast_slice(piece))?;
            let begin = k * RELEASE_EVERY_RECORDS;
            release(begin, begin + piece.len());
        }
        w.flush()?;
    }
    Ok(file)
}

/// A copy of `table` (of at least [`PARK_MIN_INSTANCES`] records) written to an unnamed file
/// in `dir` and mapped read-only ([`InstanceMap::write`]; a mapped table's pages released as
/// they are read); `None` for a smaller table, which stays where it is. The caller frees or
/// reuses the table.
pub fn park_table(
    table: &crate::InstanceTable,
    dir: &Path,
) -> Result<Option<InstanceMap>, crate::CompileError> {
    if table.len() < PARK_MIN_INSTANCES {
        return Ok(None);
    }
    InstanceMap::write_then(table, dir, &mut |b, e| table.release_range(b, e))
        .map(Some)
        .map_err(|source| crate::CompileError::Scratch {
            dir: dir.to_path_buf(),
            source,
        })
}

impl InstanceMap {
    /// Writes `records` to an unnamed file in `dir` ([`write_scratch_then`]) and maps it read-only.
    pub fn write(records: &[InstanceRecord], dir: &Path) -> std::io::Result<Self> {
        Self::write_then(records, dir, &mut |_, _| {})
    }

    /// [`InstanceMap::write`] that calls `release(begin, end)` behind the records written
    /// ([`write_scratch_then`]).
    fn write_then(
        records: &[InstanceRecord],
        dir: &Path,
        release: &mut dyn FnMut(usize, usize),
    ) -> std::io::Result<Self> {
        if records.is_empty() {
            return Ok(Self { map: None, len: 0 });
        }
        let file = write_scratch_then(records, dir, release)?;
        let bytes = std::mem::size_of_val(records);
        // SAFETY: the file is unnamed (O_TMPFILE or unlinked at creation), only this process
        // wrote it, completely, before mapping: nobody can truncate or change it under the
        // read-only map.
        let map = unsafe { memmap2::Mmap::map(&file)? };
        if map.len() != bytes {
            return Err(std::io::Error::other(format!(
                "instance file maps {} bytes, {bytes} written",
                map.len()
            )));
        }
        Ok(Self {
            map: Some(map),
            len: records.len(),
        })
    }

    /// The first `len` records of `map` (a mapped [`crate::InstanceTable`] that stopped
    /// writing: no copy).
    pub(crate) fn from_map(map: memmap2::Mmap, len: usize) -> Self {
        assert!(len * std::mem::size_of::<InstanceRecord>() <= map.len());
        Self {
            map: Some(map),
            len,
        }
    }

    /// A map of no record.
    pub(crate) fn from_map_empty() -> Self {
        Self { map: None, len: 0 }
    }

    /// How many records the map holds.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Whether the map holds no record.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// The records (the map is page-aligned, so they are aligned too).
    pub fn records(&self) -> &[InstanceRecord] {
        match &self.map {
            Some(m) => bytemuck::cast_slice(&m[..self.len * std::mem::size_of::<InstanceRecord>()]),
            None => &[],
        }
    }

    /// Drops the pages of records `begin..end` (those wholly inside and the one `begin` starts
    /// in) from the resident set.
    pub fn release_range(&self, begin: usize, end: usize) -> std::io::Result<()> {
        let (Some(m), end) = (&self.map, end.min(self.len)) else {
            return Ok(());
        };
        if begin >= end {
            return Ok(());
        }
        let size = std::mem::size_of::<InstanceRecord>();
        // SAFETY: a read-only shared map of a file nobody else writes: MADV_DONTNEED only
        // unmaps its pages and a later read faults the same bytes back in (memmap2 aligns the
        // start down to a page; the range is inside the map).
        unsafe {
            m.unchecked_advise_range(
                memmap2::UncheckedAdvice::DontNeed,
                begin * size,
                (end - begin) * size,
            )
        }
    }

    /// Drops every page of the map from the resident set.
    pub fn release_pages(&self) -> std::io::Result<()> {
        self.release_range(0, self.len)
    }
}

#[cfg(test)]
mod tests;
