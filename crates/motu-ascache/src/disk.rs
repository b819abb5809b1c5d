//! Tier 2: serialized structures in a cache directory that outlives the process.
//!
//! Nothing here fails a render: every problem is a miss or a skipped write, a
//! `tracing::warn!` naming the file and the reason, and a count in [`DiskStats::warnings`].

use std::ffi::OsString;
use std::fs;
use std::io;
use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime};

use crate::blob::{Blob, BlobPool};
use crate::compat::{Compatibility, SERIALIZED_HEADER_BYTES};
use crate::entry::{
    entry_key, entry_path, temp_owner, EntryError, ENTRY_HEADER_BYTES, VERSION_DIR,
};
pub use crate::file::io_reason;
use crate::file::{create_private_dir_all, write_entry_file};
use crate::key::CacheKey;
use crate::lru::ByteLru;
use crate::rates::{load_rates, rates_path, save_rates, DeviceRates, RatesError};
pub use crate::reads::READ_THREADS;
use crate::reads::{file_id, read_and_touch, FileId, ReadMiss, ReadPlan, ReadResult, ReadsDone};
use crate::stats::DiskStats;
use crate::writer::{Job, Writer};

/// The environment variable naming the cache directory (before the XDG default).
pub const CACHE_DIR_ENV: &str = "MOTU_AS_CACHE";

/// The most the cache directory holds by default: 32 GiB.
///
/// Enough for the compacted structures of a first frame of the largest scenes measured
/// (island at scale 0.63 builds 19–33 GB over a frame's passes at 8–24 GiB budgets, with
/// repeats), while a cache the user never asked for stays a small part of a render node's disk.
pub const DEFAULT_DISK_CAPACITY_BYTES: u64 = 32 << 30;

/// By default the cache also leaves at least half of its filesystem's free space (at open) to
/// everything else: [`default_disk_capacity_bytes`].
pub const DEFAULT_FREE_SHARE_DENOMINATOR: u64 = 2;

/// A temp file is left alone until it is this old (and its writer is gone): a live writer
/// finishes an entry in seconds.
pub const DEFAULT_STALE_TEMP_AGE: Duration = Duration::from_secs(10 * 60);

/// The default cache directory: `$MOTU_AS_CACHE` if set and not empty, else
/// `$XDG_CACHE_HOME/motu/as-cache` (when absolute, as the XDG spec requires), else
/// `$HOME/.cache/motu/as-cache`; `None` when none is set (no disk tier).
pub fn default_dir() -> Option<PathBuf> {
    dir_from_env(|name| std::env::var_os(name))
}

/// [`default_dir`]'s rule over any environment (`var` returns a variable's value).
pub fn dir_from_env(var: impl Fn(&str) -> Option<OsString>) -> Option<PathBuf> {
    let set = |name: &str| var(name).filter(|v| !v.is_empty()).map(PathBuf::from);
    if let Some(dir) = set(CACHE_DIR_ENV) {
        return Some(dir);
    }
    if let Some(xdg) = set("XDG_CACHE_HOME").filter(|p| p.is_absolute()) {
        return Some(xdg.join("motu").join("as-cache"));
    }
    set("HOME").map(|home| home.join(".cache").join("motu").join("as-cache"))
}

/// The default bound: [`DEFAULT_DISK_CAPACITY_BYTES`], or what the cache holds plus half the
/// filesystem's free space when that is smaller (`free_bytes` unknown: the constant).
pub fn default_disk_capacity_bytes(cache_bytes: u64, free_bytes: Option<u64>) -> u64 {
    match free_bytes {
        Some(free) => DEFAULT_DISK_CAPACITY_BYTES
            .min(cache_bytes.saturating_add(free / DEFAULT_FREE_SHARE_DENOMINATOR)),
        None => DEFAULT_DISK_CAPACITY_BYTES,
    }
}

/// Bytes an unprivileged user may still write on `path`'s filesystem.
pub fn filesystem_free_bytes(path: &Path) -> Option<u64> {
    #[cfg(unix)]
    {
        let s = rustix::fs::statvfs(path).ok()?;
        s.f_bavail.checked_mul(s.f_frsize)
    }
    #[cfg(not(unix))]
    {
        let _ = path;
        None
    }
}

