//! Both tiers behind one `get`/`put`.

use crate::blob::{Blob, BlobPool};
use crate::compat::Compatibility;
use crate::disk::DiskCache;
use crate::host::HostCache;
use crate::key::CacheKey;
use crate::reads::{ReadPlan, ReadsDone};
use crate::stats::{CacheStats, PoolStats, Tier};

/// The host tier in front of an optional disk tier.
///
/// - [`get`](Self::get) asks host memory, then the directory; a disk hit is promoted to host
///   memory, so the next `get` of it is a host hit.
/// - [`put`](Self::put) stores in host memory and **writes through** to the directory when
///   it does not hold the key yet: an entry is on disk as soon as it is built, so it survives
///   the process (even a killed one) and an evicted host blob needs no write-back. The write
///   (write, fsync, rename) happens on the caller's thread, or on the disk tier's own writer
///   thread with [`DiskOptions::background`](crate::DiskOptions::background), which shares
///   the host tier's blob instead of copying it.
///
/// Blobs in the host tier are trusted as this process's device wrote them (one `AsCache` per
/// device); only the disk tier asks [`Compatibility`].
///
/// Blobs read from the directory, and those a caller makes with [`pool`](Self::pool), live in
/// a [`BlobPool`]'s buffers: recycled from dropped blobs or pre-faulted after a burst
/// ([`BlobPool::refill`]), its free bytes bounded by the room the host tier has left (so the
/// two together never hold more than `--host-cache`) and by
/// [`PoolOptions::reserve_bytes`](crate::PoolOptions::reserve_bytes).
pub struct AsCache {
    host: HostCache,
    disk: Option<DiskCache>,
    pool: BlobPool,
    stats: CacheStats,
}

impl std::fmt::Debug for AsCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("AsCache")
            .field("stats", &self.stats())
            .finish()
    }
}

impl AsCache {
    /// Both tiers (`disk`: `None` for `--no-as-cache` or when there is no default directory).
    pub fn new(host: HostCache, disk: Option<DiskCache>) -> Self {
        Self::with_pool(host, disk, BlobPool::default())
    }

    /// [`new`](Self::new) with blobs in `pool`'s buffers.
    pub fn with_pool(mut host: HostCache, mut disk: Option<DiskCache>, pool: BlobPool) -> Self {
        if let Some(d) = disk.as_mut() {
            d.set_pool(pool.clone());
        }
        host.set_pool(pool.clone());
        Self {
            host,
            disk,
            pool,
            stats: CacheStats::default(),
        }
    }

    /// Where blobs' buffers come from: take one for a blob to [`put`](Self::put)
    /// ([`BlobPool::take`], [`BlobPool::copy`]), and [`BlobPool::refill`] it after a burst.
    pub fn pool(&self) -> &BlobPool {
        &self.pool
    }

    /// The pool's counters.
    pub fn pool_stats(&self) -> PoolStats {
        self.pool.stats()
    }

    /// The blob of `key` and the tier that held it; `None` when neither did (the caller
    /// builds). `compat` checks a disk entry's serialization header.
    pub fn get(&mut self, key: &CacheKey, compat: &dyn Compatibility) -> Option<(Blob, Tier)> {
        let found = match self.host.get(key) {
            Some(blob) => Some((blob, Tier::Host)),
            None => self
                .disk
                .as_mut()
                .and_then(|d| d.get(key, compat))
                .map(|blob| {
                    self.promote(*key, &blob);
                    (blob, Tier::Disk)
                }),
        };
        match &found {
            Some((blob, tier)) => {
                match tier {
                    Tier::Host => self.stats.host_hits += 1,
                    Tier::Disk => self.stats.disk_hits += 1,
                }
                self.stats.hit_bytes += blob.len() as u64;
            }
            None => self.stats.misses += 1,
        }
        found
    }

    /// [`get`](Self::get) of every key of `keys`, in order, counted as `get` counts: what
    /// host memory lacks is read from the directory on several threads
    /// ([`DiskCache::get_many`]) and promoted to host memory.
    pub fn get_many(
        &mut self,
        keys: &[CacheKey],
        compat: &(dyn Compatibility + Sync),
    ) -> Vec<Option<(Blob, Tier)>> {
        let mut found: Vec<Option<(Blob, Tier)>> = keys
            .iter()
            .map(|k| self.host.get(k).map(|b| (b, Tier::Host)))
            .collect();
        if let Some(disk) = self.disk.as_mut() {
            let todo: Vec<usize> = (0..keys.len()).filter(|&i| found[i].is_none()).collect();
            let wanted: Vec<CacheKey> = todo.iter().map(|&i| keys[i]).collect();
            for (i, blob) in todo.into_iter().zip(disk.get_many(&wanted, compat)) {
                if let Some(blob) = blob {
                    self.promote(keys[i], &blob);
                    found[i] = Some((blob, Tier::Disk));
                }
            }
        }
        for f in &found {
            match f {
                Some((blob, tier)) => {
                    match tier {
                        Tier::Host => self.stats.host_hits += 1,
                        Tier::Disk => self.stats.disk_hits += 1,
                    }
                    self.stats.hit_bytes += blob.len() as u64;
                }
                None => self.stats.misses += 1,
            }
        }
        if found.iter().any(|f| matches!(f, Some((_, Tier::Disk)))) {
            // A burst of reads is over: page in memory for the next one.
            self.pool.refill();
        }
        found
    }

