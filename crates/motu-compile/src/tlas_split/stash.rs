//! A split TLAS's records parked in an unnamed scratch file while its partition runs over
//! indices (issue 48 item 1). Splitting a range of `n` instances in memory holds the records
//! (64 bytes each) beside their bounds (24) and the permutation's arrays (5): 93 bytes an
//! instance at once, the import's peak where the root is split (island 0.63: 17.5M instances
//! over the 2^24 − 1 cap). Keyed, the partition holds bounds and indices (33 bytes), and the
//! records come back from the file into their places (68 bytes: the records and where each
//! goes). The partition looks at bounds only, so it permutes indices exactly as it would
//! permute records: the same split, bit for bit.

use crate::split::Pages;
use crate::{CompileError, InstanceTable};
use motu_abi::InstanceRecord;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// Ranges of fewer instances are split in memory: their records (under 64 MiB) would stay in
/// the allocator's arenas when freed (glibc maps only blocks over 32 MiB apart and gives
/// those back), so parking them saves nothing.
#[cfg(not(test))]
pub(crate) const MIN_INSTANCES: usize = 1 << 20;
/// Every range in tests, so small scenes take the keyed path.
#[cfg(test)]
pub(crate) const MIN_INSTANCES: usize = 1;

/// Records read back at a time (4 MiB).
const READ_RECORDS: usize = 1 << 16;

/// Places of a mapped table written at a time by a put-back (64 MiB resident; 27 buckets at
/// scale 1's 28M instances).
#[cfg(not(test))]
const BUCKET_RECORDS: usize = 1 << 20;
/// Several buckets in tests' small scenes.
#[cfg(test)]
const BUCKET_RECORDS: usize = 1 << 9;

/// Each bucket file's write buffer while the put-back deals records into them.
const DEAL_BUFFER_BYTES: usize = 1 << 18;

/// The tail of an instance table, in a file.
pub(crate) struct Stash {
    file: File,
    dir: PathBuf,
    count: usize,
    /// The table's capacity before: given back with the records, so the emitter's one
    /// reservation holds.
    capacity: usize,
}

impl Stash {
    /// Moves `instances[base..]` to an unnamed file in `dir` and frees its memory (a mapped
    /// table's pages released as they are written).
    pub(crate) fn take_tail(
        instances: &mut InstanceTable,
        base: usize,
        dir: &Path,
    ) -> Result<Self, CompileError> {
        let err = |source| CompileError::Scratch {
            dir: dir.to_path_buf(),
            source,
        };
        let file = crate::instance_map::write_scratch_then(&instances[base..], dir, &mut |b, e| {
            instances.release_range(base + b, base + e)
        })
        .map_err(err)?;
        let (count, capacity) = (instances.len() - base, instances.capacity());
        instances.truncate(base);
        instances.shrink_to_fit();
        tracing::debug!(
            instances = count,
            bytes = count * std::mem::size_of::<InstanceRecord>(),
            "split by key: the records wait in a scratch file"
        );
        Ok(Self {
            file,
            dir: dir.to_path_buf(),
            count,
            capacity,
        })
    }

    /// `f` of every stashed record, in order, into `out` (as long as the stash): read back a
    /// chunk at a time, each chunk's records mapped on the thread pool and its places' pages
    /// released after (`pages`: `out` is mapped).
    pub(crate) fn map_records_into<B: Send + bytemuck::Zeroable>(
        &mut self,
        out: &mut [B],
        pages: Pages,
        f: impl Fn(&InstanceRecord) -> B + Sync,
    ) -> Result<(), CompileError> {
        use rayon::prelude::*;
        if out.len() != self.count {
            return Err(CompileError::Internal(format!(
                "{} places for {} stashed instances",
                out.len(),
                self.count
            )));
        }
        self.read_chunks(|start, records| {
            let chunk = &mut out[start..start + records.len()];
            chunk
                .par_iter_mut()
                .zip(records.par_iter())
                .for_each(|(o, r)| *o = f(r));
            pages.release(chunk);
            Ok(())
        })
    }