/// How a [`DiskCache`] is opened.
#[derive(Debug, Clone)]
pub struct DiskOptions {
    /// The bound on the entries' file bytes; `None`: [`default_disk_capacity_bytes`].
    pub capacity_bytes: Option<u64>,
    /// Temp files of dead writers older than this are removed at open.
    pub stale_temp_age: Duration,
    /// fsync each entry before renaming it into place (default). Without it a power loss can
    /// leave an entry whose bytes never reached the disk; its checksum then fails and it is
    /// rebuilt with a warning, so turning it off trades a warning after a crash for write speed.
    pub sync: bool,
    /// For tests: every write fails with this error after its temp file holds the header and
    /// half the blob (`StorageFull` is a disk filling up mid-entry, `PermissionDenied` a
    /// read-only directory), down the same clean-up and warning path a real failure takes.
    pub fail_writes_with: Option<io::ErrorKind>,
    /// Write entries on a thread of their own (`put` queues and returns; a queued entry is
    /// answered from memory until it is on disk; dropping the cache writes the queue first).
    /// Off by default: a caller on a frame's thread turns it on.
    pub background: bool,
    /// With `background`: the most blob bytes queued before `put` waits for the writer.
    pub max_pending_bytes: u64,
}

/// The default bound of [`DiskOptions::max_pending_bytes`]: 1 GiB. The queued blobs are
/// mostly the host tier's too (shared, not copied), so this bounds how far the disk may lag
/// behind the builds rather than memory alone.
pub const DEFAULT_MAX_PENDING_BYTES: u64 = 1 << 30;

impl Default for DiskOptions {
    fn default() -> Self {
        Self {
            capacity_bytes: None,
            stale_temp_age: DEFAULT_STALE_TEMP_AGE,
            sync: true,
            fail_writes_with: None,
            background: false,
            max_pending_bytes: DEFAULT_MAX_PENDING_BYTES,
        }
    }
}

/// Whether process `pid` runs on this machine; `None` when that cannot be told (no /proc).
fn process_alive(pid: u32) -> Option<bool> {
    let proc = Path::new("/proc");
    if !proc.join("self").exists() {
        return None;
    }
    Some(proc.join(pid.to_string()).exists())
}

/// A file found by the scan at open.
struct Found {
    key: CacheKey,
    bytes: u64,
    modified: SystemTime,
}

/// Serialized structures in a cache directory, one file per entry (layout and header:
/// [`entry`](crate::entry)), bounded by their file bytes with the least recently used removed
/// first. Recency is the file's modification time, set on every hit, so it is shared by every
/// process using the directory and survives them; the scan at open orders the entries by it.
///
/// - **Writes** are atomic: the entry is written to a temp file in its own directory, fsynced
///   and renamed over its name, so a reader (in any process) sees a whole entry or none. Two
///   processes writing one key both write whole entries; the last rename wins.
/// - **Reads** check the header (magic, format, header checksum, key, length), the blob's
///   checksum and the caller's [`Compatibility`]; a bad entry is a miss with a warning, and
///   its file is removed (if it is still the file that was read).
/// - **Failures** never surface as errors: a directory that cannot be created, a read-only
///   directory, a full disk or any IO error on a write is counted, warned once, and turns
///   writes off for this cache's life; reads go on.
/// - **Other processes** sharing the directory may add or remove entries at any time: a key
///   missing from this process's index is still looked up on disk, and the byte count is this
///   process's view (rescanned at the next open), so several writers may together overshoot the
///   bound until one of them evicts.
pub struct DiskCache {
    root: PathBuf,
    lru: ByteLru<CacheKey, ()>,
    writable: bool,
    /// False when the entries' directory does not exist (it could not be created): no reads.
    readable: bool,
    /// Whether an unreadable entry was warned about (later ones are only counted).
    read_warned: bool,
    options: DiskOptions,
    stats: DiskStats,
    /// With [`DiskOptions::background`]: the thread that writes entries.
    writer: Option<Writer>,
    /// Where read blobs' buffers come from ([`set_pool`](Self::set_pool)).
    pool: BlobPool,
}

impl std::fmt::Debug for DiskCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DiskCache")
            .field("root", &self.root)
            .field("stats", &self.stats())
            .finish()
    }
}

