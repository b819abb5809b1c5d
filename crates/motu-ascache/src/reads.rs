//! Reading entries of the cache directory: checked reads of one file, and batches of them
//! planned on the cache's thread, read on any thread (several at once) and handed back to be
//! indexed and counted ([`DiskCache::plan_reads`](crate::DiskCache::plan_reads),
//! [`ReadPlan::run`], [`DiskCache::finish_reads`](crate::DiskCache::finish_reads)), so a
//! caller can read the next entries while its device works.

use std::fs::{self, File};
use std::io::{self, Read};
use std::path::{Path, PathBuf};
use std::time::{Instant, SystemTime};

use xxhash_rust::xxh3::xxh3_64;

use crate::blob::{Blob, BlobPool};
use crate::compat::{serialized_header, Compatibility, SERIALIZED_HEADER_BYTES};
use crate::entry::{decode_header, EntryError, ENTRY_HEADER_BYTES};
use crate::key::CacheKey;

/// Why a read returned nothing.
pub(crate) enum ReadMiss {
    Absent,
    /// A bad entry, and the identity of the file that was read.
    Bad(EntryError, Option<FileId>),
    Io(io::Error),
}

/// A file's identity (device, inode): a bad entry is removed only while its name still
/// points at the file that was read, never at an entry another process renamed over it since.
#[derive(Clone, Copy, PartialEq, Eq)]
pub(crate) struct FileId(u64, u64);

pub(crate) fn file_id(meta: &fs::Metadata) -> Option<FileId> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        Some(FileId(meta.dev(), meta.ino()))
    }
    #[cfg(not(unix))]
    {
        let _ = meta;
        None
    }
}

/// Threads [`ReadPlan::run`] (and [`DiskCache::get_many`](crate::DiskCache::get_many)) reads
/// entries on, at most.
pub const READ_THREADS: usize = 8;

pub(crate) type ReadResult = Result<Blob, ReadMiss>;

/// [`read_entry`], and a hit's file becomes the most recently used: recency for this and
/// every later process (a file we may not touch, another user's or in a read-only directory,
/// keeps its old time).
pub(crate) fn read_and_touch(
    path: &Path,
    key: &CacheKey,
    compat: &dyn Compatibility,
    pool: &BlobPool,
) -> ReadResult {
    let (blob, file) = read_entry(path, key, compat, pool)?;
    if let Err(e) = file.set_modified(SystemTime::now()) {
        tracing::trace!(path = %path.display(), error = %e, "hit not touched");
    }
    Ok(blob)
}

/// Reads and checks `key`'s entry at `path` into a buffer of `pool`; returns its blob and the
/// open file (to touch).
fn read_entry(
    path: &Path,
    key: &CacheKey,
    compat: &dyn Compatibility,
    pool: &BlobPool,
) -> Result<(Blob, File), ReadMiss> {
    let mut file = match File::open(path) {
        Ok(f) => f,
        // A shard path that is a file holds no entry either.
        Err(e)
            if matches!(
                e.kind(),
                io::ErrorKind::NotFound | io::ErrorKind::NotADirectory
            ) =>
        {
            return Err(ReadMiss::Absent)
        }
        Err(e) => return Err(ReadMiss::Io(e)),
    };
    let meta = file.metadata().map_err(ReadMiss::Io)?;
    let (file_bytes, id) = (meta.len(), file_id(&meta));
    let bad = |e: EntryError| ReadMiss::Bad(e, id);
    if file_bytes < ENTRY_HEADER_BYTES as u64 {
        return Err(bad(EntryError::Truncated {
            file_bytes,
            expected_bytes: ENTRY_HEADER_BYTES as u64,
        }));
    }
    let mut h = [0u8; ENTRY_HEADER_BYTES];
    file.read_exact(&mut h).map_err(ReadMiss::Io)?;
    // The length is checked against the file's before any allocation of that size.
    let header = decode_header(&h, key, file_bytes).map_err(bad)?;
    if header.blob_bytes < SERIALIZED_HEADER_BYTES as u64 {
        return Err(bad(EntryError::NoSerializationHeader(header.blob_bytes)));
    }
    let len = usize::try_from(header.blob_bytes).map_err(|_| {
        ReadMiss::Io(io::Error::new(
            io::ErrorKind::OutOfMemory,
            "entry larger than the address space",
        ))
    })?;
    // Read straight into the buffer's spare capacity (`File` reads into uninitialised memory:
    // no zero fill), one already paged in when the pool had one.
    let mut buf = pool.take(len);
    match (&mut file)
        .take(header.blob_bytes)
        .read_to_end(buf.bytes_mut())
    {
        Ok(n) if n == len => {}
        // The file shrank after its length was read (another process rewriting it in place
        // would not: entries are only ever renamed into place).
        Ok(_) => {
            return Err(bad(EntryError::Truncated {
                file_bytes,
                expected_bytes: file_bytes,
            }))
        }
        Err(e) => return Err(ReadMiss::Io(e)),
    }
    let blob = buf.freeze();
    let computed = xxh3_64(&blob);
    if computed != header.blob_xxh3 {
        return Err(bad(EntryError::BlobChecksum {
            stored: header.blob_xxh3,
            computed,
        }));
    }
    match serialized_header(&blob) {
        Some(h) if compat.compatible(h) => Ok((blob, file)),
        _ => Err(bad(EntryError::Incompatible)),
    }
}

