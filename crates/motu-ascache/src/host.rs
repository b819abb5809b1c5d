//! Tier 1: serialized structures in host memory, least recently used evicted first.

use std::sync::Arc;

use crate::key::CacheKey;
use crate::lru::ByteLru;
use crate::stats::HostStats;

/// The share of available memory the host tier takes by default: a quarter.
///
/// The cache only saves rebuilds, so it must never be what pushes the machine into swap or
/// the OOM killer. Next to it live the package's mapped pages (the page cache, which the
/// meshes are streamed from), the meshes held in host memory by a discrete GPU's streamer, the
/// driver's own staging, and whatever else runs; a quarter of what is available when the
/// renderer starts leaves three quarters to those, and is still tens of GB on a render node
/// (a compacted BLAS is ~1/5 of its meshes' bytes, so a quarter holds most of a frame's
/// evictions).
pub const DEFAULT_HOST_SHARE_DENOMINATOR: u64 = 4;

/// The host tier's bound when available memory cannot be read (no `/proc/meminfo`): 2 GiB,
/// small enough for any machine that renders a large scene at all.
pub const FALLBACK_HOST_CACHE_BYTES: u64 = 2 << 30;

/// `MemAvailable` from the text of `/proc/meminfo`, in bytes.
pub fn mem_available_bytes(meminfo: &str) -> Option<u64> {
    let line = meminfo
        .lines()
        .find_map(|l| l.strip_prefix("MemAvailable:"))?;
    let mut words = line.split_whitespace();
    let value: u64 = words.next()?.parse().ok()?;
    let unit = match words.next() {
        Some("kB") | Some("KB") => 1024,
        None => 1,
        Some(_) => return None,
    };
    value.checked_mul(unit)
}

/// The default `--host-cache`: a quarter ([`DEFAULT_HOST_SHARE_DENOMINATOR`]) of the memory
/// Linux reports available (`MemAvailable` in `/proc/meminfo`) when called, or
/// [`FALLBACK_HOST_CACHE_BYTES`] when that cannot be read.
pub fn default_host_cache_bytes() -> u64 {
    std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|text| mem_available_bytes(&text))
        .map(|available| available / DEFAULT_HOST_SHARE_DENOMINATOR)
        .unwrap_or(FALLBACK_HOST_CACHE_BYTES)
}

/// Serialized structures in host memory, bounded by their bytes; the least recently used
/// (inserted or read) is evicted first.
///
/// Blobs are shared `Arc<[u8]>`: a `get` hands out a reference, so an evicted blob stays alive
/// as long as the caller still uploads from it (its bytes then no longer count here).
pub struct HostCache {
    lru: ByteLru<CacheKey, Arc<[u8]>>,
    stats: HostStats,
}

impl std::fmt::Debug for HostCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HostCache")
            .field("stats", &self.stats())
            .finish()
    }
}

impl HostCache {
    /// An empty cache holding at most `capacity_bytes` of blobs (0: holds nothing).
    pub fn new(capacity_bytes: u64) -> Self {
        Self {
            lru: ByteLru::new(capacity_bytes),
            stats: HostStats::default(),
        }
    }

    /// Stores `blob` under `key` as the most recently used, evicting the least recently used
    /// blobs until it fits, and returns whether it was stored. A blob larger than the whole
    /// bound is refused (counted in `refused`); the cache is then unchanged. A blob already
    /// under `key` is replaced.
    pub fn insert(&mut self, key: CacheKey, blob: Arc<[u8]>) -> bool {
        let size = blob.len() as u64;
        match self.lru.insert(key, blob, size) {
            Ok(evicted) => {
                for e in evicted {
                    self.stats.evicted_entries += 1;
                    self.stats.evicted_bytes += e.weight;
                    tracing::trace!(key = %e.key, bytes = e.weight, "host cache evicted");
                }
                self.stats.inserted += 1;
                self.stats.inserted_bytes += size;
                true
            }
            Err(_) => {
                self.stats.refused += 1;
                self.stats.refused_bytes += size;
                tracing::debug!(
                    %key,
                    bytes = size,
                    capacity_bytes = self.lru.capacity(),
                    "host cache refused a blob larger than its bound"
                );
                false
            }
        }
    }

