//! Blobs and the memory they live in: a [`Blob`] is a shared, immutable byte buffer; a
//! [`BlobPool`] hands out buffers whose pages are already in memory (pre-faulted on a thread
//! of the pool's own, or recycled from blobs no one holds any more), so that filling them (a
//! copy out of a readback buffer, a read from a cache file) runs at the speed of touched
//! memory instead of paying a page fault and the kernel's zeroing per 4 KiB on the way.
//!
//! A pool never changes a byte: a buffer is handed out empty (`len` 0) and the caller writes
//! every byte of the blob into it. Its free buffers are bounded ([`BlobPool::set_bound`]: the
//! [`AsCache`](crate::AsCache) keeps it at the room its host tier has left, so the process
//! never holds more than the host tier would once full) and by [`PoolOptions::reserve_bytes`].

use std::collections::BTreeMap;
use std::ops::Deref;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, Weak};
use std::time::Duration;

use crate::stats::PoolStats;

/// Buffers shorter than this are not pooled: small allocations come from the allocator's
/// heap, whose memory is mostly touched already.
pub const MIN_POOLED_BYTES: usize = 64 << 10;

/// Pre-faulted buffers are sized up to a multiple of this, so that a buffer planned for one
/// blob fits the next of a similar size.
pub const POOL_GRANULE_BYTES: usize = 64 << 10;

/// The most free bytes a pool keeps by default: 4 GiB (a store or restore burst of the
/// measured frames moved ~1 GB per pass).
pub const DEFAULT_RESERVE_BYTES: u64 = 4 << 30;

/// The page size the filler touches at (a smaller real page would only fault on first write).
const TOUCH_STRIDE_BYTES: usize = 4096;

/// A buffer taken for a blob of `len` bytes is cut down to `len` (its tail given back to the
/// allocator) when it is longer by more than this share of `len` (or 256 KiB).
const SLACK_DENOMINATOR: usize = 4;
const MIN_SLACK_BYTES: usize = 256 << 10;

/// The most blob lengths kept for the next [`BlobPool::refill`].
const MAX_TAKEN_RECORDED: usize = 1 << 16;

/// How a [`BlobPool`] works.
#[derive(Debug, Clone)]
pub struct PoolOptions {
    /// The most free bytes the pool keeps (pre-faulted and recycled), below its bound.
    pub reserve_bytes: u64,
    /// Threads that pre-fault buffers (0: none; buffers are then only recycled).
    pub fill_threads: usize,
}

impl Default for PoolOptions {
    /// [`DEFAULT_RESERVE_BYTES`]; a quarter of the cores to pre-fault with (1 to 4).
    fn default() -> Self {
        let cores = std::thread::available_parallelism().map_or(1, usize::from);
        Self {
            reserve_bytes: DEFAULT_RESERVE_BYTES,
            fill_threads: (cores / 4).clamp(1, 4),
        }
    }
}

struct State {
    /// Free buffers (`len` 0) by capacity.
    free: BTreeMap<usize, Vec<Vec<u8>>>,
    free_bytes: u64,
    /// Bytes the filler threads are pre-faulting now.
    filling_bytes: u64,
    bound_bytes: u64,
    /// Sizes still to pre-fault.
    plan: Vec<usize>,
    /// The lengths of blobs taken since the last [`BlobPool::refill`].
    taken: Vec<usize>,
    threads_started: bool,
    stats: PoolStats,
}

struct Shared {
    state: Mutex<State>,
    work: Condvar,
    options: PoolOptions,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        // A panic while holding the lock leaves counters at worst stale: go on.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }

    fn limit(&self, s: &State) -> u64 {
        s.bound_bytes.min(self.options.reserve_bytes)
    }

    /// Keeps `buf` (of a dropped blob, or pre-faulted) when it fits under the limit.
    fn give_back(&self, mut buf: Vec<u8>, prefaulted: bool) {
        let cap = buf.capacity();
        let mut s = self.lock();
        if cap >= MIN_POOLED_BYTES && s.free_bytes + cap as u64 <= self.limit(&s) {
            buf.clear();
            s.free_bytes += cap as u64;
            s.free.entry(cap).or_default().push(buf);
            if prefaulted {
                s.stats.prefaulted += 1;
                s.stats.prefaulted_bytes += cap as u64;
            } else {
                s.stats.recycled += 1;
                s.stats.recycled_bytes += cap as u64;
            }
        } else if cap >= MIN_POOLED_BYTES {
            s.stats.released += 1;
            s.stats.released_bytes += cap as u64;
            drop(s);
            drop(buf); // freed outside the lock
        }
    }
}

