//! The disk tier's background writer: entries are written on a thread of their own, so the
//! frame that built a structure does not wait for its file (write, rename) while the GPU idles.
//!
//! The [`DiskCache`](crate::DiskCache) keeps every decision (the index, eviction, when writes
//! turn off) on its own thread; this thread only does IO and counts what it did. A key whose
//! entry is still queued or being written is answered from the queue's blob, so a pending
//! write is never a miss. Queued bytes are bounded: `submit` waits while the queue holds more
//! than its bound of blobs only the queue keeps alive, so a disk slower than the builds slows
//! the builds instead of filling memory. A blob the host tier also holds costs no memory of its
//! own and is not counted: with the bound on all queued bytes (1 GiB), island 0.63's first
//! frame on the H200 stored its 13 GB at the disk's pace, 13 s of a 24 s frame.
//! Dropping the writer writes everything queued first (a process that ends has its entries on
//! disk for the next one).

use std::collections::VecDeque;
use std::io;
use std::path::PathBuf;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};

use crate::blob::Blob;
use std::thread::JoinHandle;

use crate::file::{io_reason, write_entry_file};
use crate::key::CacheKey;
use crate::stats::WarningCounts;

/// One entry to write.
pub(crate) struct Job {
    pub key: CacheKey,
    pub root: PathBuf,
    pub blob: Blob,
    pub sync: bool,
    pub fail_with: Option<io::ErrorKind>,
}

/// What the writer did, for the owner's counters and index.
#[derive(Default)]
pub(crate) struct Done {
    /// Entries renamed into place.
    pub written: u64,
    /// Their file bytes.
    pub written_bytes: u64,
    /// Failed writes' warnings (each also a `tracing::warn!`).
    pub warnings: WarningCounts,
    /// Milliseconds the thread spent writing entries (their files' rate is
    /// `written_bytes / write_busy_ms`).
    pub write_busy_ms: f64,
    /// Milliseconds `submit` waited for room in the queue (the frame's cost of a slow disk).
    pub submit_wait_ms: f64,
    /// Milliseconds `flush` waited for queued writes.
    pub flush_wait_ms: f64,
}

#[derive(Default)]
struct State {
    queue: VecDeque<Job>,
    /// The job being written: its key and blob (still answerable), and whether it was
    /// cancelled meanwhile (its file is removed once written).
    in_flight: Option<(CacheKey, Blob, bool)>,
    /// Blob bytes queued or in flight.
    pending_bytes: u64,
    done: Done,
    /// Keys whose writes failed or were dropped after a failure: the owner forgets them.
    unwritten: Vec<CacheKey>,
    /// A write failed: later jobs are dropped (the owner turns writes off when it drains).
    failed: bool,
    closing: bool,
}

impl State {
    /// Queued bytes that only the queue keeps alive (no host tier or caller holds them). The
    /// in-flight blob is held by the writing thread until it is written, so it counts too.
    fn own_bytes(&self) -> u64 {
        let queued: u64 = self
            .queue
            .iter()
            .filter(|j| Blob::strong_count(&j.blob) == 1)
            .map(|j| j.blob.len() as u64)
            .sum();
        // The state's copy plus the thread's job: 2 when no one else holds it.
        let in_flight = self
            .in_flight
            .as_ref()
            .filter(|(_, b, _)| Blob::strong_count(b) <= 2)
            .map_or(0, |(_, b, _)| b.len() as u64);
        queued + in_flight
    }
}

struct Shared {
    state: Mutex<State>,
    /// Signalled when a job is queued, finished or the writer is closing.
    changed: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, State> {
        // A panic on the writer thread is a bug; its state is still consistent counters.
        self.state.lock().unwrap_or_else(|p| p.into_inner())
    }
}

/// The thread and the queue it drains.
pub(crate) struct Writer {
    shared: Arc<Shared>,
    max_pending_bytes: u64,
    thread: Option<JoinHandle<()>>,
}

impl Writer {
    /// Starts the thread; `submit` waits while more than `max_pending_bytes` are queued.
    pub fn start(max_pending_bytes: u64) -> io::Result<Self> {
        let shared = Arc::new(Shared {
            state: Mutex::new(State::default()),
            changed: Condvar::new(),
        });
        let worker = Arc::clone(&shared);
        let thread = std::thread::Builder::new()
            .name("motu-as-cache-writer".into())
            .spawn(move || run(&worker))?;
        Ok(Self {
            shared,
            max_pending_bytes,
            thread: Some(thread),
        })
    }

