//! A small CLI over `motu_gen::generate`, for measurements without the full
//! `motu` binary:
//!
//! ```text
//! cargo run --release -p motu-gen --example gen -- island -o /tmp/island --scale 0.15
//! ```
//!
//! Options: `--levels N --grid WxH --leaves N --depth N --scale S --seed N
//! --flat --elements N --threads N --triangles N --width W --height H`.

use std::path::PathBuf;
use std::time::Instant;

use motu_gen::{
    generate, ForestOptions, GenKind, GridSize, IslandOptions, LodGridOptions, SphereflakeOptions,
};

fn main() {
    if let Err(e) = run() {
        eprintln!("error: {e}");
        std::process::exit(2);
    }
}

fn run() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let kind_name = args
        .first()
        .ok_or("usage: gen KIND -o DIR [options]")?
        .clone();
    let mut out: Option<PathBuf> = None;
    let mut forest = ForestOptions::default();
    let mut flake = SphereflakeOptions::default();
    let mut grid = LodGridOptions::default();
    let mut island = IslandOptions::default();
    let mut i = 1;
    while i < args.len() {
        let flag = args[i].as_str();
        if flag == "--flat" {
            forest.flat = true;
            flake.flat = true;
            i += 1;
            continue;
        }
        let value = args.get(i + 1).ok_or(format!("{flag} needs a value"))?;
        let num = |v: &str| v.parse::<u64>().map_err(|e| format!("{flag}: {e}"));
        let small = |v: &str| v.parse::<u32>().map_err(|e| format!("{flag}: {e}"));
        match flag {
            "-o" | "--output" => out = Some(PathBuf::from(value)),
            "--levels" => forest.levels = small(value)?,
            "--grid" => {
                let g: GridSize = value.parse().map_err(|e| format!("{e}"))?;
                forest.grid = g;
                grid.grid = g;
            }
            "--leaves" => forest.leaves = small(value)?,
            "--depth" => flake.depth = small(value)?,
            "--scale" => island.scale = value.parse().map_err(|e| format!("--scale: {e}"))?,
            "--elements" => island.elements = Some(small(value)?),
            "--threads" => island.threads = Some(num(value)? as usize),
            "--triangles" => grid.triangles = small(value)?,
            "--seed" => {
                let s = num(value)?;
                (forest.seed, flake.seed, grid.seed, island.seed) = (s, s, s, s);
            }
            "--width" => {
                let w = small(value)?;
                (forest.width, flake.width, grid.width, island.width) = (w, w, w, w);
            }
            "--height" => {
                let h = small(value)?;
                (forest.height, flake.height, grid.height, island.height) = (h, h, h, h);
            }
            other => return Err(format!("unknown option {other}")),
        }
        i += 2;
    }
    let kind = match kind_name.as_str() {
        "forest" => GenKind::Forest(forest),
        "sphereflake" => GenKind::Sphereflake(flake),
        "lod-grid" => GenKind::LodGrid(grid),
        "island" => GenKind::Island(island),
        other => return Err(format!("unknown kind {other}")),
    };
    let out = out.ok_or("-o DIR is required")?;
    let start = Instant::now();
    let mut last_report = Instant::now();
    let summary = generate(&kind, &out, &mut |p| {
        if last_report.elapsed().as_secs() >= 5 {
            last_report = Instant::now();
            eprintln!(
                "  {}/{} files, {:.2} GB",
                p.files_written,
                p.files_total,
                p.bytes_written as f64 / 1e9
            );
        }
    })
    .map_err(|e| e.to_string())?;
    let secs = start.elapsed().as_secs_f64();
    println!("{summary:#?}");
    println!(
        "{:.2} s, {:.1} MB/s, {:.3} GB",
        secs,
        summary.bytes_written as f64 / 1e6 / secs,
        summary.bytes_written as f64 / 1e9
    );
    Ok(())
}
