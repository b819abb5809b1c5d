use super::*;
use proptest::prelude::*;

fn key(i: u8) -> CacheKey {
    CacheKey([i; 32])
}

fn blob(len: usize, fill: u8) -> Blob {
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
