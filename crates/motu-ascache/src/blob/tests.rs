use super::*;

const MIB: usize = 1 << 20;

fn pool(reserve_bytes: u64, fill_threads: usize) -> BlobPool {
    BlobPool::new(PoolOptions {
        reserve_bytes,
        fill_threads,
    })
}

fn pattern(len: usize, seed: u8) -> Vec<u8> {
    (0..len)
        .map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed))
        .collect()
}

#[test]
fn a_copy_holds_exactly_its_bytes() {
    let p = pool(64 * MIB as u64, 0);
    p.set_bound(64 * MIB as u64);
    for (len, seed) in [(0, 1), (10, 2), (MIN_POOLED_BYTES, 3), (3 * MIB + 17, 4)] {
        let bytes = pattern(len, seed);
        let blob = p.copy(&bytes);
        assert_eq!(&blob[..], &bytes[..]);
        assert_eq!(blob.len(), len);
    }
}

#[test]
fn the_last_dropped_clone_gives_the_buffer_back_and_it_is_reused() {
    let p = pool(64 * MIB as u64, 0);
    p.set_bound(64 * MIB as u64);
    let a = p.copy(&pattern(2 * MIB, 1));
    let first = a.as_ptr();
    let b = a.clone();
    drop(a);
    assert_eq!(p.stats().free_buffers, 0, "a clone still holds it");
    assert_eq!(&b[..], &pattern(2 * MIB, 1)[..]);
    drop(b);
    let s = p.stats();
    assert_eq!(
        (s.free_buffers, s.free_bytes, s.recycled),
        (1, 2 * MIB as u64, 1)
    );
    // A blob of a similar length reuses that memory, with none of the old bytes left.
    let c = p.copy(&pattern(2 * MIB - 100, 9));
    assert_eq!(c.as_ptr(), first);
    assert_eq!(&c[..], &pattern(2 * MIB - 100, 9)[..]);
    let s = p.stats();
    assert_eq!((s.hits, s.misses, s.free_buffers), (1, 1, 0));
}

#[test]
fn free_bytes_never_exceed_the_bound_or_the_reserve() {
    let p = pool(5 * MIB as u64, 0);
    p.set_bound(100 * MIB as u64);
    let blobs: Vec<Blob> = (0..8).map(|i| p.copy(&pattern(MIB, i))).collect();
    drop(blobs);
    let s = p.stats();
    assert_eq!(s.free_bytes, 5 * MIB as u64, "the reserve caps it");
    assert_eq!((s.recycled, s.released), (5, 3));
    p.set_bound(2 * MIB as u64);
    let s = p.stats();
    assert_eq!((s.free_bytes, s.free_buffers), (2 * MIB as u64, 2));
    p.set_bound(0);
    assert_eq!(p.stats().free_bytes, 0);
    // At a bound of 0 nothing is kept.
    drop(p.copy(&pattern(MIB, 0)));
    assert_eq!(p.stats().free_bytes, 0);
}

#[test]
fn a_blob_larger_than_any_free_buffer_is_allocated_fresh_and_later_recycled() {
    let p = pool(64 * MIB as u64, 0);
    p.set_bound(64 * MIB as u64);
    drop(p.copy(&pattern(MIB, 1)));
    let big = p.copy(&pattern(9 * MIB + 3, 2));
    assert_eq!(&big[..], &pattern(9 * MIB + 3, 2)[..]);
    let s = p.stats();
    assert_eq!((s.misses, s.hits, s.free_buffers), (2, 0, 1));
    drop(big);
    assert_eq!(p.stats().free_buffers, 2);
    // The small one serves a small blob, the big one a big blob.
    let small = p.copy(&pattern(MIB - 5, 3));
    let big = p.copy(&pattern(8 * MIB, 4));
    assert_eq!(&small[..], &pattern(MIB - 5, 3)[..]);
    assert_eq!(&big[..], &pattern(8 * MIB, 4)[..]);
    assert_eq!(p.stats().hits, 2);
}

#[test]
fn a_much_longer_buffer_is_cut_down_to_the_blob() {
    let p = pool(64 * MIB as u64, 0);
    p.set_bound(64 * MIB as u64);
    drop(p.copy(&pattern(16 * MIB, 1)));
    let small = p.copy(&pattern(MIB, 2));
    assert_eq!(&small[..], &pattern(MIB, 2)[..]);
    assert_eq!(p.stats().hits, 1);
    drop(small);
    // What comes back is the cut-down buffer, not 16 MiB.
    assert!(p.stats().free_bytes < 2 * MIB as u64);
}

#[test]
fn refill_prefaults_the_last_burst_s_sizes_within_the_limit() {
    let p = pool(64 * MIB as u64, 2);
    p.set_bound(10 * MIB as u64);
    let burst: Vec<Blob> = [3 * MIB, 2 * MIB, 4 * MIB, 5 * MIB, 100]
        .iter()
        .map(|&l| p.copy(&pattern(l, 1)))
        .collect();
    p.set_bound(0); // the blobs are kept elsewhere: nothing recycled
    drop(burst);
    p.set_bound(10 * MIB as u64);
    p.refill();
    p.wait_filled();
    let s = p.stats();
    // Largest first until the bound: 5 + 4 MiB (3 more would pass 10).
    assert_eq!((s.prefaulted, s.free_bytes), (2, 9 * MIB as u64));
    let b = p.copy(&pattern(4 * MIB - 1000, 7));
    assert_eq!(&b[..], &pattern(4 * MIB - 1000, 7)[..]);
    assert_eq!(p.stats().hits, 1);
    // Nothing taken since: a second refill plans nothing.
    p.refill();
    p.wait_filled();
    assert_eq!(p.stats().prefaulted, 2);
}

#[test]
fn prefault_plans_given_lengths_and_a_dropped_pool_stops_its_threads() {
    let p = pool(64 * MIB as u64, 1);
    p.set_bound(64 * MIB as u64);
    p.prefault(&[MIB, 2 * MIB, 10]);
    p.wait_filled();
    let s = p.stats();
    assert_eq!((s.prefaulted, s.prefaulted_bytes), (2, 3 * MIB as u64));
    let blob = p.copy(&pattern(2 * MIB, 5));
    let weak = Arc::downgrade(&p.shared);
    drop(p);
    // The blob outlives its pool; the threads let go of it within their wait.
    assert_eq!(&blob[..], &pattern(2 * MIB, 5)[..]);
    let t = std::time::Instant::now();
    while weak.upgrade().is_some() {
        assert!(
            t.elapsed() < Duration::from_secs(5),
            "a filler thread kept the pool"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    drop(blob);
}

#[test]
fn an_unfrozen_buffer_goes_back_and_blobs_compare_by_content() {
    let p = pool(64 * MIB as u64, 0);
    p.set_bound(64 * MIB as u64);
    let mut buf = p.take(MIB);
    buf.bytes_mut().extend_from_slice(&[1, 2, 3]);
    drop(buf);
    assert_eq!(p.stats().free_buffers, 1);
    let a = Blob::from(vec![1u8, 2, 3]);
    let b = Blob::from(&[1u8, 2, 3][..]);
    assert_eq!(a, b);
    assert!(!Blob::ptr_eq(&a, &b));
    assert_eq!(Blob::strong_count(&a), 1);
}
