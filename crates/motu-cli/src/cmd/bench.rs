//! `motu bench`: flags → [`motu_bench`] (the harness) → stdout. A `--camera-path` flight is
//! [`motu_bench::run_flight`]; the hidden `--child-render` mode opens the package and picks the camera here
//! (the render command's glue) and times the frames in the library.

use crate::cli::BenchArgs;
use crate::pipeline;
use anyhow::Context;
use motu_bench::{Backend, ChildRender, FlightOptions, SuiteOptions};
use std::time::Instant;

pub fn run(a: BenchArgs) -> anyhow::Result<()> {
    if let Some(pkg) = &a.child_render {
        return child_render(&a, pkg);
    }
    if let (Some(path), Some(pkg)) = (&a.camera_path, &a.package) {
        crate::output::check_input(
            "--camera-path",
            path,
            Some(super::render::CAMERA_PATH_MAX_BYTES),
        )?;
        crate::output::check_input("--package", pkg, None)?;
        let opts = FlightOptions {
            package: pkg.clone(),
            camera_path: path.clone(),
            width: a.width,
            height: a.height,
            frames: a.frames,
            warmup: a.warmup,
            backend: a.backend.map(Backend::from),
            stream: a.stream,
            vram_budget: a.vram_budget,
            stream_bounds: super::render::stream_bounds(&a.stream_bounds),
            stream_passes: a.stream_passes,
            next_camera: a.next_camera.map(Into::into).unwrap_or_default(),
            still_frames: a.still_frames.unwrap_or(0),
            shading: {
                let d = motu_render::ShadingOptions::default();
                motu_render::ShadingOptions {
                    ao_reach_of_diagonal: a.ao_reach.unwrap_or(d.ao_reach_of_diagonal),
                    bounces: a.bounces.unwrap_or(d.bounces),
                    ..d
                }
            },
        };
        let flight = motu_bench::run_flight(&opts)?;
        if a.json {
            println!("{}", serde_json::to_string_pretty(&flight.report)?);
        } else {
            print!("{}", flight.text);
        }
        return Ok(());
    }
    let opts = SuiteOptions {
        suite: a.suite.clone(),
        work_dir: a.work_dir.clone(),
        quick: a.quick,
        markdown: a.markdown.clone(),
        only: a.only.clone(),
        frames: a.frames,
        warmup: a.warmup,
        width: a.width,
        height: a.height,
        backend: a.backend.map(Backend::from),
        island_scale: a.island_scale,
        scenes: a.scenes.clone(),
        configs: a.configs.clone(),
        deadline_s: a.deadline_s,
        step_timeout_s: a.step_timeout_s,
        keep: a.keep,
        progress: a.progress || std::io::IsTerminal::is_terminal(&std::io::stderr()),
    };
    if a.dry_run {
        let plan = motu_bench::dry_run_plan(&opts)?;
        println!("{}", serde_json::to_string_pretty(&plan)?);
        return Ok(());
    }
    let report = motu_bench::run_suite(&opts)?;
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        print!("{}", motu_bench::text_table(&report));
    }
    report.check()?;
    Ok(())
}

/// `--child-render PKG`: the package's default camera at `--width`/`--height`, timed by the library.
fn child_render(a: &BenchArgs, package: &std::path::Path) -> anyhow::Result<()> {
    let started = Instant::now();
    let stats_path = a
        .child_stats
        .clone()
        .context("--child-render needs --child-stats")?;
    let pkg = pipeline::open(package)?;
    let view = pkg.view()?;
    let camera = super::render::camera_params(&pkg, &view, None, a.width, a.height)?;
    let meshes = super::render::PackageMeshes(&pkg);
    let opts = ChildRender {
        backend: a.backend.map(Backend::from),
        frames: a.frames,
        warmup: a.warmup,
        stats_path,
        png: a.child_png.clone(),
        started,
    };
    motu_bench::child_render(&opts, view, &camera, &meshes)?;
    Ok(())
}
