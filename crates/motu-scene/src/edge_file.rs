//! The instance edge table, on the heap or moved out of it into an unnamed file mapped
//! read-only (issue 48 item 1: an import's peak memory). A Moana-scale skeleton's edges
//! (52 bytes each, 28M of them) would otherwise sit beside the compiled instance table (64
//! bytes each) at the compile's end; mapped, the pages read count as resident only until
//! [`EdgeTable::release_pages`] drops them (they stay in the page cache and fault back in
//! when read again), so the compiler keeps only the edges it is walking.

use std::io::Write;
use std::path::Path;

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
        // SAFETY: the file is unnamed (O_TMPFILE or unlinked at creation) and only this
        // handle writes it, and it was written completely above: nobody can truncate or
        // change it under the read-only map.
        let map = unsafe { memmap2::Mmap::map(&file)? };
        if map.len() != std::mem::size_of_val(edges.as_slice()) {
            return Err(std::io::Error::other(format!(
                "edge file maps {} bytes, {} written",
                map.len(),
                std::mem::size_of_val(edges.as_slice())
            )));
        }
        let len = edges.len();
        *self = EdgeTable::Mapped(MappedEdges { map, len });
        Ok(())
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

    pub(crate) fn is_mapped(&self) -> bool {
        matches!(self, EdgeTable::Mapped(_))
    }
}

#[cfg(test)]
mod tests;
