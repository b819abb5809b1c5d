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
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! `motu bench` as a library: suite plans (scenes × configurations `sl`, `ml`, `levels2`, `+lod`),
//! one child process of the running executable per step (gen, import, render; timeouts, deadline,
//! logs), the timed child render (warm-up submitted apart, median of GPU timestamps or CPU frames),
//! ratios against `sl` of the same run, `bench.json`, the terminal and Markdown tables. Files:
//! `plan.rs` (options, settings, scenes × configurations), `steps.rs` (child processes),
//! `runner.rs` (a scene's steps → results, ratios), `child.rs` (the timed child render),
//! `report.rs` (`bench.json` structs, machine, commit), `tables.rs` (text and Markdown),
//! `error.rs`; `flight.rs` (`--camera-path` flights, full build or streaming); `lib.rs` runs the
//! suite.
//!
//! Key types: `SuiteOptions`, `run_suite`, `FlightOptions`, `run_flight`, `dry_run_plan`,
//! `BenchReport` (`check`), `text_table`, `markdown`, `ChildRender`, `child_render`, `Backend` and
//! `best_backend` (motu-render's, re-exported), `BenchError`.

#[macro_use]
mod error;
mod child;
mod flight;
mod plan;
mod report;
mod runner;
mod steps;
mod tables;

pub use child::{child_render, ChildRender};
pub use error::BenchError;
pub use flight::{run_flight, Flight, FlightOptions};
pub use plan::{
    best_backend, Backend, ConfigSpec, SceneSpec, Settings, Source, SuiteKind, SuiteOptions,
};
pub use report::{
    BenchReport, ConfigResult, ImportMetrics, Machine, Ratios, RenderMetrics, SceneResult,
};
pub use tables::{markdown, text_table};

use error::io;
use plan::{plan, settings};
use report::{commit, machine};
use runner::Runner;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use tables::failures;

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
    use crate::child::median;
    use crate::runner::fill_ratios;
    use crate::steps::run_step;

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

    /// The suite's configurations, pinned: labels and `motu import` arguments per scene.
    #[test]
    fn plans_keep_their_configurations() {
        let configs = |quick: bool| -> Vec<String> {
            let a = SuiteOptions {
                suite: "cpu".into(),
                quick,
                scenes: Some(PathBuf::from("/nonexistent/shared/scenes")),
                ..Default::default()
            };
            let s = plan::settings(&a).unwrap();
            plan::plan(&s, &a)
                .unwrap()
                .iter()
                .flat_map(|sc| {
                    sc.configs
                        .iter()
                        .map(|c| format!("{} {}: {}", sc.name, c.label, c.import_args.join(" ")))
                })
                .collect()
        };
        let std = |scene: &str| {
            [
                format!("{scene} sl: --levels sl"),
                format!("{scene} ml: --levels ml"),
                format!("{scene} levels2: --levels 2"),
                format!("{scene} auto: --levels auto"),
            ]
        };
        let mut want: Vec<String> = std("forest")
            .into_iter()
            .chain(std("sphereflake"))
            .collect();
        want.extend(
            [
                "lod-grid sl: --levels sl",
                "lod-grid ml: --levels ml",
                "lod-grid sl+lod: --levels sl --lod 4",
                "lod-grid ml+lod: --levels ml --lod 4",
                "buddha-fractal sl: --levels sl",
                "buddha-fractal ml: --levels ml",
            ]
            .map(String::from),
        );
        let mut full = want.clone();
        full.extend(["island sl: --levels sl", "island ml: --levels ml"].map(String::from));
        assert_eq!(configs(false), full);
        want.extend(
            [
                "island sl: --levels sl --max-instances 1500",
                "island ml: --levels ml --max-instances 1500",
            ]
            .map(String::from),
        );
        assert_eq!(configs(true), want);
    }

    fn tempdir() -> PathBuf {
        let d = std::env::temp_dir().join(format!("motu-bench-test-{}", std::process::id()));
        std::fs::create_dir_all(&d).ok();
        d
    }
}
