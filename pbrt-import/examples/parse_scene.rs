//! Whole-scene parse time (includes followed, PLY files loaded) on a pool of N threads, with
//! `parallel_includes` on and off; the sink drops everything.
//!
//! `cargo run --release -p pbrt-import --example parse_scene -- SCENE.pbrt THREADS [REPEATS] [MODE]`
//!
//! MODE is `both` (the default), `seq` (`parallel_includes` off) or `par` (on): one mode per
//! process lets `/usr/bin/time` attribute CPU time to it.

use std::path::Path;
use std::time::Instant;

use pbrt_import::{parse_file, Geometry, ParseOptions, SceneSink, ShapeEvent, SinkError};

/// Drops everything but counts triangles and instances.
#[derive(Default)]
struct Null(u64, u64);

impl SceneSink for Null {
    fn shape(&mut self, s: ShapeEvent) -> Result<(), SinkError> {
        if let Geometry::Mesh(m) = &s.geometry {
            self.0 += m.triangle_count() as u64;
        }
        Ok(())
    }
    fn object_instance(&mut self, _e: &pbrt_import::InstanceEvent<'_>) -> Result<(), SinkError> {
        self.1 += 1;
        Ok(())
    }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let usage = "usage: parse_scene SCENE THREADS [REPEATS] [both|seq|par]";
    let path = args.next().ok_or(usage)?;
    let threads: usize = args.next().ok_or(usage)?.parse()?;
    let repeats: u32 = args.next().map(|s| s.parse()).transpose()?.unwrap_or(3);
    let modes: &[bool] = match args.next().as_deref() {
        None | Some("both") => &[false, true],
        Some("seq") => &[false],
        Some("par") => &[true],
        Some(_) => return Err(usage.into()),
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads.max(1))
        .build()?;
    for &parallel in modes {
        let opts = ParseOptions {
            parallel_includes: parallel,
            allow_missing: true,
            ..ParseOptions::default()
        };
        for _ in 0..repeats {
            let start = Instant::now();
            let mut sink = Null::default();
            let stats = pool.install(|| parse_file(Path::new(&path), &opts, &mut sink))?;
            let secs = start.elapsed().as_secs_f64();
            println!(
                "threads {threads} parallel_includes {parallel}: {:.0} ms, {:.0} MB/s, \
                 {} files ({} parallel), {} triangles, {} instances",
                secs * 1e3,
                stats.text_bytes as f64 / secs / 1e6,
                stats.files.len(),
                stats.parallel_files,
                sink.0,
                sink.1
            );
        }
    }
    Ok(())
}
