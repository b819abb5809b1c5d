//! What a suite measures: options, settings, backends and the scenes with their configurations.

use crate::error::BenchError;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// The TLAS instance limit of the Vulkan spec (`maxInstanceCount` is at least 2^24 − 1).
const SPEC_MAX_INSTANCES: u64 = (1 << 24) - 1;
/// `--levels`/`--max-instances` the quick island uses so that `sl` still needs TLAS splits.
const QUICK_ISLAND_MAX_INSTANCES: u32 = 1500;
/// Island scale with a flattened instance count just over 2^24 (≈ 28M × scale − plant rounding
/// ≈ 17.4M; the run warns if it is not over).
const GPU_ISLAND_SCALE: f64 = 0.63;

/// A render backend (the CLI's `--backend`) and the best one of the devices there are.
pub use motu_render::{best_backend, Backend};

/// A suite run: `motu bench`'s flags (see CLI.md for each).
#[derive(Clone, Debug, Default)]
pub struct SuiteOptions {
    pub suite: String,
    pub work_dir: Option<PathBuf>,
    pub quick: bool,
    pub markdown: Option<PathBuf>,
    pub only: Vec<String>,
    pub frames: Option<u32>,
    pub warmup: Option<u32>,
    pub width: Option<u32>,
    pub height: Option<u32>,
    pub backend: Option<Backend>,
    pub island_scale: Option<f64>,
    pub scenes: Option<PathBuf>,
    pub configs: Vec<String>,
    pub deadline_s: Option<u64>,
    pub step_timeout_s: Option<u64>,
    pub keep: bool,
    /// One line per step on stderr (the CLI also turns it on when stderr is a terminal).
    pub progress: bool,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum SuiteKind {
    Gpu,
    Cpu,
}

/// What a suite measures and at which size.
#[derive(Clone, Debug, Serialize)]
pub struct Settings {
    pub suite: String,
    pub kind: SuiteKind,
    pub quick: bool,
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    pub warmup_frames: u32,
    pub backend: &'static str,
    pub island_scale: f64,
    pub step_timeout_s: u64,
    pub keep_packages: bool,
}

#[derive(Clone, Debug, Serialize)]
#[serde(tag = "kind", rename_all = "lowercase")]
pub enum Source {
    /// `motu gen <args> -o DIR`.
    Gen { args: Vec<String> },
    /// A scene file from `shared/scenes`.
    Shared { path: PathBuf },
}

#[derive(Clone, Debug, Serialize)]
pub struct ConfigSpec {
    pub label: String,
    /// Extra `motu import` arguments.
    pub import_args: Vec<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct SceneSpec {
    pub name: &'static str,
    pub source: Source,
    pub configs: Vec<ConfigSpec>,
    /// Flattened instances must exceed this for the scene to mean what it should (the island).
    pub must_exceed_instances: Option<u64>,
    pub note: String,
}

fn config(label: &str, import_args: &[&str]) -> ConfigSpec {
    ConfigSpec {
        label: label.to_string(),
        import_args: import_args.iter().map(|s| s.to_string()).collect(),
    }
}

/// One configuration per `--levels` label (`levels2` is `--levels 2`), each with `extra`
/// import arguments after the level.
fn by_levels(labels: &[&str], extra: &[&str]) -> Vec<ConfigSpec> {
    labels
        .iter()
        .map(|&label| {
            let level = if label == "levels2" { "2" } else { label };
            let mut args = vec!["--levels", level];
            args.extend_from_slice(extra);
            config(label, &args)
        })
        .collect()
}

fn gen_source(args: &[&str]) -> Source {
    Source::Gen {
        args: args.iter().map(|s| s.to_string()).collect(),
    }
}

pub(crate) fn settings(a: &SuiteOptions) -> Result<Settings, BenchError> {
    let (kind, quick) = match a.suite.as_str() {
        "gpu" => (SuiteKind::Gpu, a.quick),
        "quick" => (SuiteKind::Gpu, true),
        "cpu" => (SuiteKind::Cpu, a.quick),
        other => bail!("unknown suite '{other}': the suites are gpu, quick and cpu"),
    };
    let (w, h, frames, warmup, timeout) = match (kind, quick) {
        (SuiteKind::Gpu, false) => (1920, 1080, 21, 2, 1200),
        (SuiteKind::Gpu, true) => (320, 180, 5, 1, 300),
        (SuiteKind::Cpu, false) => (640, 360, 5, 1, 1200),
        (SuiteKind::Cpu, true) => (160, 90, 3, 1, 300),
    };
    let backend = match (a.backend, kind) {
        (Some(b), _) => b.name(),
        (None, SuiteKind::Cpu) => "cpu",
        (None, SuiteKind::Gpu) => match motu_gpu::list_devices() {
            Ok(d) => best_backend(&d).name(),
            Err(_) => "cpu",
        },
    };
    if kind == SuiteKind::Gpu && backend == "cpu" && a.backend.is_none() {
        eprintln!("warning: no Vulkan ray-tracing device; the GPU suite renders with the CPU backend (these are not GPU numbers)");
    }
    let frames = a.frames.unwrap_or(frames);
    if frames == 0 {
        bail!("--frames must be at least 1");
    }
    let width = a.width.unwrap_or(w);
    let height = a.height.unwrap_or(h);
    if width == 0 || height == 0 || width > 16384 || height > 16384 {
        bail!("image size {width}×{height} is out of range (1–16384 per side)");
    }
    let island_scale = a.island_scale.unwrap_or(match (kind, quick) {
        (_, true) => 0.0003,
        (SuiteKind::Gpu, false) => GPU_ISLAND_SCALE,
        (SuiteKind::Cpu, false) => 0.02,
    });
    if !(island_scale > 0.0 && island_scale <= 4.0) {
        bail!("--island-scale {island_scale} is out of range (0, 4]");
    }
    Ok(Settings {
        suite: a.suite.clone(),
        kind,
        quick,
        width,
        height,
        frames,
        warmup_frames: a.warmup.unwrap_or(warmup),
        backend,
        island_scale,
        step_timeout_s: a.step_timeout_s.unwrap_or(timeout).max(1),
        keep_packages: a.keep,
    })
}

/// `shared/scenes` beside or above the working directory or the binary.
fn find_shared_scenes(explicit: Option<&Path>) -> Option<PathBuf> {
    if let Some(p) = explicit {
        return Some(p.to_path_buf());
    }
    let mut roots: Vec<PathBuf> = Vec::new();
    if let Ok(cwd) = std::env::current_dir() {
        roots.extend(cwd.ancestors().take(3).map(Path::to_path_buf));
    }
    if let Ok(exe) = std::env::current_exe() {
        roots.extend(exe.ancestors().skip(1).take(5).map(Path::to_path_buf));
    }
    roots
        .into_iter()
        .map(|r| r.join("shared/scenes"))
        .find(|p| p.join("buddha-fractal").is_dir())
}

/// The suite's scenes and configurations.
pub(crate) fn plan(s: &Settings, a: &SuiteOptions) -> Result<Vec<SceneSpec>, BenchError> {
    let q = s.quick;
    let std_configs = || by_levels(&["sl", "ml", "levels2", "auto"], &[]);
    let mut scenes = vec![
        SceneSpec {
            name: "forest",
            source: gen_source(if q {
                &["forest", "--levels", "3", "--grid", "2x2", "--leaves", "40"]
            } else {
                // The thesis layout: (4·3)^3 = 1728 trees of 8,732 leaves ≈ 15.1M leaf instances.
                &[
                    "forest", "--levels", "3", "--grid", "4x3", "--leaves", "8732",
                ]
            }),
            configs: std_configs(),
            must_exceed_instances: None,
            note: "thesis 3-level forest (SL-Max vs ML-SL-EQ)".into(),
        },
        SceneSpec {
            name: "sphereflake",
            source: gen_source(&["sphereflake", "--depth", if q { "2" } else { "4" }]),
            configs: std_configs(),
            must_exceed_instances: None,
            note: String::new(),
        },
        SceneSpec {
            name: "lod-grid",
            source: gen_source(if q {
                &["lod-grid", "--grid", "4x8", "--triangles", "110000"]
            } else {
                &["lod-grid"]
            }),
            configs: vec![
                config("sl", &["--levels", "sl"]),
                config("ml", &["--levels", "ml"]),
                config("sl+lod", &["--levels", "sl", "--lod", "4"]),
                config("ml+lod", &["--levels", "ml", "--lod", "4"]),
            ],
            must_exceed_instances: None,
            note: "with and without `--lod 4` (LOD applies to meshes over 100k triangles)".into(),
        },
    ];
    // The island is last: it is the longest, and a deadline should cut it rather than the rest.
    match find_shared_scenes(a.scenes.as_deref()) {
        Some(dir) => scenes.push(SceneSpec {
            name: "buddha-fractal",
            source: Source::Shared {
                path: dir.join("buddha-fractal/buddha-fractal.pbrt"),
            },
            configs: by_levels(&["sl", "ml"], &[]),
            must_exceed_instances: None,
            note: "pbrt-v3-scenes, 25,250 instances of one plymesh".into(),
        }),
        None => {
            if a.only.iter().any(|o| o == "buddha-fractal") {
                bail!("buddha-fractal was asked for but shared/scenes was not found: pass --scenes DIR");
            }
        }
    }
    let scale = format!("{}", s.island_scale);
    // Single-level pbrt: `--levels 2` keeps the same two levels as `ml`, so it is not repeated.
    let island_configs = if q {
        // Tiny islands cannot overflow 2^24: a low --max-instances exercises the same TLAS splits.
        let m = QUICK_ISLAND_MAX_INSTANCES.to_string();
        by_levels(&["sl", "ml"], &["--max-instances", &m])
    } else {
        by_levels(&["sl", "ml"], &[])
    };
    scenes.push(SceneSpec {
        name: "island",
        source: Source::Gen {
            args: vec!["island".into(), "--scale".into(), scale],
        },
        configs: island_configs,
        must_exceed_instances: (s.kind == SuiteKind::Gpu && !q).then_some(SPEC_MAX_INSTANCES),
        note: if q {
            format!("single-level pbrt; --max-instances {QUICK_ISLAND_MAX_INSTANCES} forces TLAS splits")
        } else {
            "single-level pbrt (levels2 = ml); flattened instances > 2^24 force TLAS splits".into()
        },
    });
    if !a.only.is_empty() {
        let known: Vec<&str> = scenes.iter().map(|s| s.name).collect();
        for o in &a.only {
            if !known.contains(&o.as_str()) {
                bail!(
                    "--only {o}: unknown scene; the suite has {}",
                    known.join(", ")
                );
            }
        }
        scenes.retain(|s| a.only.iter().any(|o| o == s.name));
    }
    if !a.configs.is_empty() {
        for sc in &mut scenes {
            sc.configs.retain(|c| a.configs.contains(&c.label));
        }
        scenes.retain(|sc| !sc.configs.is_empty());
        if scenes.is_empty() {
            bail!("--configs {}: no scene has such a configuration (labels: sl, ml, levels2, auto, sl+lod, ml+lod)", a.configs.join(","));
        }
    }
    Ok(scenes)
}
