//! `motu bench --camera-path FILE --package PKG`: a recorded flight (`motu view --record`) as a
//! benchmark: the structures are built once, then every frame of the path is rendered through
//! the viewer's renderer; GPU times per frame (timestamps) after untimed warm-up frames.

use crate::cli::{BackendArg, BenchArgs};
use crate::pipeline;
use anyhow::Context as _;
use serde_json::json;
use std::path::Path;

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

pub fn run(a: &BenchArgs, package: &Path, path_file: &Path) -> anyhow::Result<()> {
    let path = super::render::load_camera_path(path_file)?;
    let pkg = pipeline::open(package)?;
    let view = pkg.view()?;
    let base = super::render::camera_params(&pkg, &view, None, None, None)?;
    let (w, h) = match (a.width, a.height, path.width, path.height) {
        (Some(w), Some(h), _, _) => (w, h),
        (None, None, Some(w), Some(h)) => (w, h),
        _ => (base.width, base.height),
    };
    let n = a.frames.unwrap_or(path.poses.len() as u32).max(1);
    let warmup = a.warmup.unwrap_or(3);
    let backend = match a.backend {
        Some(BackendArg::Cpu) => {
            anyhow::bail!("a flight benchmark runs on the GPU (--backend pipeline or query)")
        }
        Some(b) => b,
        None => super::render::best_backend(&motu_gpu::list_devices()?),
    };
    let gpu_backend = match backend {
        BackendArg::Query => motu_gpu::Backend::Query,
        BackendArg::Pipeline => motu_gpu::Backend::Pipeline,
        BackendArg::Cpu => anyhow::bail!("no Vulkan device with ray tracing (`motu devices`)"),
    };
    let ctx = motu_gpu::Context::new(&motu_gpu::ContextOptions {
        require: match gpu_backend {
            motu_gpu::Backend::Query => motu_gpu::Requirement::RayQuery,
            motu_gpu::Backend::Pipeline => motu_gpu::Requirement::RayPipeline,
        },
        ..Default::default()
    })
    .context("opening a Vulkan device for ray tracing (`motu devices` lists them)")?;
    let meshes = super::render::PackageMeshes(&pkg);
    let scene = motu_gpu::GpuScene::build(&ctx, &view, &meshes, &motu_gpu::BuildOptions::default())
        .context("building acceleration structures")?;
    let build_ms = scene.report().build_ms;
    let mut live = motu_gpu::LiveRenderer::new(scene);
    let opts = motu_gpu::RenderOptions {
        backend: gpu_backend,
        ..Default::default()
    };
    let cams: Vec<_> = (0..n).map(|f| path.sample(f, n).params(w, h)).collect();
    for _ in 0..warmup {
        live.render_frame(&cams[0], &opts)
            .context("warm-up frame")?;
    }
    let mut ms = Vec::with_capacity(cams.len());
    let mut mrays = Vec::with_capacity(cams.len());
    let mut traces = 0f64;
    for (f, cam) in cams.iter().enumerate() {
        let out = live
            .render_frame(cam, &opts)
            .with_context(|| format!("flight frame {f}"))?;
        ms.push(out.stats.ms_per_frame);
        mrays.push(out.stats.rays_per_second / 1e6);
        traces += out.stats.traces_per_ray;
    }
    drop(live);
    ctx.check_validation()
        .context("Vulkan validation reported errors")?;
    let mut sorted = ms.clone();
    sorted.sort_by(f64::total_cmp);
    let mut sorted_mrays = mrays.clone();
    sorted_mrays.sort_by(f64::total_cmp);
    let report = json!({
        "kind": "flight",
        "package": package.display().to_string(),
        "camera_path": path_file.display().to_string(),
        "device": ctx.device_name(),
        "backend": backend_name(gpu_backend),
        "width": w,
        "height": h,
        "frames": n,
        "warmup_frames": warmup,
        "as_build_ms": build_ms,
        "ms_per_frame_median": percentile(&sorted, 0.5),
        "ms_per_frame_p95": percentile(&sorted, 0.95),
        "ms_per_frame_max": sorted.last().copied().unwrap_or(0.0),
        "mrays_per_second_median": percentile(&sorted_mrays, 0.5),
        "traces_per_ray_mean": traces / n as f64,
        "frame_ms": ms,
    });
    if a.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "flight {} on {} ({}, {}×{}): {} frames, median {:.2} ms, p95 {:.2} ms, max {:.2} ms, {:.1} Mrays/s, {:.2} traces/ray",
            path_file.display(),
            ctx.device_name(),
            backend_name(gpu_backend),
            w,
            h,
            n,
            percentile(&sorted, 0.5),
            percentile(&sorted, 0.95),
            sorted.last().copied().unwrap_or(0.0),
            percentile(&sorted_mrays, 0.5),
            traces / n as f64
        );
    }
    Ok(())
}

fn backend_name(b: motu_gpu::Backend) -> &'static str {
    b.name()
}
