//! Counters both tiers keep, for `--stats` (their JSON is `motu_render::stats::CacheStats`,
//! each warning keyed by [`WarningReason::name`]) and `motu bench`.

/// Which tier answered a [`get`](crate::AsCache::get).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Tier {
    /// Host memory ([`HostCache`](crate::HostCache)).
    Host,
    /// The cache directory ([`DiskCache`](crate::DiskCache)); the blob is now in host memory too.
    Disk,
}

/// Why the disk tier warned. Every warning is also a `tracing::warn!` naming the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum WarningReason {
    /// An entry's magic, header, length field or checksum is wrong (the bytes changed).
    Corrupt,
    /// An entry is shorter than its header says (a copy cut short, a disk that lost a tail).
    Truncated,
    /// An entry's header names another key than its file name (a renamed or copied file).
    Foreign,
    /// The device cannot use the entry: another driver, version or device wrote it.
    Incompatible,
    /// The directory (or an entry) could not be written for lack of permission or on a
    /// read-only filesystem; writes are off from then on.
    ReadOnly,
    /// The filesystem or the user's quota is full; writes are off from then on.
    Full,
    /// Any other IO error; a failed write turns writes off from then on.
    Io,
}

impl WarningReason {
    /// Every reason, in the order of [`WarningCounts`]'s fields.
    pub const ALL: [WarningReason; 7] = [
        WarningReason::Corrupt,
        WarningReason::Truncated,
        WarningReason::Foreign,
        WarningReason::Incompatible,
        WarningReason::ReadOnly,
        WarningReason::Full,
        WarningReason::Io,
    ];

    /// The reason's name as in `--stats` (`read_only`, …).
    pub fn name(self) -> &'static str {
        match self {
            WarningReason::Corrupt => "corrupt",
            WarningReason::Truncated => "truncated",
            WarningReason::Foreign => "foreign",
            WarningReason::Incompatible => "incompatible",
            WarningReason::ReadOnly => "read_only",
            WarningReason::Full => "full",
            WarningReason::Io => "io",
        }
    }
}

impl std::fmt::Display for WarningReason {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// Warnings counted by reason.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct WarningCounts {
    pub corrupt: u64,
    pub truncated: u64,
    pub foreign: u64,
    pub incompatible: u64,
    pub read_only: u64,
    pub full: u64,
    pub io: u64,
}

impl WarningCounts {
    /// The count of one reason.
    pub fn get(&self, reason: WarningReason) -> u64 {
        match reason {
            WarningReason::Corrupt => self.corrupt,
            WarningReason::Truncated => self.truncated,
            WarningReason::Foreign => self.foreign,
            WarningReason::Incompatible => self.incompatible,
            WarningReason::ReadOnly => self.read_only,
            WarningReason::Full => self.full,
            WarningReason::Io => self.io,
        }
    }

    /// Counts one warning.
    pub fn count(&mut self, reason: WarningReason) {
        let c = match reason {
            WarningReason::Corrupt => &mut self.corrupt,
            WarningReason::Truncated => &mut self.truncated,
            WarningReason::Foreign => &mut self.foreign,
            WarningReason::Incompatible => &mut self.incompatible,
            WarningReason::ReadOnly => &mut self.read_only,
            WarningReason::Full => &mut self.full,
            WarningReason::Io => &mut self.io,
        };
        *c += 1;
    }

    /// Adds `other`'s counts.
    pub fn add(&mut self, other: &WarningCounts) {
        self.corrupt += other.corrupt;
        self.truncated += other.truncated;
        self.foreign += other.foreign;
        self.incompatible += other.incompatible;
        self.read_only += other.read_only;
        self.full += other.full;
        self.io += other.io;
    }

    /// All warnings.
    pub fn total(&self) -> u64 {
        WarningReason::ALL.iter().map(|&r| self.get(r)).sum()
    }
}

/// The host tier's counters ([`HostCache::stats`](crate::HostCache::stats)).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct HostStats {
    /// The byte bound (`--host-cache`).
    pub capacity_bytes: u64,
    /// Blobs held now.
    pub entries: u64,
    /// Bytes of the blobs held now (never above `capacity_bytes`).
    pub bytes: u64,
    /// `get`s that found their key.
    pub hits: u64,
    /// `get`s that did not.
    pub misses: u64,
    /// Blobs stored by `insert` (a replaced key counts again).
    pub inserted: u64,
    /// Their bytes.
    pub inserted_bytes: u64,
    /// Blobs refused because they alone exceed `capacity_bytes`.
    pub refused: u64,
    /// Their bytes.
    pub refused_bytes: u64,
    /// Blobs evicted, least recently used first, to make room.
    pub evicted_entries: u64,
    /// Their bytes.
    pub evicted_bytes: u64,
}

