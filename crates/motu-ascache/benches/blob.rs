//! The store copy and the cache-file read into fresh memory against memory a [`BlobPool`]
//! paged in: a burst of 3 MiB blobs (the H100 host's measured store: ~11.5 GB of serialised
//! BLASes a cold frame, copied on all cores) on every core.
//!
//! Only the burst is timed: making the pool's buffers (pre-faulting, recycling) is not, as it
//! runs on the pool's threads while the device works.

use std::fs::File;
use std::hint::black_box;
use std::io::{Read, Write};
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use motu_ascache::{Blob, BlobPool, PoolOptions};

const BLOB_BYTES: usize = 3 << 20;
const BLOBS: usize = 64;
const BURST_BYTES: usize = BLOB_BYTES * BLOBS;

fn threads() -> usize {
    std::thread::available_parallelism().map_or(1, usize::from)
}

/// `f(0..n)` on every core, in order.
fn par_map<T: Send>(n: usize, f: impl Fn(usize) -> T + Sync) -> Vec<T> {
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut out: Vec<Option<T>> = (0..n).map(|_| None).collect();
    std::thread::scope(|s| {
        let workers: Vec<_> = (0..threads())
            .map(|_| {
                s.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        if i >= n {
                            break done;
                        }
                        done.push((i, f(i)));
                    }
                })
            })
            .collect();
        for w in workers {
            for (i, v) in w.join().expect("a worker panicked") {
                out[i] = Some(v);
            }
        }
    });
    out.into_iter().map(|v| v.expect("every index")).collect()
}

/// A pool that keeps a burst, pre-faulting on every core.
fn pool() -> BlobPool {
    let p = BlobPool::new(PoolOptions {
        reserve_bytes: 2 * BURST_BYTES as u64,
        fill_threads: threads(),
    });
    p.set_bound(2 * BURST_BYTES as u64);
    p
}

/// Times `burst` `iters` times; `prepare` runs untimed before each (with the last burst's
/// blobs, dropped after it).
fn timed<T>(
    iters: u64,
    mut prepare: impl FnMut(Vec<T>),
    mut burst: impl FnMut() -> Vec<T>,
) -> Duration {
    let mut total = Duration::ZERO;
    let mut last = Vec::new();
    for _ in 0..iters {
        prepare(std::mem::take(&mut last));
        let t = Instant::now();
        last = black_box(burst());
        total += t.elapsed();
    }
    drop(last);
    total
}

fn store_copy(c: &mut Criterion) {
    let src: Vec<u8> = (0..BURST_BYTES).map(|i| (i * 7 + i / 4096) as u8).collect();
    let blob = |i: usize| &src[i * BLOB_BYTES..][..BLOB_BYTES];
    let mut g = c.benchmark_group("store_copy");
    g.sample_size(10)
        .throughput(Throughput::Bytes(BURST_BYTES as u64));
    g.bench_function("fresh_arc", |b| {
        b.iter_custom(|n| timed(n, drop, || par_map(BLOBS, |i| Arc::<[u8]>::from(blob(i)))))
    });
    g.bench_function("pool_empty", |b| {
        let p = pool();
        p.set_bound(0);
        b.iter_custom(|n| timed(n, drop, || par_map(BLOBS, |i| p.copy(blob(i)))))
    });
    g.bench_function("pool_prefaulted", |b| {
        let p = pool();
        let lens = vec![BLOB_BYTES; BLOBS];
        let prepare = |last: Vec<Blob>| {
            p.set_bound(0); // dropped, not recycled: every buffer pre-faulted anew
            drop(last);
            p.set_bound(2 * BURST_BYTES as u64);
            p.prefault(&lens);
            p.wait_filled();
        };
        b.iter_custom(|n| timed(n, prepare, || par_map(BLOBS, |i| p.copy(blob(i)))))
    });
    g.bench_function("pool_recycled", |b| {
        let p = pool();
        b.iter_custom(|n| timed(n, drop, || par_map(BLOBS, |i| p.copy(blob(i)))))
    });
    g.finish();
}

fn disk_read(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("a temp dir");
    let paths: Vec<PathBuf> = (0..BLOBS)
        .map(|i| {
            let path = dir.path().join(format!("{i}.blob"));
            let bytes: Vec<u8> = (0..BLOB_BYTES).map(|j| (i + j * 13) as u8).collect();
            File::create(&path)
                .and_then(|mut f| f.write_all(&bytes))
                .expect("a blob file");
            path
        })
        .collect();
    // The old read: a zero-filled `Arc<[u8]>`, read into.
    let zero_filled = |i: usize| {
        let mut blob: Arc<[u8]> = std::iter::repeat_n(0u8, BLOB_BYTES).collect();
        let buf = Arc::get_mut(&mut blob).expect("unique");
        File::open(&paths[i])
            .and_then(|mut f| f.read_exact(buf))
            .expect("read");
        blob
    };
    // The new read: into a pool buffer's spare capacity.
    let pooled = |p: &BlobPool, i: usize| {
        let mut buf = p.take(BLOB_BYTES);
        let n = File::open(&paths[i])
            .and_then(|f| f.take(BLOB_BYTES as u64).read_to_end(buf.bytes_mut()))
            .expect("read");
        assert_eq!(n, BLOB_BYTES);
        buf.freeze()
    };
    let mut g = c.benchmark_group("disk_read");
    g.sample_size(10)
        .throughput(Throughput::Bytes(BURST_BYTES as u64));
    g.bench_function("zero_filled_arc", |b| {
        b.iter_custom(|n| timed(n, drop, || par_map(BLOBS, zero_filled)))
    });
    g.bench_function("pool_empty", |b| {
        let p = pool();
        p.set_bound(0);
        b.iter_custom(|n| timed(n, drop, || par_map(BLOBS, |i| pooled(&p, i))))
    });
    g.bench_function("pool_prefaulted", |b| {
        let p = pool();
        let lens = vec![BLOB_BYTES; BLOBS];
        let prepare = |last: Vec<Blob>| {
            p.set_bound(0);
            drop(last);
            p.set_bound(2 * BURST_BYTES as u64);
            p.prefault(&lens);
            p.wait_filled();
        };
        b.iter_custom(|n| timed(n, prepare, || par_map(BLOBS, |i| pooled(&p, i))))
    });
    g.finish();
}

criterion_group!(benches, store_copy, disk_read);
criterion_main!(benches);