    /// The blob under `key`, made the most recently used; counts a hit or a miss.
    pub fn get(&mut self, key: &CacheKey) -> Option<Arc<[u8]>> {
        match self.lru.get(key) {
            Some(blob) => {
                self.stats.hits += 1;
                Some(Arc::clone(blob))
            }
            None => {
                self.stats.misses += 1;
                None
            }
        }
    }

    /// Whether `key` is held; recency and counters unchanged.
    pub fn contains(&self, key: &CacheKey) -> bool {
        self.lru.contains(key)
    }

    /// The blob under `key` without making it recent or counting: for inspection.
    pub fn peek(&self, key: &CacheKey) -> Option<&Arc<[u8]>> {
        self.lru.peek(key)
    }

    /// Removes `key` (e.g. a blob the device refused to deserialize); returns its blob.
    pub fn remove(&mut self, key: &CacheKey) -> Option<Arc<[u8]>> {
        self.lru.remove(key).map(|(blob, _)| blob)
    }

    /// Changes the bound, evicting the least recently used blobs until the cache fits it.
    pub fn set_capacity_bytes(&mut self, capacity_bytes: u64) {
        for e in self.lru.set_capacity(capacity_bytes) {
            self.stats.evicted_entries += 1;
            self.stats.evicted_bytes += e.weight;
        }
    }

    /// The bound.
    pub fn capacity_bytes(&self) -> u64 {
        self.lru.capacity()
    }

    /// Blobs held.
    pub fn len(&self) -> usize {
        self.lru.len()
    }

    /// Whether no blob is held.
    pub fn is_empty(&self) -> bool {
        self.lru.len() == 0
    }

    /// Bytes held (never above the bound).
    pub fn bytes(&self) -> u64 {
        self.lru.bytes()
    }

