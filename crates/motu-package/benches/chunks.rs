//! Chunk read throughput (raw vs zstd, first touch vs verified, vs a plain `read` of the same
//! file) and `open()` time.
//!
//! `cargo bench -p motu-package --bench chunks` uses a 128 MiB mesh-like package in a temp
//! dir. Environment:
//! - `MOTU_BENCH_MIB=N`: size of the throughput packages (default 128).
//! - `MOTU_BENCH_LARGE_GIB=N`: also write an N GiB package (4 MiB chunks plus a 256 MiB
//!   section) and time `open()` on it. Opt-in: it writes N GiB to disk.
//! - `MOTU_BENCH_DIR=DIR`: where to write the packages (default: a temp dir, removed after).

use std::hint::black_box;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::time::Duration;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use motu_package::{ChunkId, Package, PackageWriter, SectionKind, WriterOptions};

const CHUNK_BYTES: usize = 4 << 20;

/// One 4 MiB chunk of mesh-like data: a displaced grid's f32 positions, then its u32
/// triangle indices (compresses about like real vertex/index buffers).
fn mesh_chunk(seed: u32) -> Vec<u8> {
    let side = 256u32;
    let mut bytes = Vec::with_capacity(CHUNK_BYTES);
    let mut vertex = 0u32;
    while bytes.len() < CHUNK_BYTES / 2 {
        let (x, y) = (vertex % side, vertex / side);
        let h = ((x * 7 + y * 13 + seed) % 97) as f32 * 0.01;
        for v in [x as f32 * 0.5, h, y as f32 * 0.5] {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        vertex += 1;
    }
    let mut quad = 0u32;
    while bytes.len() + 24 <= CHUNK_BYTES {
        let (x, y) = (quad % (side - 1), quad / (side - 1) % (side - 1));
        let i = y * side + x;
        for index in [i, i + 1, i + side, i + 1, i + side + 1, i + side] {
            bytes.extend_from_slice(&index.to_le_bytes());
        }
        quad += 1;
    }
    bytes.resize(CHUNK_BYTES, 0);
    bytes
}

fn write_package(path: &Path, chunks: usize, zstd_level: Option<i32>, section_bytes: usize) {
    let options = WriterOptions {
        target_chunk_bytes: CHUNK_BYTES as u64,
        zstd_level,
        direct_io: false,
    };
    let mut writer = PackageWriter::create(path, options).expect("create bench package");
    let stream = writer.open_stream(0, 0);
    for i in 0..chunks {
        writer
            .append(stream, &mesh_chunk(i as u32), 256)
            .expect("append");
    }
    if section_bytes > 0 {
        let nodes: Vec<u32> = (0..section_bytes as u32 / 4).collect();
        writer
            .add_section_slice(SectionKind(1), "nodes", &nodes)
            .expect("section");
    }
    let summary = writer.finish().expect("finish");
    eprintln!(
        "wrote {}: {} chunks, {} raw bytes, {} stored bytes",
        path.display(),
        summary.chunk_count,
        summary.chunk_raw_bytes,
        summary.chunk_stored_bytes
    );
}

fn env_usize(name: &str) -> Option<usize> {
    std::env::var(name).ok()?.parse().ok()
}

struct BenchDir {
    path: PathBuf,
    _temp: Option<tempfile::TempDir>,
}

fn bench_dir() -> BenchDir {
    match std::env::var_os("MOTU_BENCH_DIR") {
        Some(dir) => BenchDir {
            path: dir.into(),
            _temp: None,
        },
        None => {
            let temp = tempfile::tempdir().expect("temp dir");
            BenchDir {
                path: temp.path().to_path_buf(),
                _temp: Some(temp),
            }
        }
    }
}

/// Reads every chunk and copies it into a staging buffer, as an upload would.
fn read_all(package: &Package, staging: &mut [u8]) -> u64 {
    let mut total = 0;
    for id in 0..package.chunk_count() {
        let chunk = package.chunk(ChunkId(id)).expect("chunk");
        staging[..chunk.len()].copy_from_slice(&chunk);
        total += chunk.len() as u64;
    }
    total
}

fn chunk_throughput(c: &mut Criterion) {
    let dir = bench_dir();
    // `cargo test --all-targets` runs benches once without `--bench`: keep that run small.
    let benchmarking = std::env::args().any(|arg| arg == "--bench");
    let mib = env_usize("MOTU_BENCH_MIB").unwrap_or(if benchmarking { 128 } else { 8 });
    let chunks = (mib << 20) / CHUNK_BYTES;
    let raw_path = dir.path.join("bench-raw.motu");
    let zstd_path = dir.path.join("bench-zstd.motu");
    write_package(&raw_path, chunks, None, 0);
    write_package(&zstd_path, chunks, Some(3), 0);
    let raw_bytes = (chunks * CHUNK_BYTES) as u64;

    let mut group = c.benchmark_group("chunk_read");
    group
        .sample_size(10)
        .measurement_time(Duration::from_secs(8));
    group.throughput(Throughput::Bytes(raw_bytes));
    let mut staging = vec![0u8; CHUNK_BYTES];

    // Plain `read(2)` of the whole file in 1 MiB blocks: what `cat > /dev/null` does.
    group.bench_function("file_read_1MiB_blocks", |b| {
        let mut buf = vec![0u8; 1 << 20];
        b.iter(|| {
            let mut file = std::fs::File::open(&raw_path).expect("open");
            let mut total = 0;
            while let Ok(n @ 1..) = file.read(&mut buf) {
                total += n;
            }
            black_box(total)
        })
    });
    group.bench_function("raw_first_touch", |b| {
        b.iter(|| {
            let package = Package::open(&raw_path).expect("open");
            black_box(read_all(&package, &mut staging))
        })
    });
    let raw = Package::open(&raw_path).expect("open");
    group.bench_function("raw_verified", |b| {
        b.iter(|| black_box(read_all(&raw, &mut staging)))
    });
    let zstd = Package::open(&zstd_path).expect("open");
    group.bench_function("zstd_decompress", |b| {
        b.iter(|| {
            let mut total = 0;
            for id in 0..zstd.chunk_count() {
                total += zstd.chunk(ChunkId(id)).expect("chunk").len();
            }
            black_box(total)
        })
    });
    group.bench_function("zstd_into_staging", |b| {
        b.iter(|| {
            let mut total = 0;
            for id in 0..zstd.chunk_count() {
                total += zstd
                    .read_chunk_into(ChunkId(id), &mut staging)
                    .expect("chunk");
            }
            black_box(total)
        })
    });
    group.bench_function("verify_raw", |b| {
        b.iter(|| black_box(raw.verify().expect("verify")))
    });
    group.finish();

    let mut group = c.benchmark_group("open");
    group.bench_function(format!("{mib}MiB"), |b| {
        b.iter(|| black_box(Package::open(&raw_path).expect("open").chunk_count()))
    });
    if let Some(gib) = env_usize("MOTU_BENCH_LARGE_GIB") {
        let large_path = dir.path.join("bench-large.motu");
        let chunks = (gib << 30) / CHUNK_BYTES;
        if !large_path.exists() {
            write_package(&large_path, chunks, None, 256 << 20);
        }
        let package = Package::open(&large_path).expect("open large");
        eprintln!(
            "large package: {} bytes, {} chunks",
            package.file_bytes(),
            package.chunk_count()
        );
        drop(package);
        group.bench_function(format!("{gib}GiB"), |b| {
            b.iter(|| black_box(Package::open(&large_path).expect("open").chunk_count()))
        });
    }
    group.finish();
}

criterion_group!(benches, chunk_throughput);
criterion_main!(benches);
