//! The report a suite writes (`bench.json`): metrics per configuration, scene results, machine.

use crate::plan::{Settings, Source};
use serde::Serialize;
use serde_json::Value;
use std::path::PathBuf;
use std::process::{Command, Stdio};

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

pub(crate) fn machine(s: &Settings) -> Machine {
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
pub(crate) fn commit() -> String {
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