/// Buffers for blobs whose pages are in memory before they are filled. Cloning shares the
/// pool. Without [`refill`](Self::refill) or [`prefault`](Self::prefault) calls it only
/// recycles the buffers of dropped blobs (within its bound).
#[derive(Clone)]
pub struct BlobPool {
    shared: Arc<Shared>,
}

impl std::fmt::Debug for BlobPool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BlobPool")
            .field("stats", &self.stats())
            .finish()
    }
}

impl Default for BlobPool {
    fn default() -> Self {
        Self::new(PoolOptions::default())
    }
}

impl BlobPool {
    /// An empty pool with a bound of 0 (it keeps nothing until [`set_bound`](Self::set_bound)).
    pub fn new(options: PoolOptions) -> Self {
        Self {
            shared: Arc::new(Shared {
                state: Mutex::new(State {
                    free: BTreeMap::new(),
                    free_bytes: 0,
                    filling_bytes: 0,
                    bound_bytes: 0,
                    plan: Vec::new(),
                    taken: Vec::new(),
                    threads_started: false,
                    stats: PoolStats::default(),
                }),
                work: Condvar::new(),
                options,
            }),
        }
    }

    /// Sets the most free bytes the pool may hold (with the reserve, the smaller counts),
    /// freeing free buffers, largest first, above it.
    pub fn set_bound(&self, bound_bytes: u64) {
        let mut freed = Vec::new();
        {
            let mut s = self.shared.lock();
            s.bound_bytes = bound_bytes;
            let limit = self.shared.limit(&s);
            while s.free_bytes > limit {
                let Some(mut last) = s.free.last_entry() else {
                    break;
                };
                let buf = last.get_mut().pop().expect("no empty lists are kept");
                if last.get().is_empty() {
                    last.remove();
                }
                s.free_bytes -= buf.capacity() as u64;
                s.stats.released += 1;
                s.stats.released_bytes += buf.capacity() as u64;
                freed.push(buf);
            }
        }
        drop(freed);
    }

    /// An empty buffer with room for `len` bytes: a free one when one is long enough (cut down
    /// to `len` when much longer), else a fresh allocation. Fill it and
    /// [`freeze`](BlobBuf::freeze) it.
    pub fn take(&self, len: usize) -> BlobBuf {
        let home = Arc::downgrade(&self.shared);
        if len < MIN_POOLED_BYTES {
            return BlobBuf::new(Vec::with_capacity(len), Weak::new());
        }
        let found = {
            let mut s = self.shared.lock();
            if s.taken.len() < MAX_TAKEN_RECORDED {
                s.taken.push(len);
            }
            let cap = s.free.range(len..).next().map(|(&c, _)| c);
            let found = cap.map(|cap| {
                let mut list = s.free.remove(&cap).expect("found above");
                let buf = list.pop().expect("no empty lists are kept");
                if !list.is_empty() {
                    s.free.insert(cap, list);
                }
                s.free_bytes -= cap as u64;
                buf
            });
            if found.is_some() {
                s.stats.hits += 1;
                s.stats.hit_bytes += len as u64;
            } else {
                s.stats.misses += 1;
                s.stats.miss_bytes += len as u64;
            }
            found
        };
        let buf = match found {
            Some(mut buf) => {
                if buf.capacity() - len > (len / SLACK_DENOMINATOR).max(MIN_SLACK_BYTES) {
                    // An empty buffer: the allocator shrinks it in place (glibc: mremap or a
                    // split chunk), the pages kept still touched; nothing is copied.
                    buf.shrink_to(len);
                }
                buf
            }
            None => Vec::with_capacity(len),
        };
        BlobBuf::new(buf, home)
    }