    /// Reads the stash from its start a chunk of [`READ_RECORDS`] at a time, giving `each` the
    /// index of the chunk's first record and its records.
    fn read_chunks(
        &mut self,
        mut each: impl FnMut(usize, &[InstanceRecord]) -> Result<(), CompileError>,
    ) -> Result<(), CompileError> {
        let err = |source| CompileError::Scratch {
            dir: self.dir.clone(),
            source,
        };
        self.file.seek(SeekFrom::Start(0)).map_err(err)?;
        let mut buf = vec![InstanceRecord::default(); READ_RECORDS.min(self.count)];
        for start in (0..self.count).step_by(READ_RECORDS) {
            let records = &mut buf[..READ_RECORDS.min(self.count - start)];
            self.file
                .read_exact(bytemuck::cast_slice_mut(records))
                .map_err(err)?;
            each(start, records)?;
        }
        Ok(())
    }

    /// Appends the stashed records to `instances` in the partition's order: `order[j]` is the
    /// stashed record that goes to place `j` (a permutation of `0..count`). The file is read
    /// in order and each record written to its place. In a mapped table random writes over
    /// the whole range would make all of it resident, so the places go in buckets of
    /// [`BUCKET_RECORDS`]: one read of the stash deals each record (with its place) into its
    /// bucket's unnamed file, then each bucket is written from its file and its pages released.
    pub(crate) fn put_back(
        mut self,
        instances: &mut InstanceTable,
        order: &[u32],
        pages: Pages,
    ) -> Result<(), CompileError> {
        if order.len() != self.count {
            return Err(CompileError::Internal(format!(
                "a keyed split ordered {} of {} instances",
                order.len(),
                self.count
            )));
        }
        let mut place = vec![0u32; self.count];
        for (k, chunk) in order.chunks(READ_RECORDS).enumerate() {
            for (j, &from) in chunk.iter().enumerate() {
                place[from as usize] = (k * READ_RECORDS + j) as u32;
            }
            pages.release(chunk);
        }
        let base = instances.len();
        instances.try_reserve_exact(self.capacity.max(base + self.count) - base)?;
        instances.resize(base + self.count, bytemuck::Zeroable::zeroed())?;
        let dir = self.dir.clone();
        let err = |source| CompileError::Scratch {
            dir: dir.clone(),
            source,
        };
        let buckets = self.count.div_ceil(BUCKET_RECORDS);
        if !instances.is_mapped() || buckets <= 1 {
            self.read_chunks(|start, records| {
                for (r, &to) in records.iter().zip(&place[start..]) {
                    instances[base + to as usize] = *r;
                }
                Ok(())
            })?;
            instances.release_range(base, base + self.count);
            return Ok(());
        }
        // Deal: each record with its place into its bucket's file.
        let mut files = Vec::with_capacity(buckets);
        for _ in 0..buckets {
            let f = tempfile::tempfile_in(&dir).map_err(err)?;
            files.push(std::io::BufWriter::with_capacity(DEAL_BUFFER_BYTES, f));
        }
        self.read_chunks(|start, records| {
            for (r, &to) in records.iter().zip(&place[start..]) {
                let w = &mut files[to as usize / BUCKET_RECORDS];
                w.write_all(&to.to_le_bytes()).map_err(err)?;
                w.write_all(bytemuck::bytes_of(r)).map_err(err)?;
            }
            Ok(())
        })?;
        drop(place);
        drop(self.file);
        // Place: a bucket at a time, read back in pieces.
        const DEALT: usize = 4 + std::mem::size_of::<InstanceRecord>();
        let mut bytes = vec![0u8; DEALT * READ_RECORDS];
        for (b, w) in files.into_iter().enumerate() {
            let mut f = w.into_inner().map_err(|e| err(e.into_error()))?;
            let len = f.stream_position().map_err(err)? as usize;
            f.seek(SeekFrom::Start(0)).map_err(err)?;
            let mut left = len;
            while left > 0 {
                let piece = &mut bytes[..left.min(DEALT * READ_RECORDS)];
                f.read_exact(piece).map_err(err)?;
                for e in piece.chunks_exact(DEALT) {
                    let to = u32::from_le_bytes([e[0], e[1], e[2], e[3]]) as usize;
                    instances[base + to] = bytemuck::pod_read_unaligned(&e[4..]);
                }
                left -= piece.len();
            }
            let first = base + b * BUCKET_RECORDS;
            instances.release_range(first, (first + BUCKET_RECORDS).min(base + self.count));
        }
        Ok(())
    }
}
