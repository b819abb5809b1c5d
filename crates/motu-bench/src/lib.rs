//! `motu bench`: repeatable measurements of the whole pipeline, one process per step.
//!
//! Every step (gen, import, render) runs in a child process of this executable, so import peak
//! RSS is the importer's own, a driver crash or out-of-memory in one configuration is recorded
//! as that configuration's failure instead of ending the suite, and a step can be killed after
//! `--step-timeout-s`. Renders go through a hidden `motu bench --child-render PKG` mode that
//! submits the warm-up frames separately from the timed ones, so the median (GPU timestamps)
//! covers only warm frames. Ratios compare each configuration with the `sl` configuration of
//! the same scene measured in the same run.
//!
//! The `motu` CLI parses the flags into [`SuiteOptions`] (or a [`ChildRender`] for the hidden
//! child mode) and prints what [`run_suite`] returns ([`text_table`] or the JSON of
//! [`BenchReport`]); the children are spawned from `std::env::current_exe()`, i.e. `motu` itself.

use motu_abi::camera::CameraParams;
use motu_abi::HierarchyView;
use motu_import::peak_rss_bytes;
use motu_report::format_size;
use serde::Serialize;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// The TLAS instance limit of the Vulkan spec (`maxInstanceCount` is at least 2^24 − 1).
const SPEC_MAX_INSTANCES: u64 = (1 << 24) - 1;
/// `--levels`/`--max-instances` the quick island uses so that `sl` still needs TLAS splits.
const QUICK_ISLAND_MAX_INSTANCES: u32 = 1500;
/// Island scale with a flattened instance count just over 2^24 (≈ 28M × scale − plant rounding
/// ≈ 17.4M; the run warns if it is not over).
const GPU_ISLAND_SCALE: f64 = 0.63;
const MIB: f64 = 1024.0 * 1024.0;

/// What went wrong in a benchmark run (a failing step is a recorded result, not an error).
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// Bad options; the text names the option and the value.
    #[error("{0}")]
    Options(String),
    #[error("{what}")]
    Io {
        what: String,
        #[source]
        source: std::io::Error,
    },
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    #[error("{what}")]
    Gpu {
        what: &'static str,
        #[source]
        source: motu_gpu::GpuError,
    },
    #[error("{what}")]
    Trace {
        what: &'static str,
        #[source]
        source: motu_trace::TraceError,
    },
    #[error(transparent)]
    TraceFrame(motu_trace::TraceError),
    #[error("{what}")]
    PngWrite {
        what: String,
        #[source]
        source: motu_trace::TraceError,
    },
    #[error("every configuration failed (first: {first}); logs in {}", logs.display())]
    EveryConfigurationFailed { first: String, logs: PathBuf },
}

macro_rules! bail {
    ($($t:tt)*) => {
        return Err(BenchError::Options(format!($($t)*)))
    };
}

fn io(what: String) -> impl FnOnce(std::io::Error) -> BenchError {
    move |source| BenchError::Io { what, source }
}

/// A render backend (the CLI's `--backend`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Pipeline,
    Query,
    Cpu,
}

/// `query` where a device has ray queries (usually fastest on RTX), else `pipeline`, else the CPU.
pub fn best_backend(devices: &[motu_gpu::DeviceReport]) -> Backend {
    if devices.iter().any(|d| d.ray_query) {
        Backend::Query
    } else if devices.iter().any(|d| d.ray_pipeline) {
        Backend::Pipeline
    } else {
        Backend::Cpu
    }
}

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

fn gen_source(args: &[&str]) -> Source {
    Source::Gen {
        args: args.iter().map(|s| s.to_string()).collect(),
    }
}

