//! Cache **policy and storage** for motu's built acceleration structures: plain Rust, no
//! Vulkan, testable without a GPU (as `motu-alloc` is for allocation policy).
//!
//! The GPU layer serializes a built, compacted BLAS
//! (`vkCmdCopyAccelerationStructureToMemoryKHR`, `SERIALIZE` mode) into bytes, hands them here
//! under a [`CacheKey`], and later asks for them back instead of rebuilding from the meshes,
//! deserializing them with `vkCmdCopyMemoryToAccelerationStructureKHR`. This crate never looks
//! inside a blob except for its first [`SERIALIZED_HEADER_BYTES`] (Vulkan's serialization
//! header: the `driverUUID` and the compatibility identifier), which it passes to the
//! caller's [`Compatibility`] check before a blob from disk is returned.
//!
//! # Tiers
//! - [`HostCache`] (tier 1, `--host-cache BYTES`): blobs in host memory, bounded by their
//!   bytes, least recently used evicted first. Default bound: [`default_host_cache_bytes`],
//!   a quarter of `MemAvailable`.
//! - [`DiskCache`] (tier 2, `--as-cache DIR`, off with `--no-as-cache`): one checksummed file
//!   per entry (`DIR/v1/ab/<hex key>.as`, byte layout in [`entry`]), written atomically,
//!   bounded by bytes with LRU eviction by file modification time. Default directory:
//!   [`default_dir`] (`$MOTU_AS_CACHE`, else `$XDG_CACHE_HOME/motu/as-cache`, else
//!   `$HOME/.cache/motu/as-cache`); default bound: [`default_disk_capacity_bytes`] (32 GiB or
//!   half the free space plus what the cache holds, whichever is smaller).
//! - [`AsCache`]: host in front of disk; a disk hit is promoted to host; `put` writes through.
//!
//! # What never happens
//! - A bad entry is never returned: truncated, corrupt (any flipped byte: header and blob are
//!   checksummed), foreign (its header names another key) or incompatible (the device says
//!   no) is a miss, a `tracing::warn!` naming the file and the reason, a count in
//!   [`WarningCounts`], and the file is removed. So a cache can change when an image is ready,
//!   never what it shows (given a key that covers every input: see [`CacheKeyBuilder`]).
//! - A cache problem never fails a render: no method returns an error. A directory that
//!   cannot be created, a read-only directory, a full disk or an IO error while writing is a
//!   counted warning that turns writes off; reads go on.
//! - No reader sees a half-written entry, in this process or another sharing the directory
//!   (temp file, fsync, rename). Two processes may write the same key: both entries are whole,
//!   the last rename wins. Temp files of killed writers are removed at the next open, never
//!   those of a live process.
//!
//! # Use from the GPU layer
//! ```
//! use motu_ascache::*;
//!
//! # let dir = tempfile::tempdir()?;
//! # let cache_dir = Some(dir.path().to_path_buf());
//! // At start-up: --host-cache, --as-cache / --no-as-cache.
//! let host = HostCache::new(default_host_cache_bytes());
//! let disk = cache_dir.map(|d| DiskCache::open(d, DiskOptions::default())); // or default_dir()
//! let mut cache = AsCache::new(host, disk);
//!
//! // A BLAS's key: its content, its build flags, the device.
//! let key = CacheKeyBuilder::new("motu-gpu blas v1")
//!     .bytes(b"geometry records").u64(0xc0ffee /* mesh chunk xxh3 */)
//!     .u32(0b110 /* VkBuildAccelerationStructureFlagsKHR */)
//!     .bytes(&[7; 16] /* driverUUID */)
//!     .finish();
//!
//! // vkGetDeviceAccelerationStructureCompatibilityKHR in the real thing.
//! let device = |header: &[u8; SERIALIZED_HEADER_BYTES]| header[..16] == [7; 16];
//! match cache.get(&key, &device) {
//!     Some((blob, tier)) => { /* deserialize `blob`: restored from `tier` */ }
//!     None => {
//!         // build, compact, serialize, then:
//!         // (or filled into `cache.pool().take(len)`: memory already paged in)
//!         let serialized: Blob = vec![7u8; 4096].into();
//!         cache.put(key, serialized);
//!     }
//! }
//! assert_eq!(cache.get(&key, &device).map(|(_, t)| t), Some(Tier::Host));
//! let stats: CacheStats = cache.stats(); // for --stats
//! assert_eq!((stats.misses, stats.host_hits), (1, 1));
//! # Ok::<(), std::io::Error>(())
//! ```
//!
//! One thread uses a cache (`&mut self`); it is `Send`, so it can live on a worker thread.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! Cache **policy and storage** for built acceleration structures, plain Rust (no Vulkan, no
//! workspace crate): blobs are serialized BLASes, opaque but for their first 32 bytes (Vulkan's
//! serialization header: driver UUID + compatibility data) that a caller's `Compatibility` check
//! (`vkGetDeviceAccelerationStructureCompatibilityKHR`) must accept; keys (`CacheKeyBuilder`: two
//! seeded XXH3-128 streams over framed fields: content, build flags, device, format version); the
//! host tier (`--host-cache`, byte-bounded LRU, default a quarter of `MemAvailable`); the disk tier
//! (`--as-cache DIR`, default `$MOTU_AS_CACHE`, `$XDG_CACHE_HOME/motu/as-cache` or
//! `~/.cache/motu/as-cache`; one file per entry `v1/ab/<hex>.as`, header with magic, version, key,
//! length and checksums (`entry.rs`); atomic writes, LRU by file mtime, bound min(32 GiB, half the
//! free space + what it holds), stale temp files of dead writers removed at open; with
//! `DiskOptions::background`, which render sets, entries are written by a writer thread of its own
//! (`writer.rs`: a queued entry is answered from memory, eviction cancels its write, the queue
//! bounded at 1 GiB of blobs only it keeps alive, written before the cache is dropped or its
//! stats are read)); a bad entry
//! (truncated, corrupt, foreign, incompatible) is a miss, a warning and a removed file; a read-only
//! or full directory a counted warning that turns writes off — nothing here returns an error.
//! Blobs (`blob.rs`) are shared immutable buffers from a `BlobPool`: recycled from dropped blobs or
//! pre-faulted on threads of its own after a burst, so copies and reads into them run at touched-memory
//! speed; its free bytes bounded by the host tier's room. Files, lowest first: `key`, `compat`,
//! `stats`, `lru`, `blob`, `host`, `entry`, `file`, `rates`, `reads`, `disk`, `writer`, `cache`.
//!
//! Key types: `AsCache`, `HostCache`, `DiskCache`, `DiskOptions`, `Blob`, `BlobPool`, `CacheKey`, `CacheKeyBuilder`,
//! `Compatibility`, `CacheStats`, `Tier`, `WarningReason`, `default_dir`,
//! `default_host_cache_bytes`.

