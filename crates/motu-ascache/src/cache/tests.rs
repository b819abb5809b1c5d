use super::*;
use crate::compat::AnyDevice;
use crate::disk::DiskOptions;
use crate::stats::WarningReason;

fn key(i: u8) -> CacheKey {
    CacheKey([i; 32])
}

/// A fake serialized structure: a 32-byte header of `driver`, then `len` bytes.
fn blob(driver: u8, len: usize) -> Blob {
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

#[test]
fn the_pool_is_bounded_by_the_host_tier_s_room_and_disk_reads_land_in_it() {
    const MIB: usize = 1 << 20;
    let dir = tempfile::tempdir().unwrap();
    let big_disk = || {
        DiskCache::open(
            dir.path(),
            DiskOptions {
                capacity_bytes: Some(64 << 20),
                ..DiskOptions::default()
            },
        )
    };
    let pool = || {
        BlobPool::new(crate::blob::PoolOptions {
            reserve_bytes: 1 << 30,
            fill_threads: 1,
        })
    };
    let mut c = AsCache::with_pool(HostCache::new(16 << 20), Some(big_disk()), pool());
    assert_eq!(c.pool_stats().bound_bytes, 16 << 20);
    let blobs: Vec<Blob> = (0..4).map(|i| blob(i, 2 * MIB + usize::from(i))).collect();
    for (i, b) in blobs.iter().enumerate() {
        c.put(key(i as u8), c.pool().copy(b));
    }
    let held = c.host().bytes();
    assert_eq!(c.pool_stats().bound_bytes, (16 << 20) - held);
    c.flush();

    // The next process reads them from disk into its pool's buffers, then pre-faults as many
    // for the next burst: the pool and the host tier together stay within the bound.
    let mut next = AsCache::with_pool(HostCache::new(12 << 20), Some(big_disk()), pool());
    let keys: Vec<CacheKey> = (0..4).map(key).collect();
    let found = next.get_many(&keys, &AnyDevice);
    for (f, b) in found.iter().zip(&blobs) {
        let (got, tier) = f.as_ref().unwrap();
        assert_eq!((*tier, &got[..]), (Tier::Disk, &b[..]));
    }
    next.pool().wait_filled();
    let s = next.pool_stats();
    assert_eq!(s.misses, 4, "an empty pool: fresh buffers");
    let room = (12 << 20) - next.host().bytes();
    assert_eq!(s.bound_bytes, room);
    assert!(s.free_bytes <= room && s.prefaulted >= 1, "{s:?}");
    // Shrinking the host tier shrinks the pool with it.
    let held = next.host().bytes();
    next.host_mut().set_capacity_bytes(held);
    assert_eq!(next.pool_stats().free_bytes, 0);
}

#[test]
fn planned_disk_reads_run_on_another_thread_and_count_as_get_many() {
    let dir = tempfile::tempdir().unwrap();
    {
        let mut c = AsCache::new(HostCache::new(1 << 20), Some(disk(dir.path())));
        for i in 0..6 {
            c.put(key(i), blob(1, 100 * usize::from(i + 1)));
        }
    }
    let mut c = AsCache::new(HostCache::new(1 << 20), Some(disk(dir.path())));
    // Sizes known without a read: the directory's index (blob bytes, not the file's).
    assert_eq!(c.entry_bytes(&key(2)), Some((Tier::Disk, 332)));
    assert_eq!(c.entry_bytes(&key(9)), None);
    // Kept in host memory only: never written to the directory.
    c.put_host(key(7), blob(1, 10));
    assert_eq!(c.entry_bytes(&key(7)), Some((Tier::Host, 42)));
    assert_eq!(c.stats().disk.unwrap().written, 0);
    let keys = [key(0), key(9), key(5)];
    let plan = c.plan_disk_reads(&keys).expect("a disk tier");
    assert_eq!(plan.files(), 3);
    let done = std::thread::spawn(move || plan.run(&driver(1)))
        .join()
        .unwrap();
    assert!(done.read_ms >= 0.0);
    let got = c.finish_disk_reads(done);
    assert_eq!(got.len(), 3);
    assert_eq!(got[0].as_deref(), Some(&*blob(1, 100)));
    assert!(got[1].is_none());
    assert_eq!(got[2].as_deref(), Some(&*blob(1, 600)));
    let s = c.stats();
    assert_eq!((s.host_hits, s.disk_hits, s.misses, s.puts), (0, 2, 1, 1));
    // Promoted to host memory, as get_many promotes.
    assert_eq!(c.contains(&key(5)), Some(Tier::Host));
    // No disk tier: nothing to plan.
    let mut host_only = AsCache::new(HostCache::new(1 << 20), None);
    assert!(host_only.plan_disk_reads(&keys).is_none());
}
