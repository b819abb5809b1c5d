//! `motu view`: the interactive viewer (crates/motu-view) over a package: a full GPU build, or
//! the streaming renderer under `--vram-budget`/`--stream` (`motu_view::PackageSource`). Here:
//! the flags' checks and mapping, the camera set-up, and the outputs of a scripted run.

use crate::cli::{BackendArg, LodModeArg, ViewArg, ViewArgs};
use crate::cmd::render::{camera_pose, load_camera_path, PackageMeshes};
use crate::pipeline;
use anyhow::{bail, Context as _};
use motu_abi::camera::RecordedPath;
use motu_abi::lod::LodParams;
use motu_pack::ScenePackage;
use motu_view::{PackageSource, PackageSourceSettings, ViewOptions, ViewStreamSettings};

pub fn run(a: ViewArgs) -> anyhow::Result<()> {
    // Before any work: without a display the answer is `motu render`.
    motu_view::check_display()?;
    if a.stream_passes == Some(0) {
        bail!("--stream-passes must be at least 1 (1: trace with what is resident, then build for the next frame)");
    }
    let streaming = a.stream || a.vram_budget.is_some();
    if !streaming && crate::cmd::render::stream_bounds(&a.stream_bounds).given() {
        bail!(
            "--stream-fallback, --stream-build-budget, --stream-build-ms and --stream-probe* bound \
             streaming frames: add --stream or --vram-budget"
        );
    }
    if !streaming && a.stream_always {
        bail!(
            "--stream-always streams even a scene the budget holds: add --stream or --vram-budget"
        );
    }
    if let Some(why) = crate::cmd::render::stream_bounds(&a.stream_bounds).conflict() {
        bail!(why);
    }
    if a.frames == Some(0) {
        bail!("--frames must be at least 1");
    }
    if a.frames.is_none() && (a.screenshot.is_some() || a.aov.is_some() || a.stats.is_some()) {
        bail!("--screenshot, --aov and --stats need --frames N (render N frames, write the last, exit)");
    }
    // Outputs all or nothing, checked and their temp files created before any work.
    let mut outputs: Vec<(&str, &std::path::Path)> = Vec::new();
    outputs.extend(a.record.as_deref().map(|p| ("--record", p)));
    outputs.extend(a.screenshot.as_deref().map(|p| ("--screenshot", p)));
    outputs.extend(a.aov.as_deref().map(|p| ("--aov", p)));
    outputs.extend(a.stats.as_deref().map(|p| ("--stats", p)));
    let mut inputs: Vec<(&str, &std::path::Path)> = vec![("package", &a.package)];
    inputs.extend(a.camera_path.as_deref().map(|p| ("--camera-path", p)));
    let mut outs = crate::output::Outputs::begin(&inputs, &outputs)?;
    if let Some(p) = &a.camera_path {
        crate::output::check_input(
            "--camera-path",
            p,
            Some(crate::cmd::render::CAMERA_PATH_MAX_BYTES),
        )?;
    }
    let pkg: ScenePackage = pipeline::open(&a.package)?;
    let base = pkg.view()?;
    let meta = pkg.meta();
    let names: Vec<String> = meta.elements.iter().map(|e| e.name.clone()).collect();
    let element_ids: Vec<u32> = meta.elements.iter().map(|e| e.id).collect();
    if !a.subset.is_empty() {
        pipeline::resolve_subset(&a.subset, &names)?;
    }
    let elements_on: Vec<bool> = names
        .iter()
        .map(|n| a.subset.is_empty() || a.subset.contains(n))
        .collect();
    let replay = match &a.camera_path {
        Some(p) => Some(load_camera_path(p)?),
        None => None,
    };
    let (start, cw, ch) = camera_pose(&pkg, &base, a.camera.as_deref(), a.width, a.height)?;
    let (width, height) = match &replay {
        Some(RecordedPath {
            width: Some(w),
            height: Some(h),
            ..
        }) if a.width.is_none() && a.height.is_none() => (*w, *h),
        _ => (cw, ch),
    };
    let cameras = motu_view::scene_cameras(&pkg, &base)?;
    let backend = match a.backend {
        Some(BackendArg::Cpu) => bail!(
            "`motu view` renders on the GPU (pipeline or query); the CPU backend is `motu render --backend cpu`"
        ),
        Some(BackendArg::Query) => motu_gpu::Backend::Query,
        Some(BackendArg::Pipeline) => motu_gpu::Backend::Pipeline,
        None => {
            let devices = motu_gpu::list_devices().context("listing Vulkan devices")?;
            let ds = match a.device {
                Some(i) => devices.get(i..i + 1).unwrap_or(&[]),
                None => &devices[..],
            };
            match crate::cmd::render::best_backend(ds) {
                BackendArg::Query => motu_gpu::Backend::Query,
                BackendArg::Pipeline => motu_gpu::Backend::Pipeline,
                BackendArg::Cpu => bail!(
                    "no Vulkan device with ray tracing (`motu devices` lists them); `motu render --backend cpu` renders without one"
                ),
            }
        }
    };
    let render = motu_gpu::RenderOptions {
        backend,
        view: match a.view {
            ViewArg::Shaded => motu_gpu::View::Shaded,
            ViewArg::Ids => motu_gpu::View::Ids,
            ViewArg::Lod => motu_gpu::View::Lod,
            ViewArg::Heatmap => motu_gpu::View::Heatmap,
            ViewArg::Albedo => motu_gpu::View::Albedo,
        },
        lod: LodParams {
            forced_lod: a
                .lod
                .map(|l| l as i32)
                .unwrap_or(motu_abi::lod::LOD_NOT_FORCED),
            r_max_px: a.lod_r_max,
            stochastic: u32::from(a.lod_stochastic),
            ..LodParams::default()
        },
        stack_size: a.stack_size,
        frames: 1,
        // The scene's lights with `motu render`'s defaults (one AO ray, one sample, exposure
        // 0) and the same --ao-reach/--bounces, so a view frame equals a render of the same
        // camera.
        shading: motu_render::scene_shading(
            motu_render::ShadingOptions {
                ao_reach_of_diagonal: a.ao_reach,
                bounces: a.bounces,
                ..Default::default()
            },
            &pkg,
            &base,
        ),
        ..Default::default()
    };
    if !(a.lod_r_max.is_finite() && a.lod_r_max > 0.0) {
        bail!("--lod-r-max must be a positive number of pixels");
    }
    let frames = a.frames.or(replay.as_ref().map(|p| p.poses.len() as u32));
    let replay_poses = replay.as_ref().map(|p| {
        let n = frames.unwrap_or(p.poses.len() as u32);
        (0..n).map(|f| p.sample(f, n)).collect::<Vec<_>>()
    });
    let opts = ViewOptions {
        title: format!("motu view — {}", a.package.display()),
        width,
        height,
        start,
        cameras,
        render,
        lod_instance: a.lod_mode == LodModeArg::Instance,
        elements: names,
        elements_on,
        speed: a
            .speed
            .unwrap_or_else(|| motu_view::default_fly_speed(&base)),
        frames,
        replay: replay_poses,
        panel: a.overlay || (a.frames.is_none() && !a.no_panel),
        vsync: !a.no_vsync,
        accumulate: a.accumulate || a.frames.is_none(),
        denoise: a.denoise,
        panel_clicks: a.panel_click.clone(),
        display: None,
    };
    let meshes = PackageMeshes(&pkg);
    let settings = PackageSourceSettings {
        device_index: a.device,
        backend,
        vram_budget_bytes: a.vram_budget,
        max_allocations: a.max_allocations,
        stream: streaming.then(|| ViewStreamSettings {
            bounds: crate::cmd::render::stream_bounds(&a.stream_bounds),
            max_passes: a.stream_passes,
            frames: a.frames,
            cache: crate::cmd::render::cache_settings(&a.as_cache),
            always: a.stream_always,
        }),
    };
    let result = motu_view::run(opts, |o| {
        PackageSource::open(o, base, &meshes, element_ids, settings)
            .map_err(|e| motu_view::chain(&e))
    })
    .context("motu view")?;
    if let Some(p) = &a.record {
        let path = RecordedPath {
            poses: result.poses.clone(),
            width: Some(result.last_size[0]),
            height: Some(result.last_size[1]),
        };
        outs.write(p, path.to_json().as_bytes())?;
    }
    if a.frames.is_none() {
        outs.commit()?;
        if let Some(p) = &a.record {
            eprintln!("recorded {} frames to {}", result.poses.len(), p.display());
        }
        return Ok(());
    }
    let [w, h] = result.last_size;
    let last = result.last.as_ref().context("no frame was shown")?;
    if let Some(p) = &a.screenshot {
        let px = result.screenshot_rgba8.as_ref().context(
            "the swapchain image could not be read back (the surface does not allow TRANSFER_SRC)",
        )?;
        outs.write_png(p, w, h, px)?;
    }
    if let Some(p) = &a.aov {
        outs.write(p, &last.output.aov.to_bytes())?;
    }
    if let Some(p) = &a.stats {
        let mut ms = result.frame_ms.clone();
        ms.sort_by(f64::total_cmp);
        let stats = motu_render::stats::ViewStats {
            frame: motu_render::stats::FrameStats {
                frames: result.frames_shown,
                ..motu_render::stats::FrameStats::gpu(&last.output.stats)
            },
            wall_ms_per_frame_median: ms.get(ms.len() / 2).copied().unwrap_or(0.0),
            wall_ms_per_frame: result.frame_ms.clone(),
            window: motu_render::stats::WindowStats {
                width: w,
                height: h,
                presented_via: "swapchain",
                panel_frames: result.panel_frames,
                panel_pixels: result.panel_pixels,
            },
            vram_used_bytes: last.stats.vram_used_bytes,
            resident_structures: last.stats.resident_structures,
            total_structures: last.stats.total_structures,
            streaming: last.stats.streaming.is_some(),
            incomplete_frames: result.incomplete_frames,
            incomplete_pixels_per_frame: result.incomplete_pixels_per_frame.clone(),
            lod_mode: last.stats.lod_mode,
            accumulated_samples: result.accumulated_samples,
            denoised: result.denoised,
            stream_fit: last.stats.stream_fit.clone(),
            detail: last.detail.clone(),
            package: a.package.display().to_string(),
        };
        outs.write(p, serde_json::to_string_pretty(&stats)?.as_bytes())?;
    }
    outs.commit()?;
    if let Some(p) = &a.record {
        eprintln!("recorded {} frames to {}", result.poses.len(), p.display());
    }
    let drawn = match &last.stats.stream_fit {
        Some(f) if f.full_build => ", the full build: the budget holds the scene",
        _ if last.stats.streaming.is_some() => ", streamed",
        _ => "",
    };
    eprintln!(
        "view: {} frames shown ({}×{}, {}{drawn}), last {:.2} Mrays/s, {:.2} traces/ray",
        result.frames_shown,
        w,
        h,
        last.output.stats.backend,
        last.output.stats.rays_per_second / 1e6,
        last.output.stats.traces_per_ray
    );
    Ok(())
}