    /// Where `key` is (host first) and its blob's bytes, without reading, counting or
    /// refreshing it (the disk answer is this process's view, as [`contains`](Self::contains)).
    pub fn entry_bytes(&self, key: &CacheKey) -> Option<(Tier, u64)> {
        if let Some(blob) = self.host.peek(key) {
            return Some((Tier::Host, blob.len() as u64));
        }
        let disk = self.disk.as_ref()?.entry_bytes(key)?;
        Some((Tier::Disk, disk))
    }

    /// The directory reads of `keys` (none without a disk tier), to run on any thread
    /// ([`ReadPlan::run`]) while the caller does other work, then hand to
    /// [`finish_disk_reads`](Self::finish_disk_reads). Host memory is not asked: for keys the
    /// caller knows to be on disk only ([`entry_bytes`](Self::entry_bytes)).
    pub fn plan_disk_reads(&mut self, keys: &[CacheKey]) -> Option<ReadPlan> {
        Some(self.disk.as_mut()?.plan_reads(keys))
    }

    /// What `done` read (in its plan's order), counted as [`get_many`](Self::get_many) counts
    /// disk hits and misses, each hit promoted to host memory.
    pub fn finish_disk_reads(&mut self, done: ReadsDone) -> Vec<Option<Blob>> {
        let Some(disk) = self.disk.as_mut() else {
            return Vec::new();
        };
        let keys = done.keys.clone();
        let found = disk.finish_reads(done);
        for (key, blob) in keys.iter().zip(&found) {
            match blob {
                Some(blob) => {
                    self.promote(*key, blob);
                    self.stats.disk_hits += 1;
                    self.stats.hit_bytes += blob.len() as u64;
                }
                None => self.stats.misses += 1,
            }
        }
        if found.iter().any(Option::is_some) {
            // A burst of reads is over: page in memory for the next one.
            self.pool.refill();
        }
        found
    }

    /// Stores `blob` in host memory only, not in the directory: for a structure whose restore
    /// pays within this process but would not in the next one (the caller's rule).
    pub fn put_host(&mut self, key: CacheKey, blob: impl Into<Blob>) {
        let blob: Blob = blob.into();
        self.stats.puts += 1;
        self.stats.put_bytes += blob.len() as u64;
        self.promote(key, &blob);
    }

    /// Stores `blob` (a serialized structure) under `key`: in host memory, and in the
    /// directory unless this process knows an entry for `key` there already. Never fails: a
    /// blob over the host bound is refused there and still written to disk, and a failed
    /// write is a counted warning (see [`DiskCache::put`]).
    pub fn put(&mut self, key: CacheKey, blob: impl Into<Blob>) {
        let blob: Blob = blob.into();
        self.stats.puts += 1;
        self.stats.put_bytes += blob.len() as u64;
        if let Some(disk) = self.disk.as_mut() {
            if !disk.contains(&key) {
                disk.put_shared(&key, &blob);
            }
        }
        self.promote(key, &blob);
    }

    /// Keeps `blob` in host memory, unless the host tier holds nothing (a bound of 0: the
    /// caller keeps structures in host memory another way, so no refusal is counted).
    fn promote(&mut self, key: CacheKey, blob: &Blob) {
        if self.host.capacity_bytes() > 0 {
            self.host.insert(key, blob.clone());
        }
    }

    /// Where `key` is (host first), without reading, counting or refreshing it. The disk
    /// answer is this process's view: another process may have removed the file since.
    pub fn contains(&self, key: &CacheKey) -> Option<Tier> {
        if self.host.contains(key) {
            Some(Tier::Host)
        } else if self.disk.as_ref().is_some_and(|d| d.contains(key)) {
            Some(Tier::Disk)
        } else {
            None
        }
    }

    /// Removes `key` from both tiers: for bytes the device refused to deserialize although
    /// their header passed, so they are rebuilt and replaced rather than tried again.
    pub fn remove(&mut self, key: &CacheKey) {
        self.host.remove(key);
        if let Some(disk) = self.disk.as_mut() {
            disk.remove(key);
        }
    }

    /// Waits until every entry written through is on disk (see [`DiskCache::flush`]).
    pub fn flush(&mut self) {
        if let Some(disk) = self.disk.as_mut() {
            disk.flush();
        }
    }

    /// The host tier.
    pub fn host(&self) -> &HostCache {
        &self.host
    }

    /// The host tier, e.g. to change its bound.
    pub fn host_mut(&mut self) -> &mut HostCache {
        &mut self.host
    }

    /// The disk tier, if any.
    pub fn disk(&self) -> Option<&DiskCache> {
        self.disk.as_ref()
    }

    /// Both tiers' counters.
    pub fn stats(&self) -> CacheStats {
        CacheStats {
            host: self.host.stats(),
            disk: self.disk.as_ref().map(DiskCache::stats),
            pool: self.pool.stats(),
            ..self.stats
        }
    }
}

#[cfg(test)]
mod tests;
