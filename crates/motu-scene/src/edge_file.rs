//! The instance edge table, on the heap or moved out of it into an unnamed file mapped
//! read-only (issue 48 item 1: an import's peak memory). A Moana-scale skeleton's edges
//! (52 bytes each, 28M of them) would otherwise sit beside the compiled instance table (64
//! bytes each) at the compile's end; mapped, the pages read count as resident only until
//! [`EdgeTable::release_pages`] drops them (they stay in the page cache and fault back in
//! when read again), so the compiler keeps only the edges it is walking.
//!
//! While parsing, an import's builder appends its edges to an [`EdgeSpill`] a chunk at a time
//! (the heap holds one chunk), and [`EdgeSpill::into_table`] sorts them into CSR order by
//! copying each parent's runs into a second file: no stage holds the whole table in memory.

use std::io::Write;
use std::path::{Path, PathBuf};

/// Edges walked between two drops of the pages passed ([`EdgeTable::release_range`]): ~13 MB
/// of 52-byte edges stay resident at most during a walk over a file-held table.
pub(crate) const RELEASE_EVERY_EDGES: usize = 1 << 18;

/// Where a scene's edges are: every scene starts on the heap; an import moves them to a file.
pub(crate) enum EdgeTable<T> {
    Heap(Vec<T>),
    Mapped(MappedEdges),
}

pub(crate) struct MappedEdges {
    /// The file's map (the file has no name: it goes when the map and handle do, whatever
    /// ends the process).
    map: memmap2::Mmap,
    len: usize,
    /// Edges walked since the pages were last all dropped ([`EdgeTable::note_walked`]).
    walked: std::sync::atomic::AtomicUsize,
}

impl MappedEdges {
    /// Maps `file` (complete, unnamed, written only by this process) as `len` edges of `T`.
    fn of<T>(file: &std::fs::File, len: usize) -> std::io::Result<Self> {
        let bytes = len * std::mem::size_of::<T>();
        // SAFETY: the file is unnamed (O_TMPFILE or unlinked at creation), only this process
        // writes it, and it was written completely before: nobody can truncate or change it
        // under the read-only map.
        let map = unsafe { memmap2::Mmap::map(file)? };
        if map.len() != bytes {
            return Err(std::io::Error::other(format!(
                "edge file maps {} bytes, {bytes} written",
                map.len()
            )));
        }
        Ok(MappedEdges {
            map,
            len,
            walked: Default::default(),
        })
    }
}

/// Edges appended in import order to an unnamed file in `dir` (made at the first append), a
/// chunk at a time, while a builder parses: the builder keeps one chunk on the heap.
pub(crate) struct EdgeSpill {
    dir: PathBuf,
    file: Option<std::fs::File>,
    len: usize,
}

/// A run of consecutive edges of one parent, in import order: (parent, edge count).
pub(crate) type Run = (u32, u32);

impl EdgeSpill {
    pub(crate) fn new(dir: PathBuf) -> Self {
        Self {
            dir,
            file: None,
            len: 0,
        }
    }

    /// The directory the file is (or will be) in, for errors.
    pub(crate) fn dir(&self) -> &Path {
        &self.dir
    }

    /// Edges appended so far.
    pub(crate) fn edge_count(&self) -> usize {
        self.len
    }

    /// Appends `edges` to the file (made on the first call).
    pub(crate) fn append<T: bytemuck::Pod>(&mut self, edges: &[T]) -> std::io::Result<()> {
        if edges.is_empty() {
            return Ok(());
        }
        let file = match &mut self.file {
            Some(f) => f,
            None => self.file.insert(tempfile::tempfile_in(&self.dir)?),
        };
        file.write_all(bytemuck::cast_slice(edges))?;
        self.len += edges.len();
        Ok(())
    }

    /// The appended edges in CSR order, mapped: `runs` (in import order, covering every
    /// appended edge) say whose each edge is; `sorted` that their parents never decrease (the
    /// file is then the table). Otherwise each parent's runs, parents in id order and runs in
    /// import order, are copied into a second unnamed file (the first's pages dropped as they
    /// are copied), which becomes the table: a stable counting sort that holds no edge table
    /// in memory. An empty table on the heap when nothing was appended.
    pub(crate) fn into_table<T: bytemuck::Pod>(
        self,
        runs: &[Run],
        sorted: bool,
    ) -> std::io::Result<EdgeTable<T>> {
        let Some(file) = self.file else {
            return Ok(EdgeTable::Heap(Vec::new()));
        };
        let source = MappedEdges::of::<T>(&file, self.len)?;
        if sorted {
            return Ok(EdgeTable::Mapped(source));
        }
        let source = EdgeTable::<T>::Mapped(source);
        let mut starts = Vec::with_capacity(runs.len());
        let mut at = 0usize;
        for &(_, n) in runs {
            starts.push(at);
            at += n as usize;
        }
        if at != self.len {
            return Err(std::io::Error::other(format!(
                "edge runs cover {at} edges of {}",
                self.len
            )));
        }
        let mut order: Vec<u32> = (0..runs.len() as u32).collect();
        // Stable: a parent's runs stay in import order.
        order.sort_by_key(|&r| runs[r as usize].0);
        let sorted_file = tempfile::tempfile_in(&self.dir)?;
        {
            let mut w = std::io::BufWriter::with_capacity(1 << 20, &sorted_file);
            let mut copied = 0usize;
            for &r in &order {
                let (begin, n) = (starts[r as usize], runs[r as usize].1 as usize);
                w.write_all(bytemuck::cast_slice(&source[begin..begin + n]))?;
                source.release_range(begin, begin + n)?;
                copied += n;
                if copied >= RELEASE_EVERY_EDGES {
                    // Runs shorter than a page leave their pages partly read: drop them all.
                    source.release_pages()?;
                    copied = 0;
                }
            }
            w.flush()?;
        }
        drop(source);
        Ok(EdgeTable::Mapped(MappedEdges::of::<T>(
            &sorted_file,
            self.len,
        )?))
    }
}

