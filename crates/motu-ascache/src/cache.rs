//! Both tiers behind one `get`/`put`.

use std::sync::Arc;

use crate::compat::Compatibility;
use crate::disk::DiskCache;
use crate::host::HostCache;
use crate::key::CacheKey;
use crate::stats::{CacheStats, Tier};

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
pub struct AsCache {
    host: HostCache,
    disk: Option<DiskCache>,
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
        Self {
            host,
            disk,
            stats: CacheStats::default(),
        }
    }

    /// The blob of `key` and the tier that held it; `None` when neither did (the caller
    /// builds). `compat` checks a disk entry's serialization header.
    pub fn get(&mut self, key: &CacheKey, compat: &dyn Compatibility) -> Option<(Arc<[u8]>, Tier)> {
        let found = match self.host.get(key) {
            Some(blob) => Some((blob, Tier::Host)),
            None => self
                .disk
                .as_mut()
                .and_then(|d| d.get(key, compat))
                .map(|blob| {
                    self.host.insert(*key, Arc::clone(&blob));
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
    ) -> Vec<Option<(Arc<[u8]>, Tier)>> {
        let mut found: Vec<Option<(Arc<[u8]>, Tier)>> = keys
            .iter()
            .map(|k| self.host.get(k).map(|b| (b, Tier::Host)))
            .collect();
        if let Some(disk) = self.disk.as_mut() {
            let todo: Vec<usize> = (0..keys.len()).filter(|&i| found[i].is_none()).collect();
            let wanted: Vec<CacheKey> = todo.iter().map(|&i| keys[i]).collect();
            for (i, blob) in todo.into_iter().zip(disk.get_many(&wanted, compat)) {
                if let Some(blob) = blob {
                    self.host.insert(keys[i], Arc::clone(&blob));
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
        found
    }

    /// Stores `blob` (a serialized structure) under `key`: in host memory, and in the
    /// directory unless this process knows an entry for `key` there already. Never fails: a
    /// blob over the host bound is refused there and still written to disk, and a failed
    /// write is a counted warning (see [`DiskCache::put`]).
    pub fn put(&mut self, key: CacheKey, blob: Arc<[u8]>) {
        self.stats.puts += 1;
        self.stats.put_bytes += blob.len() as u64;
        if let Some(disk) = self.disk.as_mut() {
            if !disk.contains(&key) {
                disk.put_shared(&key, &blob);
            }
        }
        self.host.insert(key, blob);
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
            ..self.stats
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::compat::AnyDevice;
    use crate::disk::DiskOptions;
    use crate::stats::WarningReason;

    fn key(i: u8) -> CacheKey {
        CacheKey([i; 32])
    }

    /// A fake serialized structure: a 32-byte header of `driver`, then `len` bytes.
    fn blob(driver: u8, len: usize) -> Arc<[u8]> {
        let mut v = vec![driver; 32];
        v.extend((0..len).map(|i| (i * 7 + usize::from(driver)) as u8));
        v.into()
    }

    fn driver(d: u8) -> impl Fn(&[u8; 32]) -> bool {
        move |h: &[u8; 32]| h.iter().all(|&b| b == d)
    }

    fn disk(dir: &std::path::Path) -> DiskCache {
        DiskCache::open(
            dir,
            DiskOptions {
                capacity_bytes: Some(1 << 20),
                ..DiskOptions::default()
            },
        )
    }

    #[test]
    fn put_then_get_from_host_then_from_disk_in_a_new_process() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = AsCache::new(HostCache::new(1 << 20), Some(disk(dir.path())));
        assert!(c.get(&key(1), &driver(1)).is_none());
        c.put(key(1), blob(1, 500));
        assert_eq!(c.contains(&key(1)), Some(Tier::Host));
        let (b, tier) = c.get(&key(1), &driver(1)).unwrap();
        assert_eq!((tier, &*b), (Tier::Host, &*blob(1, 500)));
        let s = c.stats();
        assert_eq!((s.host_hits, s.disk_hits, s.misses, s.puts), (1, 0, 1, 1));
        assert_eq!(s.disk.unwrap().written, 1);

        // The next process: an empty host tier, the same directory.
        let mut next = AsCache::new(HostCache::new(1 << 20), Some(disk(dir.path())));
        assert_eq!(next.contains(&key(1)), Some(Tier::Disk));
        let (b, tier) = next.get(&key(1), &driver(1)).unwrap();
        assert_eq!((tier, &*b), (Tier::Disk, &*blob(1, 500)));
        let (_, tier) = next.get(&key(1), &driver(1)).unwrap();
        assert_eq!(tier, Tier::Host, "a disk hit is promoted to host memory");
        // Put of a key the directory holds writes nothing again.
        next.put(key(1), blob(1, 500));
        let s = next.stats();
        assert_eq!((s.host_hits, s.disk_hits, s.hit_bytes), (1, 1, 2 * 532));
        assert_eq!(s.disk.unwrap().written, 0);
    }

    #[test]
    fn host_eviction_leaves_the_disk_copy_and_an_incompatible_one_is_rebuilt() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = AsCache::new(HostCache::new(600), Some(disk(dir.path())));
        c.put(key(1), blob(1, 500));
        c.put(key(2), blob(1, 500)); // evicts key 1 from host memory
        assert_eq!(c.contains(&key(1)), Some(Tier::Disk));
        assert_eq!(c.get(&key(1), &driver(1)).unwrap().1, Tier::Disk);
        assert_eq!(c.stats().host.evicted_entries, 2);
        // Another driver: a miss with a warning, and the entry is gone.
        c.host_mut().set_capacity_bytes(0);
        assert!(c.get(&key(2), &driver(9)).is_none());
        let s = c.stats();
        assert_eq!(s.warnings().get(WarningReason::Incompatible), 1);
        assert_eq!(s.misses, 1);
        assert_eq!(c.contains(&key(2)), None);
    }

    #[test]
    fn get_many_answers_as_get_does_from_both_tiers_in_order() {
        let dir = tempfile::tempdir().unwrap();
        {
            let mut c = AsCache::new(HostCache::new(1 << 20), Some(disk(dir.path())));
            for i in 0..40 {
                c.put(key(i), blob(1, 1000 + usize::from(i)));
            }
        }
        let mut c = AsCache::new(HostCache::new(1 << 20), Some(disk(dir.path())));
        c.put(key(200), blob(1, 10)); // in host memory only
                                      // An entry another driver wrote: a miss with a warning, as `get` would say.
        let mut other = AsCache::new(HostCache::new(0), Some(disk(dir.path())));
        other.put(key(201), blob(2, 10));
        drop(other);
        let keys: Vec<CacheKey> = (0..40).chain([200, 201, 202]).map(key).collect();
        let got = c.get_many(&keys, &driver(1));
        for i in 0..40u8 {
            let (b, tier) = got[usize::from(i)].as_ref().expect("on disk");
            assert_eq!(
                (tier, &**b),
                (&Tier::Disk, &*blob(1, 1000 + usize::from(i)))
            );
        }
        assert_eq!(got[40].as_ref().map(|g| g.1), Some(Tier::Host));
        assert!(got[41].is_none() && got[42].is_none());
        let s = c.stats();
        assert_eq!((s.host_hits, s.disk_hits, s.misses), (1, 40, 2));
        assert_eq!(s.warnings().get(WarningReason::Incompatible), 1);
        // Promoted: the same keys again come from host memory.
        let again = c.get_many(&keys[..40], &driver(1));
        assert!(again
            .iter()
            .all(|g| g.as_ref().map(|g| g.1) == Some(Tier::Host)));
    }

    #[test]
    fn host_only_and_remove() {
        let mut c = AsCache::new(HostCache::new(1000), None);
        c.put(key(3), blob(3, 10));
        assert_eq!(c.get(&key(3), &AnyDevice).unwrap().1, Tier::Host);
        c.remove(&key(3));
        assert!(c.get(&key(3), &AnyDevice).is_none());
        let s = c.stats();
        assert!(s.disk.is_none());
        assert_eq!(s.warnings().total(), 0);
        assert_eq!((s.host_hits, s.misses), (1, 1));
    }

    #[test]
    fn a_blob_over_the_host_bound_still_reaches_the_disk() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = AsCache::new(HostCache::new(100), Some(disk(dir.path())));
        c.put(key(4), blob(4, 1000));
        assert_eq!(c.stats().host.refused, 1);
        assert_eq!(c.get(&key(4), &driver(4)).unwrap().1, Tier::Disk);
    }

    #[test]
    fn disk_removal_makes_both_tiers_forget() {
        let dir = tempfile::tempdir().unwrap();
        let mut c = AsCache::new(HostCache::new(1 << 20), Some(disk(dir.path())));
        c.put(key(5), blob(5, 64));
        let path = c.disk().unwrap().entry_path(&key(5));
        assert!(path.exists());
        c.remove(&key(5));
        assert!(!path.exists());
        assert_eq!(c.contains(&key(5)), None);
    }
}