mod blob;
mod cache;
mod compat;
mod disk;
pub mod entry;
mod file;
mod host;
mod key;
mod lru;
pub mod rates;
mod reads;
mod stats;
mod writer;

pub use blob::{
    Blob, BlobBuf, BlobPool, PoolOptions, DEFAULT_RESERVE_BYTES, MIN_POOLED_BYTES,
    POOL_GRANULE_BYTES,
};
pub use cache::AsCache;
pub use compat::{serialized_header, AnyDevice, Compatibility, SERIALIZED_HEADER_BYTES};
pub use disk::{
    default_dir, default_disk_capacity_bytes, dir_from_env, filesystem_free_bytes, io_reason,
    DiskCache, DiskOptions, CACHE_DIR_ENV, DEFAULT_DISK_CAPACITY_BYTES,
    DEFAULT_FREE_SHARE_DENOMINATOR, DEFAULT_MAX_PENDING_BYTES, DEFAULT_STALE_TEMP_AGE,
    READ_THREADS,
};
pub use host::{
    default_host_cache_bytes, mem_available_bytes, HostCache, DEFAULT_HOST_SHARE_DENOMINATOR,
    FALLBACK_HOST_CACHE_BYTES,
};
pub use key::{CacheKey, CacheKeyBuilder, KeyParseError};
pub use rates::{parse_rates, DeviceRates, Rate, RatesError, RatesSpecError};
pub use reads::{ReadPlan, ReadsDone};
pub use stats::{CacheStats, DiskStats, HostStats, PoolStats, Tier, WarningCounts, WarningReason};

#[cfg(test)]
mod tests;