impl DiskCache {
    /// Opens (creating it if needed, mode 0700) the cache directory `root`: removes stale temp
    /// files, scans the entries, sets the bound and evicts down to it. Never fails: a directory
    /// that cannot be created or read gives a cache with warnings counted and writes off.
    pub fn open(root: impl Into<PathBuf>, options: DiskOptions) -> Self {
        let root = root.into();
        let _span = tracing::info_span!("as_cache_open", root = %root.display()).entered();
        let mut cache = Self {
            root,
            lru: ByteLru::new(0),
            writable: true,
            readable: true,
            read_warned: false,
            writer: None,
            pool: BlobPool::new(crate::blob::PoolOptions {
                reserve_bytes: 0,
                fill_threads: 0,
            }),
            options,
            stats: DiskStats::default(),
        };
        if cache.options.background {
            match Writer::start(cache.options.max_pending_bytes) {
                Ok(w) => cache.writer = Some(w),
                // Still a cache: entries are written on the caller's thread.
                Err(e) => tracing::warn!(error = %e, "no writer thread for the structure cache"),
            }
        }
        let versioned = cache.root.join(VERSION_DIR);
        if let Err(e) = create_private_dir_all(&versioned) {
            cache.write_failed(&versioned, &e, "cannot create the cache directory");
            cache.readable = versioned.is_dir();
        }
        let found = cache.scan(&versioned);
        let found_bytes: u64 = found.iter().map(|f| f.bytes).sum();
        cache.stats.found_at_open = found.len() as u64;
        cache.stats.found_bytes_at_open = found_bytes;
        let capacity = cache.options.capacity_bytes.unwrap_or_else(|| {
            default_disk_capacity_bytes(found_bytes, filesystem_free_bytes(&cache.root))
        });
        cache.lru.set_capacity(capacity);
        for f in found {
            cache.index(f.key, f.bytes);
        }
        tracing::debug!(
            entries = cache.lru.len(),
            bytes = cache.lru.bytes(),
            capacity_bytes = capacity,
            "opened the acceleration-structure cache"
        );
        cache
    }

    /// Entries found under `v1/`, oldest first; stale temp files removed on the way.
    fn scan(&mut self, versioned: &Path) -> Vec<Found> {
        let mut found = Vec::new();
        let Ok(shards) = fs::read_dir(versioned) else {
            return found;
        };
        let now = SystemTime::now();
        for shard in shards.flatten() {
            let Ok(files) = fs::read_dir(shard.path()) else {
                continue;
            };
            let shard_name = shard.file_name().to_string_lossy().into_owned();
            for file in files.flatten() {
                let name = file.file_name().to_string_lossy().into_owned();
                let Ok(meta) = file.metadata() else { continue };
                if !meta.is_file() {
                    continue;
                }
                let modified = meta.modified().unwrap_or(SystemTime::UNIX_EPOCH);
                if let Some(key) = entry_key(&shard_name, &name) {
                    found.push(Found {
                        key,
                        bytes: meta.len(),
                        modified,
                    });
                } else if let Some(pid) = temp_owner(&name) {
                    let age = now.duration_since(modified).unwrap_or_default();
                    self.remove_stale_temp(&file.path(), pid, age);
                }
            }
        }
        found.sort_by_key(|f| (f.modified, f.key));
        found
    }

    /// Removes a temp file whose writer is gone (or cannot be told alive: no /proc) once it is
    /// older than `stale_temp_age`; a live process's temp file is never touched.
    fn remove_stale_temp(&mut self, path: &Path, pid: u32, age: Duration) {
        if pid == std::process::id()
            || process_alive(pid) == Some(true)
            || age < self.options.stale_temp_age
        {
            return;
        }
        match fs::remove_file(path) {
            Ok(()) => {
                self.stats.stale_temp_files_removed += 1;
                tracing::info!(path = %path.display(), pid, "removed a stale cache temp file");
            }
            Err(e) => tracing::debug!(path = %path.display(), error = %e, "stale temp file kept"),
        }
    }

