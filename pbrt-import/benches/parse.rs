//! Tokenizer and full-parse throughput (single thread).
//!
//! `cargo bench -p pbrt-import -- --quick`
//! Inputs: buddha-fractal's `geometry.pbrt` (instance-heavy, when present) and a
//! generated inline `trianglemesh` (Moana-v3-like huge arrays).
//!
//! Large generated files (the documented island measurement):
//! `cargo run --release -p motu-gen --example gen -- island -o /tmp/isl --scale 0.01`, then
//! `cargo run --release -p pbrt-import --example parse_throughput -- /tmp/isl/isIronwoodA1/isIronwoodA1_xgLeaves.pbrt`.

use std::hint::black_box;
use std::path::{Path, PathBuf};

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use pbrt_import::lexer::Lexer;
use pbrt_import::{
    parse_bytes, FileId, Geometry, Mesh, ParseOptions, PlyLoading, SceneSink, ShapeEvent, SinkError,
};

/// Drops everything but counts triangles, like a sink that streams to disk.
#[derive(Default)]
struct Null(u64);

impl SceneSink for Null {
    fn shape(&mut self, s: ShapeEvent) -> Result<(), SinkError> {
        if let Geometry::Mesh(m) = &s.geometry {
            self.0 += m.triangle_count() as u64;
        }
        Ok(())
    }
}

fn generated_mesh_text(grid: u32) -> String {
    let mut mesh = Mesh::default();
    for j in 0..=grid {
        for i in 0..=grid {
            let (x, y) = (i as f32 * 0.013_771, j as f32 * 0.027_113);
            mesh.positions.push([x, y, (x * 3.1).sin() * 12.345_67]);
        }
    }
    let w = grid + 1;
    for j in 0..grid {
        for i in 0..grid {
            let a = j * w + i;
            mesh.indices
                .extend_from_slice(&[a, a + 1, a + w + 1, a, a + w + 1, a + w]);
        }
    }
    mesh.normals = Some(vec![[0.0, 0.0, 1.0]; mesh.positions.len()]);
    let mut w = pbrt_import::writer::Writer::new();
    w.world_begin();
    w.triangle_mesh(&mesh);
    w.finish()
}

fn inputs() -> Vec<(String, Vec<u8>, PathBuf)> {
    let mut v = Vec::new();
    let buddha = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/scenes/buddha-fractal");
    if let Ok(bytes) = std::fs::read(buddha.join("geometry.pbrt")) {
        let mut text = b"WorldBegin\n".to_vec();
        text.extend_from_slice(&bytes);
        v.push(("buddha-geometry".to_owned(), text, buddha));
    } else {
        eprintln!("buddha-fractal not present; benchmarking the generated mesh only");
    }
    v.push((
        "inline-trianglemesh".to_owned(),
        generated_mesh_text(700).into_bytes(),
        PathBuf::from("."),
    ));
    v
}

fn bench(c: &mut Criterion) {
    let opts = ParseOptions {
        ply_loading: PlyLoading::Sequential,
        ..Default::default()
    };
    for (name, bytes, dir) in inputs() {
        let mut g = c.benchmark_group(name);
        g.throughput(Throughput::Bytes(bytes.len() as u64));
        g.sample_size(10);
        g.bench_function("tokenize", |b| {
            b.iter(|| {
                Lexer::new(black_box(&bytes), FileId(0))
                    .count_tokens()
                    .unwrap_or(0)
            })
        });
        g.bench_function("parse", |b| {
            b.iter(|| {
                let mut sink = Null::default();
                let r = parse_bytes(black_box(&bytes), &dir, &opts, &mut sink);
                assert!(r.is_ok(), "{r:?}");
                sink.0
            })
        });
        g.finish();
    }
}

fn bench_ply(c: &mut Criterion) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../shared/scenes/buddha-fractal/geometry/buddha.ply");
    let Ok(bytes) = std::fs::read(&path) else {
        return;
    };
    let mut g = c.benchmark_group("ply-buddha");
    g.throughput(Throughput::Bytes(bytes.len() as u64));
    g.sample_size(10);
    g.bench_function("read", |b| {
        b.iter(|| pbrt_import::ply::parse_ply(black_box(&bytes)).map(|m| m.indices.len()))
    });
    g.finish();
}

criterion_group!(benches, bench, bench_ply);
criterion_main!(benches);