    /// A blob holding a copy of `bytes`, in a buffer from [`take`](Self::take).
    pub fn copy(&self, bytes: &[u8]) -> Blob {
        let mut buf = self.take(bytes.len());
        buf.bytes_mut().extend_from_slice(bytes);
        buf.freeze()
    }

    /// Pre-faults, on the pool's threads, buffers of the lengths taken since the last call
    /// (a burst's blobs: the next burst's are of similar sizes), up to the limit. Call it when
    /// a burst is over; it returns at once.
    pub fn refill(&self) {
        let mut s = self.shared.lock();
        let taken = std::mem::take(&mut s.taken);
        self.plan(&mut s, &taken);
    }

    /// Pre-faults, on the pool's threads, buffers for blobs of `lens` bytes (e.g. a batch's
    /// serialised sizes, known before the device writes them), up to the limit; returns at
    /// once.
    pub fn prefault(&self, lens: &[usize]) {
        let mut s = self.shared.lock();
        self.plan(&mut s, lens);
    }

    fn plan(&self, s: &mut MutexGuard<'_, State>, lens: &[usize]) {
        if self.shared.options.fill_threads == 0 {
            return;
        }
        let limit = self.shared.limit(s);
        let mut planned: u64 =
            s.free_bytes + s.filling_bytes + s.plan.iter().map(|&l| l as u64).sum::<u64>();
        // Buffers free or planned already serve the lengths they fit (as `take` would match
        // them); the rest are planned, largest first (the large blobs carry most bytes), each
        // that still fits under the limit.
        let mut have: BTreeMap<usize, usize> = BTreeMap::new();
        for (&cap, list) in &s.free {
            *have.entry(cap).or_default() += list.len();
        }
        for &size in &s.plan {
            *have.entry(size).or_default() += 1;
        }
        let mut lens: Vec<usize> = lens
            .iter()
            .copied()
            .filter(|&len| len >= MIN_POOLED_BYTES)
            .collect();
        lens.sort_unstable_by(|a, b| b.cmp(a));
        for len in lens {
            if let Some(cap) = have.range(len..).next().map(|(&c, _)| c) {
                let n = have.get_mut(&cap).expect("found above");
                *n -= 1;
                if *n == 0 {
                    have.remove(&cap);
                }
                continue;
            }
            let size = len.div_ceil(POOL_GRANULE_BYTES) * POOL_GRANULE_BYTES;
            if planned + size as u64 <= limit {
                planned += size as u64;
                s.plan.push(size);
            }
        }
        if s.plan.is_empty() {
            return;
        }
        // Largest first: the filler pops from the end.
        s.plan.sort_unstable();
        if !s.threads_started {
            s.threads_started = true;
            for i in 0..self.shared.options.fill_threads {
                let weak = Arc::downgrade(&self.shared);
                let spawned = std::thread::Builder::new()
                    .name(format!("motu-blob-pool-{i}"))
                    .spawn(move || fill(weak));
                if let Err(e) = spawned {
                    tracing::warn!(error = %e, "no thread to pre-fault cache blobs");
                    if i == 0 {
                        s.plan.clear(); // nothing would ever take it
                        return;
                    }
                }
            }
        }
        self.shared.work.notify_all();
    }

    /// Waits until nothing is left to pre-fault (for tests and benchmarks).
    pub fn wait_filled(&self) {
        let mut s = self.shared.lock();
        while !(s.plan.is_empty() && s.filling_bytes == 0) && s.threads_started {
            let (g, _) = self
                .shared
                .work
                .wait_timeout(s, Duration::from_millis(10))
                .unwrap_or_else(|p| p.into_inner());
            s = g;
        }
    }

    /// The counters now.
    pub fn stats(&self) -> PoolStats {
        let s = self.shared.lock();
        PoolStats {
            free_buffers: s.free.values().map(|l| l.len() as u64).sum(),
            free_bytes: s.free_bytes,
            bound_bytes: s.bound_bytes,
            ..s.stats
        }
    }
}

