//! The background writer, through the disk tier that owns it.

use crate::blob::Blob;
use std::fs;
use std::io;
use std::path::Path;

use crate::compat::AnyDevice;
use crate::disk::{DiskCache, DiskOptions};
use crate::entry::ENTRY_HEADER_BYTES;
use crate::key::{CacheKey, CacheKeyBuilder};

fn key(i: u32) -> CacheKey {
    CacheKeyBuilder::new("writer tests").u32(i).finish()
}

fn blob(i: u32, len: usize) -> Blob {
    let mut v = vec![7u8; 32];
    v.extend((0..len).map(|j| (j as u32 * 13 + i) as u8));
    v.into()
}

fn background(dir: &Path, capacity_bytes: u64, max_pending_bytes: u64) -> DiskCache {
    DiskCache::open(
        dir,
        DiskOptions {
            capacity_bytes: Some(capacity_bytes),
            background: true,
            max_pending_bytes,
            sync: false,
            ..DiskOptions::default()
        },
    )
}

/// Entry files (`*.as`) under `dir` and whether any temp file is left.
fn entry_files(dir: &Path) -> (usize, bool) {
    let (mut entries, mut temps) = (0, false);
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "as") {
                entries += 1;
            } else {
                temps = true;
            }
        }
    }
    (entries, temps)
}

#[test]
fn a_queued_entry_is_answered_from_memory_and_reaches_the_disk() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = background(dir.path(), 1 << 24, 1 << 30);
    for i in 0..20 {
        assert!(c.put_shared(&key(i), &blob(i, 10_000)));
    }
    // Whether queued or written by now, every key reads back as its bytes.
    for i in 0..20 {
        assert_eq!(
            &*c.get(&key(i), &AnyDevice).unwrap(),
            &*blob(i, 10_000),
            "key {i}"
        );
    }
    c.flush();
    let s = c.stats();
    assert_eq!(s.written, 20);
    assert_eq!(s.written_bytes, 20 * (10_032 + ENTRY_HEADER_BYTES as u64));
    assert_eq!(entry_files(dir.path()), (20, false));
    // Another process (a synchronous cache) reads them from disk.
    let mut next = DiskCache::open(dir.path(), DiskOptions::default());
    assert_eq!(&*next.get(&key(3), &AnyDevice).unwrap(), &*blob(3, 10_000));
}

#[test]
fn dropping_the_cache_writes_its_queue_first() {
    let dir = tempfile::tempdir().unwrap();
    {
        let mut c = background(dir.path(), 1 << 26, 1 << 30);
        for i in 0..50 {
            c.put_shared(&key(i), &blob(i, 50_000));
        }
    }
    assert_eq!(entry_files(dir.path()), (50, false));
    let next = DiskCache::open(dir.path(), DiskOptions::default());
    assert_eq!(next.stats().found_at_open, 50);
}

#[test]
fn a_full_disk_turns_writes_off_with_one_warning_and_forgets_the_keys() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = DiskCache::open(
        dir.path(),
        DiskOptions {
            capacity_bytes: Some(1 << 24),
            background: true,
            fail_writes_with: Some(io::ErrorKind::StorageFull),
            ..DiskOptions::default()
        },
    );
    for i in 0..5 {
        c.put_shared(&key(i), &blob(i, 1000));
    }
    // stats() waits for the queue: the failure is in it without a flush.
    let s = c.stats();
    assert!(!s.writable && s.warnings.full == 1, "{s:?}");
    c.flush();
    let s = c.stats();
    assert!(!s.writable, "a failed write turns writes off");
    assert_eq!(s.written, 0);
    assert_eq!(
        s.warnings.full, 1,
        "one failed write, the rest dropped without a warning each"
    );
    for i in 0..5 {
        assert!(!c.contains(&key(i)), "key {i} was never written");
    }
    // Later puts are skipped, counted; nothing half-written is left.
    assert!(!c.put_shared(&key(9), &blob(9, 1000)));
    assert_eq!(c.stats().skipped_writes, 1);
    assert_eq!(entry_files(dir.path()), (0, false));
}

#[test]
fn an_entry_evicted_while_queued_never_stays_on_disk() {
    let dir = tempfile::tempdir().unwrap();
    let entry = 10_032 + ENTRY_HEADER_BYTES as u64;
    // Room for two entries: each put past the second evicts the oldest, queued or written.
    let mut c = background(dir.path(), 2 * entry, 1 << 30);
    for i in 0..10 {
        c.put_shared(&key(i), &blob(i, 10_000));
    }
    c.flush();
    assert_eq!(entry_files(dir.path()), (2, false));
    let s = c.stats();
    assert_eq!((s.entries, s.bytes, s.evicted_entries), (2, 2 * entry, 8));
    assert!(c.contains(&key(9)) && c.contains(&key(8)) && !c.contains(&key(0)));
}

#[test]
fn a_small_queue_bound_slows_puts_without_losing_or_deadlocking() {
    let dir = tempfile::tempdir().unwrap();
    // Smaller than one blob: every put waits for the previous write.
    let mut c = background(dir.path(), 1 << 26, 100);
    for i in 0..30 {
        c.put_shared(&key(i), &blob(i, 20_000));
    }
    c.flush();
    assert_eq!(c.stats().written, 30);
    assert_eq!(entry_files(dir.path()), (30, false));
}

#[test]
fn removing_a_queued_key_drops_its_write() {
    let dir = tempfile::tempdir().unwrap();
    let mut c = background(dir.path(), 1 << 26, 1 << 30);
    for i in 0..10 {
        c.put_shared(&key(i), &blob(i, 100_000));
        c.remove(&key(i));
    }
    c.flush();
    assert_eq!(entry_files(dir.path()), (0, false));
    assert!(c.get(&key(4), &AnyDevice).is_none());
}

#[test]
fn blobs_held_elsewhere_do_not_count_against_the_queue_bound() {
    let dir = tempfile::tempdir().unwrap();
    // The bound is smaller than one blob, but the host tier (here: `held`) keeps every blob
    // alive, so queueing them costs no memory of the queue's own: no put waits.
    let mut c = background(dir.path(), 1 << 26, 100);
    let held: Vec<Blob> = (0..30).map(|i| blob(i, 20_000)).collect();
    for (i, b) in held.iter().enumerate() {
        c.put_shared(&key(i as u32), b);
    }
    let s = c.stats();
    assert_eq!(s.submit_wait_ms, 0.0, "{s:?}");
    assert_eq!(s.written, 30);
    assert!(s.write_busy_ms > 0.0, "{s:?}");
    assert_eq!(entry_files(dir.path()), (30, false));
}