fn settings(a: &SuiteOptions) -> Result<Settings, BenchError> {
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
        (Some(b), _) => backend_name(b),
        (None, SuiteKind::Cpu) => "cpu",
        (None, SuiteKind::Gpu) => match motu_gpu::list_devices() {
            Ok(d) => backend_name(best_backend(&d)),
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

fn backend_name(b: Backend) -> &'static str {
    match b {
        Backend::Pipeline => "pipeline",
        Backend::Query => "query",
        Backend::Cpu => "cpu",
    }
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
fn plan(s: &Settings, a: &SuiteOptions) -> Result<Vec<SceneSpec>, BenchError> {
    let q = s.quick;
    let std_configs = || {
        vec![
            config("sl", &["--levels", "sl"]),
            config("ml", &["--levels", "ml"]),
            config("levels2", &["--levels", "2"]),
            config("auto", &["--levels", "auto"]),
        ]
    };
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
            configs: vec![
                config("sl", &["--levels", "sl"]),
                config("ml", &["--levels", "ml"]),
            ],
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
        vec![
            ConfigSpec {
                label: "sl".into(),
                import_args: vec![
                    "--levels".into(),
                    "sl".into(),
                    "--max-instances".into(),
                    m.clone(),
                ],
            },
            ConfigSpec {
                label: "ml".into(),
                import_args: vec!["--levels".into(), "ml".into(), "--max-instances".into(), m],
            },
        ]
    } else {
        vec![
            config("sl", &["--levels", "sl"]),
            config("ml", &["--levels", "ml"]),
        ]
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

// ------------------------------------------------------------------------------ child steps

/// How one child process ended.
#[derive(Debug)]
struct StepRun {
    wall_s: f64,
    stdout: String,
    /// `None` on success; else what went wrong (the child's error paragraph, a signal, a timeout).
    error: Option<String>,
}

/// Runs this executable with `args`, logging its output under `log_dir/<tag>.{out,err}`.
fn run_step(args: &[String], log_dir: &Path, tag: &str, timeout: Duration) -> StepRun {
    let t0 = Instant::now();
    let fail = |e: String| StepRun {
        wall_s: t0.elapsed().as_secs_f64(),
        stdout: String::new(),
        error: Some(e),
    };
    let exe = match std::env::current_exe() {
        Ok(e) => e,
        Err(e) => return fail(format!("cannot find the motu executable: {e}")),
    };
    let out_path = log_dir.join(format!("{tag}.out"));
    let err_path = log_dir.join(format!("{tag}.err"));
    let (out_file, err_file) = match (
        std::fs::File::create(&out_path),
        std::fs::File::create(&err_path),
    ) {
        (Ok(o), Ok(e)) => (o, e),
        (Err(e), _) | (_, Err(e)) => {
            return fail(format!("cannot create logs in {}: {e}", log_dir.display()))
        }
    };
    let mut child = match Command::new(&exe)
        .args(args)
        .stdin(Stdio::null())
        .stdout(out_file)
        .stderr(err_file)
        .spawn()
    {
        Ok(c) => c,
        Err(e) => return fail(format!("cannot start {}: {e}", exe.display())),
    };
    let mut timed_out = false;
    let status = loop {
        match child.try_wait() {
            Ok(Some(st)) => break Some(st),
            Ok(None) if t0.elapsed() > timeout => {
                timed_out = true;
                // Killing our own child by its handle; a failure means it already exited.
                let _ = child.kill();
                break child.wait().ok();
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return fail(format!("waiting for the child process: {e}")),
        }
    };
    let wall_s = t0.elapsed().as_secs_f64();
    let stdout = std::fs::read_to_string(&out_path).unwrap_or_default();
    let stderr = std::fs::read_to_string(&err_path).unwrap_or_default();
    let error = if timed_out {
        Some(format!(
            "timed out after {} s (--step-timeout-s); log: {}",
            timeout.as_secs(),
            err_path.display()
        ))
    } else {
        match status {
            Some(st) if st.success() => None,
            Some(st) => Some(child_error(&stderr, st, &err_path)),
            None => Some("the child process vanished".into()),
        }
    };
    StepRun {
        wall_s,
        stdout,
        error,
    }
}

/// The child's own error paragraph, else how it ended.
fn child_error(stderr: &str, status: std::process::ExitStatus, log: &Path) -> String {
    use std::os::unix::process::ExitStatusExt;
    let line = stderr
        .lines()
        .rev()
        .find(|l| l.starts_with("error"))
        .or_else(|| stderr.lines().rev().find(|l| !l.trim().is_empty()))
        .unwrap_or("")
        .trim();
    let how = match (status.code(), status.signal()) {
        (Some(c), _) => format!("exit status {c}"),
        (None, Some(9)) => "killed (signal 9: out of memory?)".to_string(),
        (None, Some(s)) => format!("killed by signal {s}"),
        (None, None) => "ended abnormally".to_string(),
    };
    let mut msg = if line.is_empty() {
        how
    } else {
        format!("{line} ({how})")
    };
    if msg.len() > 600 {
        let mut cut = 600;
        while !msg.is_char_boundary(cut) {
            cut -= 1;
        }
        msg.truncate(cut);
        msg.push('…');
    }
    format!("{msg}; log: {}", log.display())
}

fn parse_json(stdout: &str) -> Result<Value, String> {
    serde_json::from_str(stdout.trim()).map_err(|e| format!("the child printed no JSON ({e})"))
}

// ------------------------------------------------------------------------------ results

#[derive(Clone, Debug, Default, Serialize)]
pub struct ImportMetrics {
    pub wall_s: f64,
    pub parse_ms: f64,
    pub compile_ms: f64,
    pub pack_ms: f64,
    pub peak_rss_bytes: u64,
    pub file_bytes: u64,
    pub instances: u64,
    pub flattened_instances: u64,
    pub tlas_count: u64,
    pub blas_count: u64,
}

/// What the render child measures (written as JSON by `--child-render`).
#[derive(Clone, Debug, Default, Serialize, serde::Deserialize)]
pub struct RenderMetrics {
    pub backend: String,
    pub device: String,
    pub width: u32,
    pub height: u32,
    pub warmup_frames: u32,
    pub frames: u32,
    /// Median of the timed frames (GPU timestamps; wall clock on the CPU backend).
    pub ms_per_frame: f64,
    pub fps: f64,
    pub rays: u64,
    pub rays_per_second: f64,
    pub traces_per_ray: f64,
    pub stack_overflows: u64,
    /// Acceleration-structure bytes resident while rendering (after compaction).
    pub as_bytes: u64,
    pub blas_bytes: u64,
    pub blas_compacted_bytes: u64,
    pub tlas_bytes: u64,
    pub tlas_compacted_bytes: u64,
    pub geometry_bytes: u64,
    pub scratch_peak_bytes: u64,
    /// AS build (GPU) or BVH preparation (CPU) time.
    pub as_build_ms: f64,
    pub vram_peak_bytes: u64,
    pub allocation_count: u32,
    /// Package open → stats written, in the child.
    pub wall_s: f64,
    pub peak_rss_bytes: u64,
}

#[derive(Clone, Debug, Default, Serialize)]
pub struct Ratios {
    /// rays/s of this configuration ÷ rays/s of `sl`.
    pub rays_per_second_vs_sl: Option<f64>,
    /// AS bytes of `sl` ÷ AS bytes of this configuration.
    pub as_bytes_sl_over_this: Option<f64>,
    /// Import peak RSS of this configuration ÷ that of `sl`.
    pub import_peak_rss_vs_sl: Option<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct ConfigResult {
    pub label: String,
    pub import_args: Vec<String>,
    /// `ok`, or `failed` with `error` saying which step and why.
    pub status: &'static str,
    pub error: Option<String>,
    pub import: Option<ImportMetrics>,
    pub render: Option<RenderMetrics>,
    pub ratios: Ratios,
}

#[derive(Clone, Debug, Serialize)]
pub struct SceneResult {
    pub name: &'static str,
    pub source: Source,
    pub note: String,
    pub scene_path: Option<PathBuf>,
    pub gen_s: Option<f64>,
    pub gen_cached: bool,
    /// `motu gen --json` output (absent for shared scenes).
    pub gen: Option<Value>,
    pub error: Option<String>,
    pub warnings: Vec<String>,
    pub configs: Vec<ConfigResult>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Machine {
    pub hostname: String,
    pub os: String,
    pub cpu: String,
    pub cpu_cores: usize,
    pub memory_bytes: u64,
    pub device: Option<String>,
    pub driver: Option<String>,
    pub device_error: Option<String>,
}

#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub motu_version: &'static str,
    pub suite: String,
    pub command: String,
    pub commit: String,
    pub started_unix_s: u64,
    pub machine: Machine,
    pub settings: Settings,
    pub work_dir: PathBuf,
    pub total_s: f64,
    pub configurations: usize,
    pub failures: usize,
    pub skipped: usize,
    /// False while the suite is still running (the file is rewritten after every scene).
    pub complete: bool,
    pub scenes: Vec<SceneResult>,
}

fn read_proc(path: &str, key: &str) -> Option<String> {
    let text = std::fs::read_to_string(path).ok()?;
    let line = text.lines().find(|l| l.starts_with(key))?;
    Some(line.split_once(':')?.1.trim().to_string())
}

fn machine(s: &Settings) -> Machine {
    let (device, driver, device_error) = if s.backend == "cpu" {
        (None, None, None)
    } else {
        match motu_gpu::list_devices() {
            Ok(d) => {
                let pick = std::env::var(motu_gpu::ENV_DEVICE)
                    .ok()
                    .and_then(|v| v.trim().parse::<usize>().ok())
                    .and_then(|i| d.iter().find(|x| x.index == i))
                    .or_else(|| d.iter().find(|x| x.ray_pipeline || x.ray_query));
                (
                    pick.map(|x| x.name.clone()),
                    pick.map(|x| x.driver.clone()),
                    None,
                )
            }
            Err(e) => (None, None, Some(e.to_string())),
        }
    };
    Machine {
        hostname: std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_string())
            .unwrap_or_default(),
        os: read_proc("/etc/os-release", "PRETTY_NAME")
            .map(|v| v.replace('=', "").trim_matches('"').to_string())
            .or_else(|| {
                std::fs::read_to_string("/etc/os-release")
                    .ok()
                    .and_then(|t| {
                        t.lines()
                            .find_map(|l| l.strip_prefix("PRETTY_NAME="))
                            .map(|v| v.trim_matches('"').to_string())
                    })
            })
            .unwrap_or_else(|| std::env::consts::OS.to_string()),
        cpu: read_proc("/proc/cpuinfo", "model name").unwrap_or_default(),
        cpu_cores: std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1),
        memory_bytes: read_proc("/proc/meminfo", "MemTotal")
            .and_then(|v| v.split_whitespace().next()?.parse::<u64>().ok())
            .map(|kib| kib * 1024)
            .unwrap_or(0),
        device,
        driver,
        device_error,
    }
}

/// `MOTU_BENCH_COMMIT`, else `git rev-parse --short HEAD` (+`-dirty`), else `unknown`.
fn commit() -> String {
    if let Ok(c) = std::env::var("MOTU_BENCH_COMMIT") {
        if !c.trim().is_empty() {
            return c.trim().to_string();
        }
    }
    let git = |args: &[&str]| {
        Command::new("git")
            .args(args)
            .stderr(Stdio::null())
            .output()
            .ok()
            .filter(|o| o.status.success())
            .map(|o| String::from_utf8_lossy(&o.stdout).trim().to_string())
    };
    match git(&["rev-parse", "--short", "HEAD"]) {
        Some(h) if !h.is_empty() => {
            let dirty = git(&["status", "--porcelain", "--untracked-files=no"])
                .is_some_and(|s| !s.is_empty());
            if dirty {
                format!("{h}-dirty")
            } else {
                h
            }
        }
        _ => "unknown".into(),
    }
}

// ------------------------------------------------------------------------------ the runner

struct Runner {
    settings: Settings,
    work: PathBuf,
    logs: PathBuf,
    t0: Instant,
    progress: bool,
    deadline: Option<Duration>,
}

impl Runner {
    fn say(&self, msg: &str) {
        if self.progress {
            eprintln!("[{:7.1} s] {msg}", self.t0.elapsed().as_secs_f64());
        }
    }

    /// The step timeout, shortened to what is left before the deadline.
    fn timeout(&self) -> Duration {
        let step = Duration::from_secs(self.settings.step_timeout_s);
        match self.deadline {
            Some(d) => step
                .min(d.saturating_sub(self.t0.elapsed()))
                .max(Duration::from_secs(1)),
            None => step,
        }
    }

    fn past_deadline(&self) -> bool {
        self.deadline.is_some_and(|d| self.t0.elapsed() >= d)
    }

    /// Generates (or reuses) the scene; returns the entry file.
    fn scene(&self, spec: &SceneSpec, r: &mut SceneResult) -> Option<PathBuf> {
        let args = match &spec.source {
            Source::Shared { path } => {
                if path.exists() {
                    return Some(path.clone());
                }
                r.error = Some(format!("{} does not exist", path.display()));
                return None;
            }
            Source::Gen { args } => args,
        };
        let dir = self.work.join("scenes").join(spec.name);
        let stamp = dir.join("bench-gen.json");
        // Generated once: reuse a scene made with the same arguments by an earlier run.
        if let Ok(text) = std::fs::read_to_string(&stamp) {
            if let Ok(v) = serde_json::from_str::<Value>(&text) {
                if v["args"] == json!(args) && dir.join("scene.pbrt").exists() {
                    r.gen_cached = true;
                    r.gen = Some(v["gen"].clone());
                    r.gen_s = v["gen_s"].as_f64();
                    self.say(&format!("{}: reusing {}", spec.name, dir.display()));
                    return Some(dir.join("scene.pbrt"));
                }
            }
        }
        if dir.exists() {
            if let Err(e) = std::fs::remove_dir_all(&dir) {
                r.error = Some(format!("cannot clear {}: {e}", dir.display()));
                return None;
            }
        }
        self.say(&format!("{}: motu gen {}", spec.name, args.join(" ")));
        let mut full = vec!["gen".to_string()];
        full.extend(args.iter().cloned());
        full.extend([
            "-o".into(),
            dir.display().to_string(),
            "--width".into(),
            self.settings.width.to_string(),
            "--height".into(),
            self.settings.height.to_string(),
            "--json".into(),
        ]);
        let run = run_step(
            &full,
            &self.logs,
            &format!("{}-gen", spec.name),
            self.timeout(),
        );
        r.gen_s = Some(run.wall_s);
        if let Some(e) = run.error {
            r.error = Some(format!("gen: {e}"));
            return None;
        }
        let gen = match parse_json(&run.stdout) {
            Ok(v) => v,
            Err(e) => {
                r.error = Some(format!("gen: {e}"));
                return None;
            }
        };
        let stamp_body = json!({ "args": args, "gen": gen, "gen_s": run.wall_s });
        if let Err(e) = std::fs::write(&stamp, stamp_body.to_string()) {
            r.warnings
                .push(format!("cannot write {}: {e}", stamp.display()));
        }
        self.say(&format!(
            "{}: generated in {:.1} s ({}, {} flattened instances)",
            spec.name,
            run.wall_s,
            format_size(gen["bytes_written"].as_u64().unwrap_or(0)),
            gen["flattened_instances"].as_u64().unwrap_or(0)
        ));
        r.gen = Some(gen);
        Some(dir.join("scene.pbrt"))
    }

    fn import(
        &self,
        scene: &Path,
        pkg: &Path,
        tag: &str,
        extra: &[String],
    ) -> Result<ImportMetrics, String> {
        let mut args = vec![
            "import".to_string(),
            scene.display().to_string(),
            "-o".into(),
            pkg.display().to_string(),
        ];
        args.extend(extra.iter().cloned());
        args.push("--json".into());
        let run = run_step(&args, &self.logs, &format!("{tag}-import"), self.timeout());
        if let Some(e) = run.error {
            return Err(format!("import: {e}"));
        }
        let v = parse_json(&run.stdout).map_err(|e| format!("import: {e}"))?;
        let u = |k: &str| v[k].as_u64().unwrap_or(0);
        let f = |k: &str| v[k].as_f64().unwrap_or(0.0);
        Ok(ImportMetrics {
            wall_s: run.wall_s,
            parse_ms: f("parse_ms"),
            compile_ms: f("compile_ms"),
            pack_ms: f("pack_ms"),
            peak_rss_bytes: u("peak_rss_bytes"),
            file_bytes: u("file_bytes"),
            instances: u("instances"),
            flattened_instances: u("flattened_instances"),
            tlas_count: u("tlas_count"),
            blas_count: u("blas_count"),
        })
    }

    fn render(&self, pkg: &Path, tag: &str) -> Result<RenderMetrics, String> {
        let stats = self.logs.join(format!("{tag}-render.json"));
        let png = self.work.join("renders").join(format!("{tag}.png"));
        let s = &self.settings;
        let args: Vec<String> = vec![
            "bench".into(),
            "--child-render".into(),
            pkg.display().to_string(),
            "--child-stats".into(),
            stats.display().to_string(),
            "--child-png".into(),
            png.display().to_string(),
            "--backend".into(),
            s.backend.into(),
            "--width".into(),
            s.width.to_string(),
            "--height".into(),
            s.height.to_string(),
            "--frames".into(),
            s.frames.to_string(),
            "--warmup".into(),
            s.warmup_frames.to_string(),
        ];
        let run = run_step(&args, &self.logs, &format!("{tag}-render"), self.timeout());
        if let Some(e) = run.error {
            return Err(format!("render: {e}"));
        }
        let text = std::fs::read_to_string(&stats)
            .map_err(|e| format!("render: reading {}: {e}", stats.display()))?;
        serde_json::from_str(&text)
            .map_err(|e| format!("render: bad stats {}: {e}", stats.display()))
    }

    fn run_scene(&self, spec: &SceneSpec) -> SceneResult {
        let mut r = SceneResult {
            name: spec.name,
            source: spec.source.clone(),
            note: spec.note.clone(),
            scene_path: None,
            gen_s: None,
            gen_cached: false,
            gen: None,
            error: None,
            warnings: Vec::new(),
            configs: Vec::new(),
        };
        if self.past_deadline() {
            r.configs = spec
                .configs
                .iter()
                .map(|c| skipped(c, "not run: --deadline-s reached"))
                .collect();
            return r;
        }
        let Some(scene) = self.scene(spec, &mut r) else {
            self.say(&format!(
                "{}: FAILED {}",
                spec.name,
                r.error.as_deref().unwrap_or("")
            ));
            r.configs = spec
                .configs
                .iter()
                .map(|c| failed(c, r.error.clone().unwrap_or_default(), None))
                .collect();
            return r;
        };
        r.scene_path = Some(scene.clone());
        if let (Some(limit), Some(n)) = (
            spec.must_exceed_instances,
            r.gen
                .as_ref()
                .and_then(|g| g["flattened_instances"].as_u64()),
        ) {
            if n <= limit {
                r.warnings.push(format!(
                    "{n} flattened instances do not exceed {limit}: raise --island-scale so that `sl` needs TLAS splits"
                ));
            }
        }
        let pkg_dir = self.work.join("packages");
        for c in &spec.configs {
            if self.past_deadline() {
                r.configs.push(skipped(c, "not run: --deadline-s reached"));
                continue;
            }
            let tag = format!("{}-{}", spec.name, c.label.replace('+', "-"));
            let pkg = pkg_dir.join(format!("{tag}.motu"));
            self.say(&format!("{tag}: import {}", c.import_args.join(" ")));
            let import = match self.import(&scene, &pkg, &tag, &c.import_args) {
                Ok(m) => m,
                Err(e) => {
                    self.say(&format!("{tag}: FAILED {e}"));
                    let _ = std::fs::remove_file(&pkg);
                    r.configs.push(failed(c, e, None));
                    continue;
                }
            };
            self.say(&format!(
                "{tag}: imported in {:.1} s (peak RSS {}, {}, {} TLAS / {} BLAS); render {}×{} {} ({}+{} frames)",
                import.wall_s,
                format_size(import.peak_rss_bytes),
                format_size(import.file_bytes),
                import.tlas_count,
                import.blas_count,
                self.settings.width,
                self.settings.height,
                self.settings.backend,
                self.settings.warmup_frames,
                self.settings.frames,
            ));
            let render = self.render(&pkg, &tag);
            if !self.settings.keep_packages {
                // Packages of the big scenes are tens of GB: keep only one at a time.
                let _ = std::fs::remove_file(&pkg);
            }
            match render {
                Ok(m) => {
                    self.say(&format!(
                        "{tag}: {:.2} ms/frame, {:.1} Mrays/s, AS {} (build {:.0} ms), child {:.1} s",
                        m.ms_per_frame,
                        m.rays_per_second / 1e6,
                        format_size(m.as_bytes),
                        m.as_build_ms,
                        m.wall_s
                    ));
                    r.configs.push(ConfigResult {
                        label: c.label.clone(),
                        import_args: c.import_args.clone(),
                        status: "ok",
                        error: None,
                        import: Some(import),
                        render: Some(m),
                        ratios: Ratios::default(),
                    });
                }
                Err(e) => {
                    self.say(&format!("{tag}: FAILED {e}"));
                    r.configs.push(failed(c, e, Some(import)));
                }
            }
        }
        fill_ratios(&mut r.configs);
        r
    }
}

fn skipped(c: &ConfigSpec, why: &str) -> ConfigResult {
    ConfigResult {
        status: "skipped",
        ..failed(c, why.to_string(), None)
    }
}

fn failed(c: &ConfigSpec, error: String, import: Option<ImportMetrics>) -> ConfigResult {
    ConfigResult {
        label: c.label.clone(),
        import_args: c.import_args.clone(),
        status: "failed",
        error: Some(error),
        import,
        render: None,
        ratios: Ratios::default(),
    }
}

/// Ratios against the scene's `sl` configuration (absent when either side is missing or 0).
fn fill_ratios(configs: &mut [ConfigResult]) {
    let Some(base) = configs.iter().find(|c| c.label == "sl").cloned() else {
        return;
    };
    let ratio = |num: Option<f64>, den: Option<f64>| match (num, den) {
        (Some(n), Some(d)) if n > 0.0 && d > 0.0 => Some(n / d),
        _ => None,
    };
    let rays = |c: &ConfigResult| c.render.as_ref().map(|m| m.rays_per_second);
    let as_bytes = |c: &ConfigResult| c.render.as_ref().map(|m| m.as_bytes as f64);
    let rss = |c: &ConfigResult| c.import.as_ref().map(|m| m.peak_rss_bytes as f64);
    for c in configs.iter_mut() {
        c.ratios = Ratios {
            rays_per_second_vs_sl: ratio(rays(c), rays(&base)),
            as_bytes_sl_over_this: ratio(as_bytes(&base), as_bytes(c)),
            import_peak_rss_vs_sl: ratio(rss(c), rss(&base)),
        };
    }
}

// ------------------------------------------------------------------------------ the child render

/// The hidden `--child-render PKG` mode's options.
#[derive(Clone, Debug)]
pub struct ChildRender {
    pub backend: Option<Backend>,
    pub frames: Option<u32>,
    pub warmup: Option<u32>,
    /// Where the [`RenderMetrics`] JSON goes (`--child-stats`).
    pub stats_path: PathBuf,
    pub png: Option<PathBuf>,
    /// When the child started (before opening the package), for `wall_s`.
    pub started: Instant,
}

/// `--child-render PKG`: build, warm up, time `frames` frames, write [`RenderMetrics`] as JSON.
/// The caller opens the package and picks the camera (`view`, `camera`, `meshes`).
pub fn child_render<M>(
    a: &ChildRender,
    view: HierarchyView<'_>,
    camera: &CameraParams,
    meshes: &M,
) -> Result<(), BenchError>
where
    M: motu_trace::MeshSource + motu_gpu::MeshBlobSource,
{
    let t0 = a.started;
    let stats_path = &a.stats_path;
    let frames = a.frames.unwrap_or(21).max(1);
    let warmup = a.warmup.unwrap_or(1);
    let camera = *camera;
    let backend = a.backend.unwrap_or(Backend::Query);
    let mut m = RenderMetrics {
        backend: backend_name(backend).into(),
        width: camera.width,
        height: camera.height,
        warmup_frames: warmup,
        frames,
        ..Default::default()
    };
    let rgba8 = match backend {
        Backend::Cpu => {
            let tracer =
                motu_trace::Tracer::new(view, meshes).map_err(|source| BenchError::Trace {
                    what: "preparing the CPU tracer",
                    source,
                })?;
            let opts = motu_trace::RenderOptions::default();
            // The first frame builds every reachable BVH (`prepare`): that is the build time.
            let first = motu_trace::render_with(&tracer, &camera, &opts).map_err(|source| {
                BenchError::Trace {
                    what: "rendering on the CPU",
                    source,
                }
            })?;
            m.as_build_ms = first.stats.prepare_ms;
            let timed = motu_trace::RenderOptions {
                prepare: false,
                ..opts
            };
            for _ in 1..warmup {
                motu_trace::render_with(&tracer, &camera, &timed)
                    .map_err(BenchError::TraceFrame)?;
            }
            let mut times = Vec::with_capacity(frames as usize);
            let mut last = first;
            for _ in 0..frames {
                let t = Instant::now();
                let o = motu_trace::render_with(&tracer, &camera, &timed)
                    .map_err(BenchError::TraceFrame)?;
                times.push(t.elapsed().as_secs_f64() * 1e3);
                last = o;
            }
            m.ms_per_frame = median(&mut times);
            m.device = format!("CPU ({} threads)", last.stats.threads);
            m.rays = last.stats.rays;
            m.traces_per_ray = last.stats.traces_per_ray;
            m.stack_overflows = last.stats.stack_overflows;
            last.rgba8
        }
        Backend::Pipeline | Backend::Query => {
            use motu_gpu::{Context as GpuContext, ContextOptions, Requirement};
            let ctx = GpuContext::new(&ContextOptions {
                require: if backend == Backend::Query {
                    Requirement::RayQuery
                } else {
                    Requirement::RayPipeline
                },
                ..Default::default()
            })
            .map_err(gpu_err(
                "opening a Vulkan device for ray tracing (`motu devices` lists them)",
            ))?;
            m.device = ctx.device_name().to_string();
            let scene =
                motu_gpu::GpuScene::build(&ctx, &view, meshes, &motu_gpu::BuildOptions::default())
                    .map_err(gpu_err("building acceleration structures"))?;
            let res = scene.report();
            m.as_build_ms = res.build_ms;
            m.blas_bytes = res.blas_bytes;
            m.blas_compacted_bytes = res.blas_compacted_bytes;
            m.tlas_bytes = res.tlas_bytes;
            m.tlas_compacted_bytes = res.tlas_compacted_bytes;
            m.geometry_bytes = res.geometry_bytes;
            m.scratch_peak_bytes = res.scratch_peak_bytes;
            let opts = motu_gpu::RenderOptions {
                backend: if backend == Backend::Query {
                    motu_gpu::Backend::Query
                } else {
                    motu_gpu::Backend::Pipeline
                },
                frames: warmup.max(1),
                ..Default::default()
            };
            // Warm-up in its own submission: its frames never enter the timed median.
            if warmup > 0 {
                motu_gpu::render(&ctx, &scene, &camera, &opts)
                    .map_err(gpu_err("warm-up frames"))?;
            }
            let out = motu_gpu::render(
                &ctx,
                &scene,
                &camera,
                &motu_gpu::RenderOptions { frames, ..opts },
            )
            .map_err(gpu_err("timed frames"))?;
            let st = &out.stats;
            m.ms_per_frame = st.ms_per_frame;
            m.rays = st.rays;
            m.traces_per_ray = st.traces_per_ray;
            m.stack_overflows = st.stack_overflows;
            m.as_bytes = st.as_bytes;
            m.vram_peak_bytes = st.vram_peak_bytes;
            m.allocation_count = st.allocation_count;
            drop(scene);
            ctx.check_validation()
                .map_err(gpu_err("Vulkan validation reported errors"))?;
            out.rgba8
        }
    };
    m.fps = if m.ms_per_frame > 0.0 {
        1e3 / m.ms_per_frame
    } else {
        0.0
    };
    m.rays_per_second = if m.ms_per_frame > 0.0 {
        m.rays as f64 / (m.ms_per_frame / 1e3)
    } else {
        0.0
    };
    if let Some(png) = &a.png {
        if let Some(dir) = png.parent() {
            std::fs::create_dir_all(dir).map_err(io(format!("creating {}", dir.display())))?;
        }
        motu_trace::write_png(png, camera.width, camera.height, &rgba8).map_err(|source| {
            BenchError::PngWrite {
                what: format!("writing {}", png.display()),
                source,
            }
        })?;
    }
    m.peak_rss_bytes = peak_rss_bytes().unwrap_or(0);
    m.wall_s = t0.elapsed().as_secs_f64();
    std::fs::write(stats_path, serde_json::to_string_pretty(&m)?)
        .map_err(io(format!("writing {}", stats_path.display())))?;
    Ok(())
}

fn gpu_err(what: &'static str) -> impl FnOnce(motu_gpu::GpuError) -> BenchError {
    move |source| BenchError::Gpu { what, source }
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}

// ------------------------------------------------------------------------------ output

fn mb(b: u64) -> String {
    format!("{:.1}", b as f64 / MIB)
}

fn opt_ratio(r: Option<f64>) -> String {
    match r {
        Some(v) if v >= 100.0 => format!("{v:.0}×"),
        Some(v) => format!("{v:.2}×"),
        None => "–".into(),
    }
}

const HEADER: [&str; 17] = [
    "scene",
    "config",
    "TLAS/BLAS",
    "import s",
    "import RSS MB",
    "compile ms",
    "AS build ms",
    "BLAS MB built→compacted",
    "AS MB",
    "ms/frame",
    "FPS",
    "Mrays/s",
    "traces/ray",
    "overflows",
    "rays/s vs sl",
    "AS sl/x",
    "status",
];

fn rows(report: &BenchReport) -> Vec<[String; 17]> {
    let mut out = Vec::new();
    for s in &report.scenes {
        for c in &s.configs {
            let i = c.import.as_ref();
            let m = c.render.as_ref();
            let f = |x: Option<String>| x.unwrap_or_else(|| "–".into());
            out.push([
                s.name.to_string(),
                c.label.clone(),
                f(i.map(|i| format!("{}/{}", i.tlas_count, i.blas_count))),
                f(i.map(|i| format!("{:.2}", i.wall_s))),
                f(i.map(|i| mb(i.peak_rss_bytes))),
                f(i.map(|i| format!("{:.0}", i.compile_ms))),
                f(m.map(|m| format!("{:.0}", m.as_build_ms))),
                f(m.map(|m| format!("{}→{}", mb(m.blas_bytes), mb(m.blas_compacted_bytes)))),
                f(m.map(|m| mb(m.as_bytes))),
                f(m.map(|m| format!("{:.2}", m.ms_per_frame))),
                f(m.map(|m| format!("{:.1}", m.fps))),
                f(m.map(|m| format!("{:.1}", m.rays_per_second / 1e6))),
                f(m.map(|m| format!("{:.2}", m.traces_per_ray))),
                f(m.map(|m| m.stack_overflows.to_string())),
                opt_ratio(c.ratios.rays_per_second_vs_sl),
                opt_ratio(c.ratios.as_bytes_sl_over_this),
                match c.status {
                    "ok" => "ok".into(),
                    "skipped" => "skipped".into(),
                    _ => "FAILED".into(),
                },
            ]);
        }
    }
    out
}

fn failures(report: &BenchReport) -> Vec<String> {
    let mut out = Vec::new();
    for s in &report.scenes {
        for w in &s.warnings {
            out.push(format!("{}: warning: {w}", s.name));
        }
        for c in &s.configs {
            if let Some(e) = &c.error {
                out.push(format!("{}/{}: {e}", s.name, c.label));
            }
        }
    }
    out
}

fn header_lines(r: &BenchReport) -> Vec<String> {
    let st = &r.settings;
    let m = &r.machine;
    vec![
        format!(
            "suite {}{}: {}×{}, backend {}, median of {} timed frames after {} warm-up frame(s)",
            st.suite,
            if st.quick && st.suite != "quick" {
                " (quick)"
            } else {
                ""
            },
            st.width,
            st.height,
            st.backend,
            st.frames,
            st.warmup_frames
        ),
        format!(
            "machine: {} — {} ({} cores, {} RAM), {}",
            m.hostname,
            m.cpu,
            m.cpu_cores,
            format_size(m.memory_bytes),
            m.os
        ),
        format!(
            "device: {}{}",
            m.device.as_deref().unwrap_or("none (CPU backend)"),
            m.driver
                .as_deref()
                .map(|d| format!(", driver {d}"))
                .unwrap_or_default()
        ),
        format!("commit {}, motu {}", r.commit, r.motu_version),
        format!("command: {}", r.command),
    ]
}

/// The terminal table `motu bench` prints (header lines, one row per configuration,
/// failures, a summary line), each line ending in a newline.
pub fn text_table(r: &BenchReport) -> String {
    let mut out = String::new();
    let mut println = |l: String| {
        out.push_str(&l);
        out.push('\n');
    };
    for l in header_lines(r) {
        println(l);
    }
    let rows = rows(r);
    let mut widths: Vec<usize> = HEADER.iter().map(|h| h.chars().count()).collect();
    for row in &rows {
        for (w, cell) in widths.iter_mut().zip(row.iter()) {
            *w = (*w).max(cell.chars().count());
        }
    }
    let line = |cells: Vec<&str>| {
        let mut s = String::new();
        for (i, (c, w)) in cells.iter().zip(&widths).enumerate() {
            let pad = w.saturating_sub(c.chars().count());
            if i < 2 {
                s.push_str(c);
                s.push_str(&" ".repeat(pad));
            } else {
                s.push_str(&" ".repeat(pad));
                s.push_str(c);
            }
            s.push_str("  ");
        }
        s.trim_end().to_string()
    };
    println(String::new());
    println(line(HEADER.to_vec()));
    for row in &rows {
        println(line(row.iter().map(String::as_str).collect()));
    }
    let f = failures(r);
    if !f.is_empty() {
        println(String::new());
        for l in f {
            println(l);
        }
    }
    println(format!(
        "\n{} configurations, {} failed, {} skipped, {:.1} s in all; logs and renders in {}",
        r.configurations,
        r.failures,
        r.skipped,
        r.total_s,
        r.work_dir.display()
    ));
    out
}

/// The results as a Markdown table (`--markdown`, for BENCHMARKS.md).
pub fn markdown(r: &BenchReport) -> String {
    let mut s = String::new();
    for l in header_lines(r) {
        s.push_str(&format!("- {l}\n"));
    }
    s.push('\n');
    s.push_str(&format!("| {} |\n", HEADER.join(" | ")));
    s.push_str(&format!(
        "|{}\n",
        HEADER
            .iter()
            .enumerate()
            .map(|(i, _)| if i < 2 { "---|" } else { "---:|" })
            .collect::<String>()
    ));
    for row in rows(r) {
        s.push_str(&format!("| {} |\n", row.join(" | ")));
    }
    let notes: Vec<String> = r
        .scenes
        .iter()
        .filter(|sc| !sc.note.is_empty())
        .map(|sc| {
            let src = match &sc.source {
                Source::Gen { args } => format!("`motu gen {}`", args.join(" ")),
                Source::Shared { path } => format!(
                    "`{}`",
                    path.file_name()
                        .map(|f| f.to_string_lossy().to_string())
                        .unwrap_or_default()
                ),
            };
            let inst = sc
                .gen
                .as_ref()
                .and_then(|g| g["flattened_instances"].as_u64())
                .map(|n| format!(", {n} flattened instances"))
                .unwrap_or_default();
            format!("- {}: {src}{inst}; {}\n", sc.name, sc.note)
        })
        .collect();
    if !notes.is_empty() {
        s.push('\n');
        for n in notes {
            s.push_str(&n);
        }
    }
    let f = failures(r);
    if !f.is_empty() {
        s.push('\n');
        for l in f {
            s.push_str(&format!("- {}\n", l.replace('|', "\\|")));
        }
    }
    s
}

fn work_dir(a: &SuiteOptions) -> PathBuf {
    a.work_dir
        .clone()
        .unwrap_or_else(|| PathBuf::from("motu-bench"))
}

/// `--dry-run`: the settings, work directory and scenes (with their configurations) a run would
/// measure, as JSON.
pub fn dry_run_plan(a: &SuiteOptions) -> Result<Value, BenchError> {
    let settings = settings(a)?;
    let scenes = plan(&settings, a)?;
    let work = work_dir(a);
    Ok(json!({ "settings": settings, "work_dir": work, "scenes": scenes }))
}

/// Runs the suite: every step a child process, `bench.json` (and `--markdown`) rewritten after
/// every scene. Failed configurations are recorded in the report; see [`BenchReport::check`].
pub fn run_suite(a: &SuiteOptions) -> Result<BenchReport, BenchError> {
    let settings = settings(a)?;
    let scenes = plan(&settings, a)?;
    let work = work_dir(a);
    let logs = work.join("logs");
    for d in [&work, &logs, &work.join("packages"), &work.join("renders")] {
        std::fs::create_dir_all(d).map_err(io(format!("creating {}", d.display())))?;
    }
    // Children are given absolute paths so their logs say where things are.
    let work = std::fs::canonicalize(&work).map_err(io(format!("resolving {}", work.display())))?;
    let runner = Runner {
        work: work.clone(),
        logs: work.join("logs"),
        t0: Instant::now(),
        progress: a.progress,
        deadline: a.deadline_s.map(Duration::from_secs),
        settings: settings.clone(),
    };
    let started_unix_s = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs())
        .unwrap_or(0);
    runner.say(&format!(
        "motu bench {}: {} scenes, {}×{} {}, work dir {}",
        settings.suite,
        scenes.len(),
        settings.width,
        settings.height,
        settings.backend,
        work.display()
    ));
    let mut report = BenchReport {
        motu_version: env!("CARGO_PKG_VERSION"),
        suite: settings.suite.clone(),
        command: std::iter::once("motu".to_string())
            .chain(std::env::args().skip(1))
            .collect::<Vec<_>>()
            .join(" "),
        commit: commit(),
        started_unix_s,
        machine: machine(&settings),
        settings,
        work_dir: work.clone(),
        total_s: 0.0,
        configurations: 0,
        failures: 0,
        skipped: 0,
        complete: false,
        scenes: Vec::new(),
    };
    for spec in &scenes {
        let r = runner.run_scene(spec);
        report.scenes.push(r);
        report.complete = report.scenes.len() == scenes.len();
        report.total_s = runner.t0.elapsed().as_secs_f64();
        let all = || report.scenes.iter().flat_map(|s| &s.configs);
        report.configurations = all().count();
        report.failures = all().filter(|c| c.status == "failed").count();
        report.skipped = all().filter(|c| c.status == "skipped").count();
        // Written after every scene: a run killed from outside still leaves what it measured.
        write_outputs(&report, &work, a.markdown.as_deref())?;
    }
    Ok(report)
}

impl BenchReport {
    /// An error when every configuration failed (the run measured nothing), else `Ok`.
    pub fn check(&self) -> Result<(), BenchError> {
        if self.configurations > 0 && self.failures == self.configurations {
            return Err(BenchError::EveryConfigurationFailed {
                first: failures_first(self),
                logs: self.work_dir.join("logs"),
            });
        }
        Ok(())
    }
}

fn write_outputs(report: &BenchReport, work: &Path, md: Option<&Path>) -> Result<(), BenchError> {
    let json_path = work.join("bench.json");
    std::fs::write(&json_path, serde_json::to_string_pretty(report)?)
        .map_err(io(format!("writing {}", json_path.display())))?;
    if let Some(p) = md {
        std::fs::write(p, markdown(report)).map_err(io(format!("writing {}", p.display())))?;
    }
    Ok(())
}

fn failures_first(r: &BenchReport) -> String {
    failures(r).into_iter().next().unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn result(label: &str, rays_per_second: f64, as_bytes: u64, rss: u64) -> ConfigResult {
        ConfigResult {
            label: label.into(),
            import_args: Vec::new(),
            status: "ok",
            error: None,
            import: Some(ImportMetrics {
                peak_rss_bytes: rss,
                ..Default::default()
            }),
            render: Some(RenderMetrics {
                rays_per_second,
                as_bytes,
                ..Default::default()
            }),
            ratios: Ratios::default(),
        }
    }

    #[test]
    fn ratios_are_against_the_sl_configuration_of_the_same_run() {
        let mut c = vec![
            result("ml", 60.0, 10, 100),
            result("sl", 100.0, 400, 200),
            result("levels2", 0.0, 0, 0),
        ];
        fill_ratios(&mut c);
        assert_eq!(c[0].ratios.rays_per_second_vs_sl, Some(0.6));
        assert_eq!(c[0].ratios.as_bytes_sl_over_this, Some(40.0));
        assert_eq!(c[0].ratios.import_peak_rss_vs_sl, Some(0.5));
        assert_eq!(c[1].ratios.rays_per_second_vs_sl, Some(1.0));
        // Zero (e.g. a failed render) gives no ratio rather than infinity.
        assert_eq!(c[2].ratios.rays_per_second_vs_sl, None);
        assert_eq!(c[2].ratios.as_bytes_sl_over_this, None);
    }

    #[test]
    fn no_sl_means_no_ratios() {
        let mut c = vec![result("ml", 60.0, 10, 1)];
        fill_ratios(&mut c);
        assert!(c[0].ratios.rays_per_second_vs_sl.is_none());
    }

    #[test]
    fn median_is_the_middle_of_sorted_times() {
        assert_eq!(median(&mut [5.0, 1.0, 3.0]), 3.0);
        assert_eq!(median(&mut []), 0.0);
    }

    #[test]
    fn a_failing_child_is_recorded_not_raised() {
        let dir = tempdir();
        // `motu-cli`'s test binary is not motu: any arguments make it fail, which is the point.
        let run = run_step(
            &["--definitely-not-a-flag".into()],
            &dir,
            "t",
            Duration::from_secs(60),
        );
        assert!(run.error.is_some(), "{run:?}");
        assert!(dir.join("t.err").exists());
        std::fs::remove_dir_all(&dir).ok();
    }

    fn tempdir() -> PathBuf {
        let d = std::env::temp_dir().join(format!("motu-bench-test-{}", std::process::id()));
        std::fs::create_dir_all(&d).ok();
        d
    }
}
