//! A stream split's instance table moved off the heap into an unnamed file, mapped read-only
//! (issue 48 item 1: an import's peak memory; the crate's one `unsafe`). While the import makes
//! the proxy clusters over the split, the split's table (64 bytes an instance, 1.1 GB at island
//! 0.63) would sit on the heap beside the clusters' tables; mapped, its pages count as resident
//! only until [`InstanceMap::release_pages`] drops them (they stay in the page cache and fault
//! back in unchanged when read again), so the import keeps only the batch it is reading.

use motu_abi::InstanceRecord;
use std::fs::File;
use std::io::Write;
use std::path::Path;

/// Records read between two drops of the pages passed (2 MiB) in a sequential walk: the
/// gather back into the package's order runs at the import's post-parse peak, where a wider
/// window showed (16 MiB on island 0.05 and the grid at 2^18 records).
pub(crate) const RELEASE_EVERY_RECORDS: usize = 1 << 15;

/// Instance records in an unnamed file (gone with the map, whatever ends the process).
pub(crate) struct InstanceMap {
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
/// split's stash (`tlas_split/stash.rs`).
pub(crate) fn write_scratch(records: &[InstanceRecord], dir: &Path) -> std::io::Result<File> {
    let file = tempfile::tempfile_in(dir)?;
    {
        let mut w = std::io::BufWriter::with_capacity(1 << 20, &file);
        for piece in records.chunks(1 << 14) {
            w.write_all(bytemuck::cast_slice(piece))?;
        }
        w.flush()?;
    }
    Ok(file)
}

impl InstanceMap {
    /// Writes `records` to an unnamed file in `dir` ([`write_scratch`]) and maps it read-only.
    pub(crate) fn write(records: &[InstanceRecord], dir: &Path) -> std::io::Result<Self> {
        if records.is_empty() {
            return Ok(Self { map: None, len: 0 });
        }
        let file = write_scratch(records, dir)?;
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

    /// The records (the map is page-aligned, so they are aligned too).
    pub(crate) fn records(&self) -> &[InstanceRecord] {
        match &self.map {
            Some(m) => bytemuck::cast_slice(&m[..]),
            None => &[],
        }
    }

    /// Drops the pages of records `begin..end` (those wholly inside and the one `begin` starts
    /// in) from the resident set.
    pub(crate) fn release_range(&self, begin: usize, end: usize) -> std::io::Result<()> {
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
    pub(crate) fn release_pages(&self) -> std::io::Result<()> {
        self.release_range(0, self.len)
    }
}

#[cfg(test)]
mod tests;
