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
pub use flight::{run_flight, Flight, FlightOptions, NextCamera};
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
mod tests;