    /// Records `key` as the most recent entry of `bytes`, removing the files of the entries
    /// evicted to make room. False when the entry alone exceeds the bound.
    fn index(&mut self, key: CacheKey, bytes: u64) -> bool {
        if self.lru.contains(&key) {
            self.lru.remove(&key);
        }
        match self.lru.insert(key, (), bytes) {
            Ok(evicted) => {
                for e in evicted {
                    if let Some(w) = &self.writer {
                        w.cancel(&e.key);
                    }
                    let path = entry_path(&self.root, &e.key);
                    match fs::remove_file(&path) {
                        Ok(()) => {}
                        Err(err) if err.kind() == io::ErrorKind::NotFound => {}
                        Err(err) => {
                            tracing::debug!(path = %path.display(), error = %err, "evicted entry kept");
                        }
                    }
                    self.stats.evicted_entries += 1;
                    self.stats.evicted_bytes += e.weight;
                }
                true
            }
            Err(()) => {
                // An entry found at open larger than the bound: too big to keep.
                let path = entry_path(&self.root, &key);
                if fs::remove_file(&path).is_ok() {
                    self.stats.evicted_entries += 1;
                    self.stats.evicted_bytes += bytes;
                }
                false
            }
        }
    }

    /// Reads blobs into `pool`'s buffers (by default, fresh ones: a pool that keeps nothing).
    pub fn set_pool(&mut self, pool: BlobPool) {
        self.pool = pool;
    }

    /// The directory given to [`open`](Self::open).
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The file `key`'s entry has (or would have).
    pub fn entry_path(&self, key: &CacheKey) -> PathBuf {
        entry_path(&self.root, key)
    }

    /// Whether writes are still on.
    pub fn writable(&self) -> bool {
        self.writable
    }

    /// Whether this process knows an entry for `key` (found at open, written or read since);
    /// another process may have removed it since.
    pub fn contains(&self, key: &CacheKey) -> bool {
        self.lru.contains(key)
    }

    /// The blob of `key`'s entry when it is whole, matches its checksums and `compat` accepts
    /// its serialization header; its file becomes the most recently used. Anything else is
    /// `None`: a bad entry is warned about, counted by reason and removed.
    pub fn get(&mut self, key: &CacheKey, compat: &dyn Compatibility) -> Option<Blob> {
        self.drain();
        if let Some(blob) = self.pending_hit(key) {
            return Some(blob);
        }
        if !self.readable {
            self.stats.misses += 1;
            return None;
        }
        let path = entry_path(&self.root, key);
        let read = read_and_touch(&path, key, compat, &self.pool);
        self.apply_read(key, &path, read)
    }

    /// [`get`](Self::get) of every key of `keys`, in order: entries are read and checked on up
    /// to [`READ_THREADS`] threads, then indexed in order as `get` would
    /// ([`plan_reads`](Self::plan_reads), [`ReadPlan::run`], [`finish_reads`](Self::finish_reads)).
    pub fn get_many(
        &mut self,
        keys: &[CacheKey],
        compat: &(dyn Compatibility + Sync),
    ) -> Vec<Option<Blob>> {
        let plan = self.plan_reads(keys);
        self.finish_reads(plan.run(compat))
    }

    /// The reads [`get_many`](Self::get_many) would make of `keys`, to run on any thread
    /// ([`ReadPlan::run`]) and hand back to [`finish_reads`](Self::finish_reads); keys the
    /// background writer still holds are answered now.
    pub fn plan_reads(&mut self, keys: &[CacheKey]) -> ReadPlan {
        self.drain();
        let found: Vec<Option<Blob>> = keys.iter().map(|k| self.pending_hit(k)).collect();
        let todo = if self.readable {
            (0..keys.len())
                .filter(|&i| found[i].is_none())
                .map(|i| (i, entry_path(&self.root, &keys[i])))
                .collect()
        } else {
            Vec::new()
        };
        ReadPlan {
            keys: keys.to_vec(),
            found,
            todo,
            pool: self.pool.clone(),
        }
    }

    /// What `done` read, indexed and counted in order as [`get`](Self::get) would: per key of
    /// its plan, the blob or `None` (absent, bad: warned about and removed).
    pub fn finish_reads(&mut self, done: ReadsDone) -> Vec<Option<Blob>> {
        let ReadsDone {
            keys,
            mut found,
            reads,
            ..
        } = done;
        let mut read = vec![false; keys.len()];
        for (i, path, result) in reads {
            read[i] = true;
            found[i] = self.apply_read(&keys[i], &path, result);
        }
        // Not read (an unreadable directory) and not answered from the writer's queue.
        let missing = (0..keys.len())
            .filter(|&i| !read[i] && found[i].is_none())
            .count();
        self.stats.misses += missing as u64;
        found
    }

    /// The blob bytes of `key`'s entry as this process knows it (`None`: not known here; a
    /// file another process wrote since open may still be there).
    pub fn entry_bytes(&self, key: &CacheKey) -> Option<u64> {
        self.lru
            .weight(key)
            .map(|w| w.saturating_sub(ENTRY_HEADER_BYTES as u64))
    }