/// The disk tier's counters ([`DiskCache::stats`](crate::DiskCache::stats)).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct DiskStats {
    /// The byte bound of the entries' files.
    pub capacity_bytes: u64,
    /// Whether writes are still on (a write failure or an unusable directory turns them off).
    pub writable: bool,
    /// Entries known now (found at open, written or read since).
    pub entries: u64,
    /// Bytes of their files (headers included), as this process knows them.
    pub bytes: u64,
    /// Entries found by the scan at open.
    pub found_at_open: u64,
    /// Their bytes.
    pub found_bytes_at_open: u64,
    /// Reads that returned a valid, compatible blob.
    pub hits: u64,
    /// Blob bytes those reads returned.
    pub hit_bytes: u64,
    /// Reads that returned nothing: no entry, or a bad one (also counted in `warnings`).
    pub misses: u64,
    /// Entries written (renamed into place).
    pub written: u64,
    /// Their file bytes.
    pub written_bytes: u64,
    /// Writes not attempted: writes were off, the blob had no serialization header, or the
    /// entry alone exceeds `capacity_bytes`.
    pub skipped_writes: u64,
    /// Entries removed, least recently used first, to stay under `capacity_bytes`.
    pub evicted_entries: u64,
    /// Their file bytes.
    pub evicted_bytes: u64,
    /// Bad entries removed after a warning.
    pub removed_bad: u64,
    /// Temp files of dead writers removed at open.
    pub stale_temp_files_removed: u64,
    /// Warnings by reason.
    pub warnings: WarningCounts,
    /// With the background writer: milliseconds its thread spent writing entries (the files'
    /// rate is `written_bytes / write_busy_ms`), those `put` waited for room in its queue (a
    /// disk slower than the builds), and those taken to wait for queued writes when the
    /// counters were read (at the end of a render: writes still pending after the image).
    pub write_busy_ms: f64,
    pub submit_wait_ms: f64,
    pub flush_wait_ms: f64,
}

/// Both tiers' counters as [`AsCache::stats`](crate::AsCache::stats) reports them: what the
/// streaming stats print.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CacheStats {
    /// `get`s answered from host memory.
    pub host_hits: u64,
    /// `get`s answered from the cache directory (each promoted to host memory).
    pub disk_hits: u64,
    /// `get`s neither tier answered: the caller builds.
    pub misses: u64,
    /// Blob bytes returned by hits of either tier.
    pub hit_bytes: u64,
    /// `put`s.
    pub puts: u64,
    /// Their blob bytes.
    pub put_bytes: u64,
    /// The host tier.
    pub host: HostStats,
    /// The disk tier (`None` when there is none: `--no-as-cache`, or no default directory).
    pub disk: Option<DiskStats>,
    /// The pool the blobs' memory comes from.
    pub pool: PoolStats,
}

/// A [`BlobPool`](crate::BlobPool)'s counters (`CacheStats::pool`, `AsCache::pool_stats`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PoolStats {
    /// Free buffers held now, and their bytes (capacity).
    pub free_buffers: u64,
    pub free_bytes: u64,
    /// The bound on free bytes now (the host tier's room; 0 before one is set).
    pub bound_bytes: u64,
    /// Buffers for blobs of at least [`MIN_POOLED_BYTES`](crate::MIN_POOLED_BYTES) (smaller
    /// ones come from the allocator's heap, uncounted) taken from the pool (pre-faulted or
    /// recycled), and the blob bytes they held.
    pub hits: u64,
    pub hit_bytes: u64,
    /// Buffers taken fresh from the allocator (nothing free fit), and their bytes.
    pub misses: u64,
    pub miss_bytes: u64,
    /// Buffers the filler threads pre-faulted, and their bytes.
    pub prefaulted: u64,
    pub prefaulted_bytes: u64,
    /// Buffers of dropped blobs kept for reuse, and their bytes.
    pub recycled: u64,
    pub recycled_bytes: u64,
    /// Buffers freed because the pool was at its bound or reserve.
    pub released: u64,
    pub released_bytes: u64,
    /// Milliseconds the filler threads spent pre-faulting, together.
    pub prefault_ms: f64,
}

impl CacheStats {
    /// Warnings of the disk tier by reason (all zero without one).
    pub fn warnings(&self) -> WarningCounts {
        self.disk.map(|d| d.warnings).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests;