    /// The counters, with `entries`, `bytes` and `capacity_bytes` as of now.
    pub fn stats(&self) -> HostStats {
        HostStats {
            capacity_bytes: self.lru.capacity(),
            entries: self.lru.len() as u64,
            bytes: self.lru.bytes(),
            ..self.stats
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn key(i: u8) -> CacheKey {
        CacheKey([i; 32])
    }

    fn blob(len: usize, fill: u8) -> Arc<[u8]> {
        vec![fill; len].into()
    }

    #[test]
    fn round_trip_counts_hits_and_misses() {
        let mut c = HostCache::new(1000);
        assert!(c.insert(key(1), blob(100, 7)));
        assert_eq!(c.get(&key(1)).as_deref(), Some(&[7u8; 100][..]));
        assert!(c.get(&key(2)).is_none());
        let s = c.stats();
        assert_eq!(
            (s.entries, s.bytes, s.hits, s.misses, s.inserted),
            (1, 100, 1, 1, 1)
        );
        assert_eq!(c.remove(&key(1)).map(|b| b.len()), Some(100));
        assert!(c.is_empty());
        assert_eq!(c.stats().bytes, 0);
    }

    #[test]
    fn evicts_least_recently_used_first_within_the_bound() {
        let mut c = HostCache::new(300);
        for i in 0..3 {
            assert!(c.insert(key(i), blob(100, i)));
        }
        c.get(&key(0)); // 1 is now the least recently used
        assert!(c.insert(key(3), blob(100, 3)));
        assert!(!c.contains(&key(1)));
        assert!(c.contains(&key(0)) && c.contains(&key(2)) && c.contains(&key(3)));
        assert!(c.insert(key(4), blob(250, 4)));
        assert_eq!(c.len(), 1, "250 bytes leave room for nothing else");
        let s = c.stats();
        assert_eq!((s.evicted_entries, s.evicted_bytes), (4, 400));
        assert!(s.bytes <= s.capacity_bytes);
        c.set_capacity_bytes(100);
        assert!(c.is_empty());
        assert_eq!(c.stats().evicted_entries, 5);
    }

    #[test]
    fn a_blob_over_the_bound_is_refused_not_a_panic() {
        let mut c = HostCache::new(100);
        assert!(c.insert(key(1), blob(60, 1)));
        assert!(!c.insert(key(2), blob(101, 2)));
        assert!(c.contains(&key(1)), "a refusal evicts nothing");
        let s = c.stats();
        assert_eq!((s.refused, s.refused_bytes, s.evicted_entries), (1, 101, 0));
        let mut off = HostCache::new(0);
        assert!(!off.insert(key(1), blob(1, 1)));
        assert!(
            off.insert(key(1), blob(0, 1)),
            "an empty blob fits any bound"
        );
    }

    #[test]
    fn a_handed_out_blob_outlives_its_eviction() {
        let mut c = HostCache::new(100);
        c.insert(key(1), blob(100, 9));
        let held = c.get(&key(1)).unwrap();
        c.insert(key(2), blob(100, 8));
        assert!(!c.contains(&key(1)));
        assert_eq!(held[99], 9);
    }

    #[test]
    fn reads_mem_available() {
        let text = "MemTotal:       65838288 kB\nMemFree:  1 kB\nMemAvailable:   40000000 kB\n";
        assert_eq!(mem_available_bytes(text), Some(40_000_000 * 1024));
        assert_eq!(mem_available_bytes("MemTotal: 5 kB\n"), None);
        assert_eq!(mem_available_bytes("MemAvailable: x kB\n"), None);
        assert_eq!(mem_available_bytes("MemAvailable: 5 MB\n"), None);
        let d = default_host_cache_bytes();
        match std::fs::read_to_string("/proc/meminfo")
            .ok()
            .and_then(|t| mem_available_bytes(&t))
        {
            // MemAvailable moves between the two reads; a quarter of it, roughly.
            Some(avail) => assert!(d > 0 && d <= avail / 2, "{d} of {avail}"),
            None => assert_eq!(d, FALLBACK_HOST_CACHE_BYTES),
        }
    }

    proptest! {
        /// Never over the bound, the blob just inserted (if it fits) or read is kept, and the
        /// byte counters balance: inserted = held + evicted + removed + replaced.
        #[test]
        fn lru_invariants(
            capacity in 0u64..2000,
            ops in proptest::collection::vec((0u8..3, 0u8..12, 0usize..700), 1..150),
        ) {
            let mut c = HostCache::new(capacity);
            let mut removed_bytes = 0u64;
            for (kind, k, len) in ops {
                match kind {
                    0 => {
                        let old = c.peek(&key(k)).map(|b| b.len() as u64);
                        let stored = c.insert(key(k), blob(len, k));
                        prop_assert_eq!(stored, len as u64 <= capacity);
                        if stored {
                            removed_bytes += old.unwrap_or(0);
                            prop_assert!(c.contains(&key(k)));
                        }
                    }
                    1 => {
                        if let Some(b) = c.get(&key(k)) {
                            prop_assert!(b.iter().all(|&x| x == k));
                            // the most recent survives the next insert that fits beside it
                            let other = key(k.wrapping_add(100));
                            if b.len() as u64 + (len as u64) <= capacity {
                                c.insert(other, blob(len, k.wrapping_add(100)));
                                prop_assert!(c.contains(&key(k)));
                                removed_bytes += c.remove(&other).map_or(0, |b| b.len() as u64);
                            }
                        }
                    }
                    _ => {
                        removed_bytes += c.remove(&key(k)).map_or(0, |b| b.len() as u64);
                    }
                }
                let s = c.stats();
                prop_assert!(s.bytes <= capacity);
                prop_assert_eq!(s.inserted_bytes, s.bytes + s.evicted_bytes + removed_bytes);
            }
        }
    }
}