    /// `device`'s rates as the last process that measured them here wrote them
    /// ([`rates`](crate::rates)): a missing file is logged, an unreadable, corrupt or foreign
    /// one is a warning; either way the caller goes on from its priors.
    pub fn device_rates(&self, device: &str) -> Result<DeviceRates, RatesError> {
        let loaded = load_rates(&self.root, device);
        let path = rates_path(&self.root, device);
        match &loaded {
            Ok(_) => tracing::debug!(path = %path.display(), "device rates read"),
            Err(RatesError::Missing) => {
                tracing::info!(path = %path.display(), "no device rates in the cache directory yet; deciding restores from priors")
            }
            Err(e) => tracing::warn!(
                path = %path.display(),
                error = %e,
                "device rates not used; deciding restores from priors (the file is rewritten at the end)"
            ),
        }
        loaded
    }

    /// Writes `device`'s `rates` for the next process (atomically); false when writes are off
    /// or the write failed (a warning: the rates are only a head start).
    pub fn save_device_rates(&self, device: &str, rates: &DeviceRates) -> bool {
        if !self.writable {
            return false;
        }
        match save_rates(&self.root, device, rates) {
            Ok(()) => true,
            Err(e) => {
                tracing::warn!(root = %self.root.display(), error = %e, "device rates not written");
                false
            }
        }
    }

    /// A hit on a blob the background writer still holds.
    fn pending_hit(&mut self, key: &CacheKey) -> Option<Blob> {
        let blob = self.writer.as_ref()?.pending_blob(key)?;
        // Written by this process a moment ago and not on disk yet: the same bytes.
        self.index(*key, blob.len() as u64 + ENTRY_HEADER_BYTES as u64);
        self.stats.hits += 1;
        self.stats.hit_bytes += blob.len() as u64;
        Some(blob)
    }

    /// Counts and indexes one read of `key`'s entry at `path`.
    fn apply_read(&mut self, key: &CacheKey, path: &Path, read: ReadResult) -> Option<Blob> {
        match read {
            Ok(blob) => {
                self.index(*key, blob.len() as u64 + ENTRY_HEADER_BYTES as u64);
                self.stats.hits += 1;
                self.stats.hit_bytes += blob.len() as u64;
                tracing::trace!(%key, bytes = blob.len(), "cache entry read");
                Some(blob)
            }
            Err(miss) => {
                self.stats.misses += 1;
                self.lru.remove(key);
                match miss {
                    ReadMiss::Absent => {}
                    ReadMiss::Bad(e, id) => self.bad_entry(path, e, id),
                    ReadMiss::Io(e) => {
                        let reason = io_reason(&e);
                        self.stats.warnings.count(reason);
                        // Counted every time, said once: an unreadable directory would
                        // otherwise warn for every structure of every frame.
                        if !std::mem::replace(&mut self.read_warned, true) {
                            tracing::warn!(
                                path = %path.display(),
                                %reason,
                                error = %e,
                                "acceleration-structure cache entry unreadable; rebuilding it \
                                 (further unreadable entries are only counted)"
                            );
                        } else {
                            tracing::debug!(path = %path.display(), %reason, error = %e, "entry unreadable");
                        }
                    }
                }
                None
            }
        }
    }

    fn bad_entry(&mut self, path: &Path, e: EntryError, read: Option<FileId>) {
        let reason = e.reason();
        self.stats.warnings.count(reason);
        tracing::warn!(
            path = %path.display(),
            %reason,
            "acceleration-structure cache entry not used ({e}); rebuilding it and removing the file"
        );
        let now = fs::metadata(path).ok().as_ref().and_then(file_id);
        if read.is_some() && now != read {
            return; // replaced since (or gone): not the bad file any more
        }
        match fs::remove_file(path) {
            Ok(()) => self.stats.removed_bad += 1,
            Err(err) if err.kind() == io::ErrorKind::NotFound => {}
            Err(err) => tracing::debug!(path = %path.display(), error = %err, "bad entry kept"),
        }
    }