impl<T: bytemuck::Pod> std::ops::Deref for EdgeTable<T> {
    type Target = [T];
    fn deref(&self) -> &[T] {
        match self {
            EdgeTable::Heap(v) => v,
            EdgeTable::Mapped(m) => {
                let bytes = m.map.get(..m.len * std::mem::size_of::<T>());
                bytemuck::cast_slice(bytes.unwrap_or_default())
            }
        }
    }
}

impl<T: bytemuck::Pod> EdgeTable<T> {
    /// Moves heap edges into an unnamed file in `dir`, mapped read-only; the heap table is
    /// freed. Already mapped or empty tables stay as they are. On error the table is
    /// unchanged.
    pub(crate) fn move_to_file(&mut self, dir: &Path) -> std::io::Result<()> {
        let EdgeTable::Heap(edges) = self else {
            return Ok(());
        };
        if edges.is_empty() {
            return Ok(());
        }
        let file = tempfile::tempfile_in(dir)?;
        {
            let mut w = std::io::BufWriter::with_capacity(1 << 20, &file);
            // In pieces: one write of the whole table would be fine too, but a short
            // buffer keeps the dirty page cache flowing to disk as it is written.
            for piece in edges.chunks(1 << 16) {
                w.write_all(bytemuck::cast_slice(piece))?;
            }
            w.flush()?;
        }
        let len = edges.len();
        *self = EdgeTable::Mapped(MappedEdges::of::<T>(&file, len)?);
        Ok(())
    }

    /// Drops the pages of edges `begin..end` of a mapped table from the resident set (those
    /// wholly inside the range and the one `begin` starts in; a no-op on the heap): walks
    /// over every edge call it as they pass, so only a window of the table stays resident.
    pub(crate) fn release_range(&self, begin: usize, end: usize) -> std::io::Result<()> {
        let EdgeTable::Mapped(m) = self else {
            return Ok(());
        };
        let size = std::mem::size_of::<T>();
        let end = end.min(m.len);
        if begin >= end {
            return Ok(());
        }
        let (from, to) = (begin * size, end * size);
        // SAFETY: as in `release_pages`: a read-only shared map of a file nobody else writes;
        // dropped pages fault back in from the file unchanged (memmap2 aligns the start down
        // to a page; the range is inside the map).
        unsafe {
            m.map
                .unchecked_advise_range(memmap2::UncheckedAdvice::DontNeed, from, to - from)
        }
    }

    /// Drops the mapped edges' pages from this process's resident set (no-op on the heap):
    /// they stay in the page cache and fault back in when read again, with the same bytes.
    pub(crate) fn release_pages(&self) -> std::io::Result<()> {
        match self {
            EdgeTable::Heap(_) => Ok(()),
            // SAFETY: a read-only shared map of a file nobody else can write: MADV_DONTNEED
            // only unmaps its pages, and a later read faults the same bytes back in from
            // the file (no private changes exist that it could discard).
            EdgeTable::Mapped(m) => unsafe {
                m.map.unchecked_advise(memmap2::UncheckedAdvice::DontNeed)
            },
        }
    }

    /// Counts `n` edges walked whose pages may still be resident; once
    /// [`RELEASE_EVERY_EDGES`] have been, every page of a mapped table is dropped.
    pub(crate) fn note_walked(&self, n: usize) {
        let EdgeTable::Mapped(m) = self else {
            return;
        };
        use std::sync::atomic::Ordering::Relaxed;
        if m.walked.fetch_add(n, Relaxed) + n >= RELEASE_EVERY_EDGES {
            m.walked.store(0, Relaxed);
            // A failed drop leaves pages resident; the edges read the same either way.
            let _ = self.release_pages();
        }
    }

    pub(crate) fn is_mapped(&self) -> bool {
        matches!(self, EdgeTable::Mapped(_))
    }
}

#[cfg(test)]
mod tests;
