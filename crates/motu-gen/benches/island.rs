//! Island generation throughput (bytes of pbrt + PLY written per second).
//! Run: `cargo bench -p motu-gen --bench island`.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use motu_gen::{generate, GenKind, IslandOptions};

fn island(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("tempdir");
    let kind = GenKind::Island(IslandOptions {
        scale: 0.002,
        ..IslandOptions::default()
    });
    let bytes = generate(&kind, dir.path(), &mut |_| {})
        .expect("generate")
        .bytes_written;
    let mut group = c.benchmark_group("island");
    group.sample_size(10);
    group.throughput(Throughput::Bytes(bytes));
    group.bench_function("scale_0.002", |b| {
        b.iter(|| generate(&kind, dir.path(), &mut |_| {}).expect("generate"))
    });
    group.finish();
}

criterion_group!(benches, island);
criterion_main!(benches);