/// Entries to read, planned by [`DiskCache::plan_reads`](crate::DiskCache::plan_reads): it
/// owns what the reads need, so [`run`](Self::run) may go on any thread while the cache is
/// used for other things; [`DiskCache::finish_reads`](crate::DiskCache::finish_reads) then
/// indexes and counts what it read, as [`get`](crate::DiskCache::get) would.
pub struct ReadPlan {
    pub(crate) keys: Vec<CacheKey>,
    /// Per key, a blob answered already (the background writer still held it).
    pub(crate) found: Vec<Option<Blob>>,
    /// The keys (by index) whose files are read, and those files.
    pub(crate) todo: Vec<(usize, PathBuf)>,
    pub(crate) pool: BlobPool,
}

/// What [`ReadPlan::run`] read, for [`DiskCache::finish_reads`](crate::DiskCache::finish_reads).
pub struct ReadsDone {
    pub(crate) keys: Vec<CacheKey>,
    pub(crate) found: Vec<Option<Blob>>,
    pub(crate) reads: Vec<(usize, PathBuf, ReadResult)>,
    /// Wall milliseconds the reads took (on the thread that ran them).
    pub read_ms: f64,
}

impl ReadPlan {
    /// How many entry files the plan reads.
    pub fn files(&self) -> usize {
        self.todo.len()
    }

    /// Reads and checks the planned files on up to [`READ_THREADS`] threads (one thread read
    /// the H200 host's ~3 MB entries at 0.6 GB/s, checksums included); `compat` checks each
    /// entry's serialization header.
    pub fn run(self, compat: &(dyn Compatibility + Sync)) -> ReadsDone {
        let t = Instant::now();
        let ReadPlan {
            keys,
            found,
            todo,
            pool,
        } = self;
        let threads = READ_THREADS
            .min(std::thread::available_parallelism().map_or(1, usize::from))
            .min(todo.len())
            .max(1);
        let next = std::sync::atomic::AtomicUsize::new(0);
        let mut results: Vec<Option<ReadResult>> = (0..todo.len()).map(|_| None).collect();
        std::thread::scope(|scope| {
            let workers: Vec<_> = (0..threads)
                .map(|_| {
                    scope.spawn(|| {
                        let mut done = Vec::new();
                        loop {
                            let j = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            let Some((i, path)) = todo.get(j) else {
                                break done;
                            };
                            done.push((j, read_and_touch(path, &keys[*i], compat, &pool)));
                        }
                    })
                })
                .collect();
            for w in workers {
                // A panicking reader is a bug; its keys stay misses (rebuilt).
                for (j, r) in w.join().unwrap_or_default() {
                    results[j] = Some(r);
                }
            }
        });
        let reads = todo
            .into_iter()
            .zip(results)
            .map(|((i, path), r)| (i, path, r.unwrap_or(Err(ReadMiss::Absent))))
            .collect();
        ReadsDone {
            keys,
            found,
            reads,
            read_ms: t.elapsed().as_secs_f64() * 1e3,
        }
    }
}
