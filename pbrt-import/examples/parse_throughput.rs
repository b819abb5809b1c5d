//! Single-thread full-parse throughput of one pbrt file (the documented benchmark
//! command for large generated files; criterion covers the fixed inputs).
//!
//! `cargo run --release -p pbrt-import --example parse_throughput -- FILE [REPEATS]`
//!
//! `plymesh` files load sequentially (counted in the time) and missing ones are skipped:
//! use files with inline geometry or instances to measure the text path.

use std::path::Path;
use std::time::Instant;

use pbrt_import::lexer::{Lexer, TokenKind};
use pbrt_import::{
    parse_bytes, FileId, Geometry, ParseOptions, PlyLoading, SceneSink, ShapeEvent, SinkError,
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

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let path = args
        .next()
        .ok_or("usage: parse_throughput FILE [REPEATS]")?;
    let repeats: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(5);
    let path = Path::new(&path);
    let mut bytes = std::fs::read(path)?;
    if !bytes.windows(10).any(|w| w == b"WorldBegin") {
        // Element files are included from inside the world block, after the objects
        // they instance are defined: define those (empty) first, outside the timing.
        let mut text = b"WorldBegin\n".to_vec();
        if !bytes.windows(11).any(|w| w == b"ObjectBegin") {
            let mut names = std::collections::BTreeSet::new();
            let mut lx = Lexer::new(&bytes, FileId(0));
            let mut after_instance = false;
            while let Ok(Some(t)) = lx.next_token() {
                if after_instance && t.kind == TokenKind::String {
                    names.insert(t.bytes.to_vec());
                }
                after_instance = t.kind == TokenKind::Word && t.bytes == b"ObjectInstance";
            }
            for n in names {
                text.extend_from_slice(b"ObjectBegin \"");
                text.extend_from_slice(&n);
                text.extend_from_slice(b"\" ObjectEnd\n");
            }
        }
        text.append(&mut bytes);
        bytes = text;
    }
    let dir = path.parent().unwrap_or(Path::new("."));
    let opts = ParseOptions {
        ply_loading: PlyLoading::Sequential,
        allow_missing: true,
        ..Default::default()
    };
    let mut best = f64::MAX;
    for _ in 0..repeats.max(1) {
        let mut sink = Null::default();
        let t = Instant::now();
        let stats = parse_bytes(&bytes, dir, &opts, &mut sink)?;
        let s = t.elapsed().as_secs_f64();
        best = best.min(s);
        eprintln!(
            "{:.1} ms, {} shapes, {} instances, {} triangles",
            s * 1e3,
            stats.shapes,
            stats.instances,
            sink.0
        );
    }
    let mb = bytes.len() as f64 / 1e6;
    println!(
        "{}: {mb:.1} MB, best {:.1} ms = {:.0} MB/s",
        path.display(),
        best * 1e3,
        mb / best
    );
    Ok(())
}
