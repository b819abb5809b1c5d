//! Tier 1: serialized structures in host memory, least recently used evicted first.

use crate::blob::{Blob, BlobPool};
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
/// Blobs are shared ([`Blob`]): a `get` hands out a reference, so an evicted blob stays alive
/// as long as the caller still uploads from it (its bytes then no longer count here).
pub struct HostCache {
    lru: ByteLru<CacheKey, Blob>,
    stats: HostStats,
    /// The pool whose free bytes this tier's room bounds ([`set_pool`](Self::set_pool)).
    pool: Option<BlobPool>,
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
            pool: None,
        }
    }

    /// Bounds `pool`'s free bytes by the room this tier has left (its bound less the bytes
    /// it holds), from now on: the two together hold no more than the bound.
    pub fn set_pool(&mut self, pool: BlobPool) {
        self.pool = Some(pool);
        self.bound_pool();
    }

    fn bound_pool(&self) {
        if let Some(pool) = &self.pool {
            pool.set_bound(self.lru.capacity().saturating_sub(self.lru.bytes()));
        }
    }

    /// Stores `blob` under `key` as the most recently used, evicting the least recently used
    /// blobs until it fits, and returns whether it was stored. A blob larger than the whole
    /// bound is refused (counted in `refused`); the cache is then unchanged. A blob already
    /// under `key` is replaced.
    pub fn insert(&mut self, key: CacheKey, blob: Blob) -> bool {
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
                self.bound_pool();
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
    pub fn get(&mut self, key: &CacheKey) -> Option<Blob> {
        match self.lru.get(key) {
            Some(blob) => {
                self.stats.hits += 1;
                Some(blob.clone())
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
    pub fn peek(&self, key: &CacheKey) -> Option<&Blob> {
        self.lru.peek(key)
    }

    /// Removes `key` (e.g. a blob the device refused to deserialize); returns its blob.
    pub fn remove(&mut self, key: &CacheKey) -> Option<Blob> {
        let removed = self.lru.remove(key).map(|(blob, _)| blob);
        self.bound_pool();
        removed
    }

    /// Changes the bound, evicting the least recently used blobs until the cache fits it.
    pub fn set_capacity_bytes(&mut self, capacity_bytes: u64) {
        for e in self.lru.set_capacity(capacity_bytes) {
            self.stats.evicted_entries += 1;
            self.stats.evicted_bytes += e.weight;
        }
        self.bound_pool();
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
mod tests;