/// A filler thread: pre-faults planned buffers until the pool is dropped.
fn fill(weak: Weak<Shared>) {
    loop {
        let Some(shared) = weak.upgrade() else { return };
        let size = {
            let mut s = shared.lock();
            match s.plan.pop() {
                Some(size) if s.free_bytes + s.filling_bytes + size as u64 <= shared.limit(&s) => {
                    s.filling_bytes += size as u64;
                    Some(size)
                }
                Some(_) => {
                    s.plan.clear(); // the bound fell since: drop the rest of the plan
                    shared.work.notify_all();
                    None
                }
                None => {
                    // Wake now and then without holding the pool, so its drop frees it.
                    drop(shared.work.wait_timeout(s, Duration::from_millis(50)));
                    None
                }
            }
        };
        let Some(size) = size else { continue };
        let t = std::time::Instant::now();
        let buf = prefaulted(size);
        let ms = t.elapsed().as_secs_f64() * 1e3;
        {
            let mut s = shared.lock();
            s.filling_bytes -= size as u64;
            s.stats.prefault_ms += ms;
        }
        shared.give_back(buf, true);
        shared.work.notify_all();
    }
}

/// An empty buffer of `size` bytes' capacity whose pages are in memory: one byte written per
/// page (the kernel zeroes the page on that fault), none read.
fn prefaulted(size: usize) -> Vec<u8> {
    let mut buf: Vec<u8> = Vec::with_capacity(size);
    for page in buf
        .spare_capacity_mut()
        .iter_mut()
        .step_by(TOUCH_STRIDE_BYTES)
    {
        page.write(0);
    }
    buf
}

/// A buffer being filled for a blob (from [`BlobPool::take`]); dropped unfrozen, it goes back
/// to its pool.
pub struct BlobBuf(Inner);

impl BlobBuf {
    fn new(bytes: Vec<u8>, home: Weak<Shared>) -> Self {
        BlobBuf(Inner { bytes, home })
    }

    /// The bytes so far (empty when taken); write the blob here (within the capacity taken
    /// for, nothing is reallocated).
    pub fn bytes_mut(&mut self) -> &mut Vec<u8> {
        &mut self.0.bytes
    }

    /// The blob of the bytes written.
    pub fn freeze(self) -> Blob {
        Blob(Arc::new(self.0))
    }
}

struct Inner {
    bytes: Vec<u8>,
    /// The pool its buffer goes back to (none for a blob made outside one).
    home: Weak<Shared>,
}

impl Drop for Inner {
    fn drop(&mut self) {
        if let Some(pool) = self.home.upgrade() {
            pool.give_back(std::mem::take(&mut self.bytes), false);
        }
    }
}

/// A serialised structure (or any cache blob): shared, immutable bytes. Cloning shares them;
/// when the last clone drops, a pooled blob's buffer goes back to its [`BlobPool`].
#[derive(Clone)]
pub struct Blob(Arc<Inner>);

impl Blob {
    /// Whether `a` and `b` share their bytes.
    pub fn ptr_eq(a: &Blob, b: &Blob) -> bool {
        Arc::ptr_eq(&a.0, &b.0)
    }

    /// How many clones of this blob are alive.
    pub fn strong_count(this: &Blob) -> usize {
        Arc::strong_count(&this.0)
    }
}

impl Deref for Blob {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        &self.0.bytes
    }
}

impl AsRef<[u8]> for Blob {
    fn as_ref(&self) -> &[u8] {
        self
    }
}

impl std::fmt::Debug for Blob {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Blob").field("len", &self.len()).finish()
    }
}

impl PartialEq for Blob {
    fn eq(&self, other: &Blob) -> bool {
        self[..] == other[..]
    }
}

impl Eq for Blob {}

impl From<Vec<u8>> for Blob {
    /// A blob of `bytes`, outside any pool (no copy).
    fn from(bytes: Vec<u8>) -> Blob {
        BlobBuf::new(bytes, Weak::new()).freeze()
    }
}

impl From<&[u8]> for Blob {
    fn from(bytes: &[u8]) -> Blob {
        Blob::from(bytes.to_vec())
    }
}

impl From<Arc<[u8]>> for Blob {
    /// A copy of `bytes`.
    fn from(bytes: Arc<[u8]>) -> Blob {
        Blob::from(&bytes[..])
    }
}

#[cfg(test)]
mod tests;