    /// Writes `blob` as `key`'s entry (replacing any), evicting the least recently used
    /// entries first to stay under the bound; returns whether the entry is now on disk.
    /// Skipped (counted in `skipped_writes`) when writes are off, when `blob` is shorter than
    /// a serialization header, or when the entry alone exceeds the bound. A failed write is a
    /// warning that turns writes off; the temp file is removed and nothing else changes.
    pub fn put(&mut self, key: &CacheKey, blob: &[u8]) -> bool {
        self.put_inner(key, blob, None)
    }

    /// [`put`](Self::put) of a shared blob: the background writer keeps a reference instead
    /// of a copy.
    pub fn put_shared(&mut self, key: &CacheKey, blob: &Blob) -> bool {
        self.put_inner(key, blob, Some(blob))
    }

    fn put_inner(&mut self, key: &CacheKey, blob: &[u8], shared: Option<&Blob>) -> bool {
        self.drain();
        let file_bytes = blob.len() as u64 + ENTRY_HEADER_BYTES as u64;
        if !self.writable
            || blob.len() < SERIALIZED_HEADER_BYTES
            || file_bytes > self.lru.capacity()
        {
            self.stats.skipped_writes += 1;
            return false;
        }
        // Evict first, so a cache at its bound on a nearly full disk makes room before writing.
        self.index(*key, file_bytes);
        if let Some(w) = &self.writer {
            w.submit(Job {
                key: *key,
                root: self.root.clone(),
                blob: shared.map_or_else(|| self.pool.copy(blob), Blob::clone),
                sync: self.options.sync,
                fail_with: self.options.fail_writes_with,
            });
            return true;
        }
        let path = entry_path(&self.root, key);
        match write_entry_file(
            &self.root,
            key,
            blob,
            self.options.sync,
            self.options.fail_writes_with,
        ) {
            Ok(_) => {
                self.stats.written += 1;
                self.stats.written_bytes += file_bytes;
                tracing::debug!(%key, bytes = file_bytes, "wrote a cache entry");
                true
            }
            Err((_, e)) => {
                self.lru.remove(key);
                self.write_failed(&path, &e, "cannot write a cache entry");
                false
            }
        }
    }

    /// Applies what the writer thread reports: keys it could not write are forgotten, and a
    /// failed write turns writes off (the writer warned).
    fn drain(&mut self) {
        let Some(w) = &self.writer else { return };
        let (unwritten, failed) = w.take_unwritten();
        for key in unwritten {
            self.lru.remove(&key);
        }
        if failed {
            self.writable = false;
        }
    }

    /// Waits until every entry `put` queued is on disk (or failed); a no-op without
    /// [`DiskOptions::background`].
    pub fn flush(&mut self) {
        if let Some(w) = &self.writer {
            w.flush();
        }
        self.drain();
    }

    fn write_failed(&mut self, path: &Path, e: &io::Error, what: &str) {
        let reason = io_reason(e);
        self.stats.warnings.count(reason);
        self.writable = false;
        tracing::warn!(
            path = %path.display(),
            %reason,
            error = %e,
            "{what}; the acceleration-structure cache stops writing (renders go on, rebuilding)"
        );
    }

    /// Forgets and removes `key`'s entry (e.g. bytes the device refused to deserialize).
    pub fn remove(&mut self, key: &CacheKey) -> bool {
        if let Some(w) = &self.writer {
            w.cancel(key);
        }
        self.lru.remove(key);
        fs::remove_file(entry_path(&self.root, key)).is_ok()
    }

    /// The counters, with `entries`, `bytes`, `capacity_bytes` and `writable` as of now; with
    /// the background writer, after every queued write is done (this waits for them).
    pub fn stats(&self) -> DiskStats {
        let mut s = DiskStats {
            capacity_bytes: self.lru.capacity(),
            writable: self.writable,
            entries: self.lru.len() as u64,
            bytes: self.lru.bytes(),
            ..self.stats
        };
        if let Some(w) = &self.writer {
            // Counts of writes still queued would be guesses: wait for them (a report is
            // taken once, at the end; the process writes them before it exits anyway).
            w.flush();
            w.with_done(|d| {
                s.written += d.written;
                s.written_bytes += d.written_bytes;
                s.warnings.add(&d.warnings);
                s.write_busy_ms = d.write_busy_ms;
                s.submit_wait_ms = d.submit_wait_ms;
                s.flush_wait_ms = d.flush_wait_ms;
                s.writable &= d.warnings.total() == 0;
            });
        }
        s
    }
}

#[cfg(test)]
mod tests;