    /// Queues `job`, first waiting while the queue's own bytes are over its bound (unless
    /// nothing queued is the queue's alone).
    pub fn submit(&self, job: Job) {
        let bytes = job.blob.len() as u64;
        let mut s = self.shared.lock();
        let mut waited = None;
        loop {
            let own = s.own_bytes();
            if own == 0 || own + bytes <= self.max_pending_bytes {
                break;
            }
            waited.get_or_insert_with(std::time::Instant::now);
            s = self
                .shared
                .changed
                .wait(s)
                .unwrap_or_else(|p| p.into_inner());
        }
        if let Some(t) = waited {
            s.done.submit_wait_ms += t.elapsed().as_secs_f64() * 1e3;
        }
        s.pending_bytes += bytes;
        s.queue.push_back(job);
        drop(s);
        self.shared.changed.notify_all();
    }

    /// The blob of `key` if its write is queued or under way.
    pub fn pending_blob(&self, key: &CacheKey) -> Option<Blob> {
        let s = self.shared.lock();
        if let Some((k, blob, false)) = &s.in_flight {
            if k == key {
                return Some(blob.clone());
            }
        }
        s.queue
            .iter()
            .rev()
            .find(|j| j.key == *key)
            .map(|j| j.blob.clone())
    }

    /// Drops `key`'s queued write; one under way has its file removed once it is written.
    pub fn cancel(&self, key: &CacheKey) {
        let mut s = self.shared.lock();
        let before = s.queue.len();
        let mut freed = 0;
        s.queue.retain(|j| {
            let keep = j.key != *key;
            if !keep {
                freed += j.blob.len() as u64;
            }
            keep
        });
        s.pending_bytes -= freed;
        if let Some((k, _, cancelled)) = s.in_flight.as_mut() {
            if k == key {
                *cancelled = true;
            }
        }
        let removed = before != s.queue.len();
        drop(s);
        if removed {
            self.shared.changed.notify_all();
        }
    }

    /// The counters so far (not drained: they keep growing).
    pub fn with_done<R>(&self, f: impl FnOnce(&Done) -> R) -> R {
        f(&self.shared.lock().done)
    }

    /// Keys whose writes failed or were dropped since the last call, and whether a write
    /// failed (writes must turn off).
    pub fn take_unwritten(&self) -> (Vec<CacheKey>, bool) {
        let mut s = self.shared.lock();
        (std::mem::take(&mut s.unwritten), s.failed)
    }

    /// Waits until every queued write is done.
    pub fn flush(&self) {
        let t = std::time::Instant::now();
        let mut s = self.shared.lock();
        while !s.queue.is_empty() || s.in_flight.is_some() {
            s = self
                .shared
                .changed
                .wait(s)
                .unwrap_or_else(|p| p.into_inner());
        }
        s.done.flush_wait_ms += t.elapsed().as_secs_f64() * 1e3;
    }
}

impl Drop for Writer {
    fn drop(&mut self) {
        self.shared.lock().closing = true;
        self.shared.changed.notify_all();
        if let Some(t) = self.thread.take() {
            if t.join().is_err() {
                tracing::warn!(
                    "the structure cache's writer thread panicked; entries may be missing"
                );
            }
        }
    }
}

fn run(shared: &Shared) {
    loop {
        let job = {
            let mut s = shared.lock();
            loop {
                if let Some(job) = s.queue.pop_front() {
                    break job;
                }
                if s.closing {
                    return;
                }
                s = shared.changed.wait(s).unwrap_or_else(|p| p.into_inner());
            }
        };
        let bytes = job.blob.len() as u64;
        {
            let mut s = shared.lock();
            if s.failed {
                // Writes are off: the owner forgets the key when it drains.
                s.unwritten.push(job.key);
                s.pending_bytes -= bytes;
                drop(s);
                shared.changed.notify_all();
                continue;
            }
            s.in_flight = Some((job.key, job.blob.clone(), false));
        }
        let t = std::time::Instant::now();
        let result = write_entry_file(&job.root, &job.key, &job.blob, job.sync, job.fail_with);
        let busy_ms = t.elapsed().as_secs_f64() * 1e3;
        drop(job.blob);
        let mut s = shared.lock();
        s.done.write_busy_ms += busy_ms;
        let cancelled = s.in_flight.take().is_some_and(|(_, _, c)| c);
        s.pending_bytes -= bytes;
        match result {
            Ok((path, file_bytes)) => {
                if cancelled {
                    // Evicted while it was written: the index no longer has it.
                    let _ = std::fs::remove_file(&path);
                } else {
                    s.done.written += 1;
                    s.done.written_bytes += file_bytes;
                    tracing::debug!(key = %job.key, bytes = file_bytes, "wrote a cache entry");
                }
            }
            Err((path, e)) => {
                let reason = io_reason(&e);
                s.done.warnings.count(reason);
                s.failed = true;
                s.unwritten.push(job.key);
                tracing::warn!(
                    path = %path.display(),
                    %reason,
                    error = %e,
                    "cannot write a cache entry; the acceleration-structure cache stops writing \
                     (renders go on, rebuilding)"
                );
            }
        }
        drop(s);
        shared.changed.notify_all();
    }
}

#[cfg(test)]
mod tests;
