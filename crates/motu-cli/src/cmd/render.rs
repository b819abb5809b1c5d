//! `motu render` and `motu compare`.

use crate::cli::{BackendArg, CompareArgs, LodModeArg, RenderArgs, ViewArg};
use crate::output;
use crate::pipeline;
use anyhow::{bail, Context};
use motu_abi::aov::Aov;
use motu_abi::camera::{camera_path, CameraParams};
use motu_abi::lod::LodParams;
use motu_abi::lod_instance::InstanceLod;
use motu_abi::{HierarchyView, RootSubset};
use motu_pack::ScenePackage;
use serde_json::{json, Value};

pub use motu_render::{
    camera_params, camera_pose, choose_lod_mode, load_camera_path, LodChoice, PackageMeshes,
};

/// The shaded view's lighting with `--ao-samples`, `--spp` and `--exposure`
/// ([`motu_render::scene_shading`]).
pub fn scene_shading(
    a: &RenderArgs,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
) -> motu_abi::shade::Shading {
    let o = motu_render::ShadingOptions {
        ao_samples: a.ao_samples,
        spp: a.spp,
        exposure_ev: a.exposure,
    };
    motu_render::scene_shading(o, pkg, view)
}

fn gpu_context(a: &RenderArgs, backend: BackendArg) -> anyhow::Result<motu_gpu::Context> {
    use motu_gpu::{ContextOptions, LimitOverrides, Requirement};
    motu_gpu::Context::new(&ContextOptions {
        device_index: a.device,
        limit_overrides: LimitOverrides {
            max_memory_allocation_count: a.max_allocations,
            ..Default::default()
        },
        require: match backend {
            BackendArg::Query => Requirement::RayQuery,
            _ => Requirement::RayPipeline,
        },
        ..Default::default()
    })
    .context("opening a Vulkan device for ray tracing (`motu devices` lists them; `--backend cpu` needs none)")
    .and_then(|ctx| {
        check_vram_budget(a.vram_budget, &ctx)?;
        Ok(ctx)
    })
}

/// `--vram-budget` above what the device has is a mistake (a unit typo), not a wish to clamp.
fn check_vram_budget(budget: Option<u64>, ctx: &motu_gpu::Context) -> anyhow::Result<()> {
    let Some(b) = budget else { return Ok(()) };
    let device_bytes = ctx
        .heaps()
        .iter()
        .filter(|h| h.device_local)
        .map(|h| h.size_bytes)
        .max()
        .unwrap_or(0);
    if device_bytes > 0 && b > device_bytes {
        bail!(
            "--vram-budget {} is more than {} has ({} of device-local memory): give at most {}, or omit it to use what is free",
            crate::size::format_size(b),
            ctx.device_name(),
            crate::size::format_size(device_bytes),
            crate::size::format_size(device_bytes),
        );
    }
    Ok(())
}

fn gpu_render_options(
    a: &RenderArgs,
    lod: LodParams,
    backend: BackendArg,
    frames: u32,
    shading: motu_abi::shade::Shading,
) -> motu_gpu::RenderOptions {
    motu_gpu::RenderOptions {
        backend: match backend {
            BackendArg::Query => motu_gpu::Backend::Query,
            _ => motu_gpu::Backend::Pipeline,
        },
        view: match a.view {
            ViewArg::Shaded => motu_gpu::View::Shaded,
            ViewArg::Ids => motu_gpu::View::Ids,
            ViewArg::Lod => motu_gpu::View::Lod,
            ViewArg::Heatmap => motu_gpu::View::Heatmap,
        },
        lod,
        stack_size: a.stack_size,
        max_traces_per_ray: a.max_traces_per_ray,
        frames,
        shading,
        ..Default::default()
    }
}

/// `--stream`: builds only what rays touch, evicting under the budget, frame by frame along a
/// camera path (`--frames N`; one frame renders the camera itself).
fn render_streaming(
    a: &RenderArgs,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    lod: LodParams,
    backend: BackendArg,
    recorded: Option<&[CameraParams]>,
) -> anyhow::Result<(Aov, Vec<u8>, Value)> {
    let ctx = gpu_context(a, backend)?;
    let (pose, w, h) = camera_pose(pkg, view, a.camera.as_deref(), a.width, a.height)?;
    let path = motu_render::sweep_around_root(view, &pose);
    let meshes = PackageMeshes(pkg);
    let opts = motu_gpu::StreamOptions {
        budget_bytes: a.vram_budget.unwrap_or(u64::MAX),
        max_allocations: a
            .max_allocations
            .unwrap_or(motu_gpu::StreamOptions::default().max_allocations),
        max_passes: a.stream_max_passes.unwrap_or(0),
        ..stream_bounds(&a.stream_bounds).options()
    };
    // A recorded path renders at its cameras' size, not the package camera's.
    let (w, h) = match recorded {
        Some(r) if !r.is_empty() => r
            .iter()
            .fold((0, 0), |(w, h), c| (w.max(c.width), h.max(c.height))),
        _ => (w, h),
    };
    // Refused up front below the floor: under it some frame could not complete.
    let floor = motu_gpu::streaming_floor(view, &ctx, w, h, opts.staging_bytes)
        .context("computing the streaming floor")?;
    if let Some(budget) = a.vram_budget {
        if budget < floor.min_resident_bytes {
            bail!(
                "--vram-budget {} is below the streaming floor of {} ({} bytes) for {w}×{h}: \
                 the resident skeleton ({} of tables, {} of TLASes, proxies and PI BLASes), the \
                 largest BLAS build ({}), TLAS rebuilds ({}), frame buffers ({}), shading \
                 tables and attributes ({}), staging and allocator slack; raise --vram-budget to at least the floor (`motu report` \
                 prints it as streaming.min_resident_bytes)",
                crate::size::format_size(budget),
                crate::size::format_size(floor.min_resident_bytes),
                floor.min_resident_bytes,
                crate::size::format_size(floor.tables_bytes),
                crate::size::format_size(floor.skeleton_structures_bytes),
                crate::size::format_size(floor.largest_blas_build_bytes),
                crate::size::format_size(floor.tlas_rebuild_bytes),
                crate::size::format_size(floor.frame_bytes),
                crate::size::format_size(
                    floor.shading_tables_bytes
                        + floor.shading_attributes_bytes
                        + floor.shading_textures_bytes
                ),
            );
        }
    }
    let mut sr = motu_gpu::StreamingRenderer::new(&ctx, *view, &meshes, &opts).with_context(|| {
        format!(
            "setting up streaming (the resident skeleton must fit the budget; the floor is {} bytes)",
            floor.min_resident_bytes
        )
    })?;
    let ropts = gpu_render_options(a, lod, backend, 1, scene_shading(a, pkg, view));
    if a.spp > 1 {
        eprintln!(
            "warning: --stream renders one sample per pixel (--spp {} ignored)",
            a.spp
        );
    }
    let mut frames = Vec::new();
    let mut last = None;
    let frame_count = recorded.map_or(a.frames, |r| r.len() as u32);
    for f in 0..frame_count {
        let cam = match recorded {
            Some(r) => r[f as usize],
            None => camera_path(&pose, &path, f, a.frames).params(w, h),
        };
        let (out, st) = sr
            .render_frame(&cam, &ropts)
            .with_context(|| format!("streaming frame {f}"))?;
        let why = if st.complete {
            ""
        } else if st.build_budget_spent {
            " (incomplete: frame build budget spent)"
        } else {
            " (incomplete: pass cap)"
        };
        eprintln!(
            "frame {f}: {} passes{why}, {} BLAS + {} TLAS built ({}), {} evicted, {} streamed, {:.1} ms building, VRAM {} of {}",
            st.passes,
            st.blas_built,
            st.tlas_built,
            crate::size::format_size(st.built_bytes),
            st.evicted,
            crate::size::format_size(st.bytes_streamed),
            st.build_ms,
            crate::size::format_size(st.vram_peak_bytes),
            crate::size::format_size(st.vram_budget_bytes),
        );
        if !st.complete && st.fallback_pixels > 0 {
            // Opt-in (--stream-fallback): loud and counted, refined by later frames.
            eprintln!(
                "WARNING: frame {f}: {} pixels show the coarse FALLBACK (bounds of structures not \
                 resident yet{}): this frame is not exact (--stream-fallback coarse)",
                st.fallback_pixels,
                if st.build_budget_spent {
                    "; the frame's build budget is spent"
                } else {
                    ""
                }
            );
        } else if !st.complete {
            // A wrong image never exits 0 silently.
            if !a.allow_incomplete {
                let cause = if st.build_budget_spent {
                    "its build budget (--stream-build-budget/--stream-build-ms) spent".to_string()
                } else {
                    format!("the pass cap, {}", sr.max_passes())
                };
                bail!(
                    "frame {f}: {} pixels unfinished after {} passes ({cause}): the image would be \
                     wrong; nothing written (--allow-incomplete writes it with those pixels \
                     magenta; --stream-fallback coarse shows what is missing by its bounds, \
                     counted)",
                    st.incomplete_pixels,
                    st.passes,
                );
            }
            eprintln!(
                "WARNING: frame {f}: {} pixels UNFINISHED after {} passes (pass cap): written as \
                 magenta misses (--allow-incomplete)",
                st.incomplete_pixels, st.passes
            );
        }
        frames.push(serde_json::to_value(&st)?);
        last = Some(out);
    }
    let out = last.context("no frame rendered")?;
    let mut stats = serde_json::to_value(&out.stats)?;
    // The last frame is the image written: its cut rays decide (render's common check).
    stats["truncated_rays"] = frames
        .last()
        .and_then(|f| f["truncated_rays"].as_u64())
        .map_or(json!(0), |n| json!(n));
    // The written frame's fallback pixels (not exact; 0 unless --stream-fallback).
    stats["fallback_pixels"] = frames
        .last()
        .and_then(|f| f["fallback_pixels"].as_u64())
        .map_or(json!(0), |n| json!(n));
    let totals = sr.totals();
    let after_first: Vec<f64> = frames
        .iter()
        .skip(1)
        .filter_map(|f| f["passes"].as_f64())
        .collect();
    stats["stream"] = json!({
        "frames": frames,
        "totals": totals,
        "floor": floor,
        "max_passes": sr.max_passes(),
        "mean_passes_after_first": if after_first.is_empty() { Value::Null } else { json!(after_first.iter().sum::<f64>() / after_first.len() as f64) },
    });
    drop(sr);
    ctx.check_validation()
        .context("Vulkan validation reported errors")?;
    Ok((out.aov, out.rgba8, stats))
}

/// The streaming bounds of `--stream-fallback`, `--stream-build-budget`, `--stream-build-ms`.
pub fn stream_bounds(b: &crate::cli::StreamBoundArgs) -> motu_render::StreamBounds {
    motu_render::StreamBounds {
        fallback: match b.stream_fallback {
            crate::cli::FallbackArg::Off => motu_gpu::StreamFallback::Off,
            crate::cli::FallbackArg::Coarse => motu_gpu::StreamFallback::Coarse,
        },
        frame_build_bytes: b.stream_build_budget,
        frame_build_ms: b.stream_build_ms,
    }
}

/// `--lod-mode` as the library's request.
pub(crate) fn lod_mode(m: LodModeArg) -> motu_render::LodMode {
    match m {
        LodModeArg::Instance => motu_render::LodMode::Instance,
        LodModeArg::Traversal => motu_render::LodMode::Traversal,
    }
}

/// The device and the package's structures built on it under `--vram-budget` and
/// `--max-allocations` (a full build: `render` and `render --camera-path`).
fn build_gpu_scene<'v>(
    a: &RenderArgs,
    pkg: &ScenePackage,
    view: &HierarchyView<'v>,
    backend: BackendArg,
    instance_lod: Option<&InstanceLod>,
) -> anyhow::Result<(motu_gpu::Context, motu_gpu::GpuScene)> {
    let ctx = gpu_context(a, backend)?;
    let budget = a.vram_budget.unwrap_or(u64::MAX);
    let build = motu_gpu::BuildOptions {
        budget_bytes: budget,
        max_allocations: a
            .max_allocations
            .unwrap_or(motu_gpu::BuildOptions::default().max_allocations),
        // Each half of the staging ring should hold a build batch's geometry so uploads overlap
        // builds; host-visible memory counts against the budget on unified-memory devices.
        staging_bytes: (budget / 8).clamp(4 << 20, 64 << 20),
        ..Default::default()
    };
    let meshes = PackageMeshes(pkg);
    let built = match instance_lod {
        Some(il) => il.view(view),
        None => *view,
    };
    let mut scene = motu_gpu::GpuScene::build(&ctx, &built, &meshes, &build)
        .context("building acceleration structures")?;
    if let Some(il) = instance_lod {
        scene
            .enable_instance_lod(view, il)
            .context("setting up instance-level LOD")?;
    }
    Ok((ctx, scene))
}

/// Builds the package's structures on the GPU under the budget and renders with a traversal
/// shader backend.
fn render_gpu(
    a: &RenderArgs,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    camera: &CameraParams,
    lod: LodParams,
    backend: BackendArg,
    instance_lod: Option<&InstanceLod>,
) -> anyhow::Result<(Aov, Vec<u8>, Value)> {
    let (ctx, scene) = build_gpu_scene(a, pkg, view, backend, instance_lod)?;
    let opts = gpu_render_options(a, lod, backend, a.frames, scene_shading(a, pkg, view));
    let (out, counts) =
        motu_gpu::render_counted(&ctx, &scene, camera, &opts).context("rendering on the GPU")?;
    let mut stats = serde_json::to_value(&out.stats)?;
    stats["truncated_rays"] = json!(counts.truncated_rays);
    stats["resources"] = serde_json::to_value(scene.report())?;
    lod_pass_stats(&mut stats, scene.lod_instance_passes());
    drop(scene);
    ctx.check_validation()
        .context("Vulkan validation reported errors")?;
    Ok((out.aov, out.rgba8, stats))
}

/// `--camera-path`: the frame cameras (None without a path). The image size is --width/--height,
/// else the path's recorded size, else the camera's.
fn recorded_cameras(
    a: &RenderArgs,
    camera: CameraParams,
) -> anyhow::Result<Option<Vec<CameraParams>>> {
    let Some(p) = &a.camera_path else {
        return Ok(None);
    };
    let path = load_camera_path(p)?;
    let path_size = a.width.is_none() && a.height.is_none();
    Ok(Some(motu_render::recorded_path_cameras(
        &path, &camera, path_size, a.frames,
    )))
}

/// Instance-level LOD's per-frame pass: `lod_passes` frames ran it (levels picked, slot TLASes
/// rebuilt), `lod_passes_skipped` frames did not (their camera was the one the levels were
/// built for).
fn lod_pass_stats(stats: &mut Value, [run, skipped]: [u64; 2]) {
    stats["lod_passes"] = json!(run);
    stats["lod_passes_skipped"] = json!(skipped);
}

/// A recorded camera path on a full GPU build: one frame per camera through the viewer's
/// renderer (pipeline compiled once); the last frame is the output, every frame's time is in
/// `path_ms_per_frame`.
fn render_gpu_path(
    a: &RenderArgs,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    cams: &[CameraParams],
    lod: LodParams,
    backend: BackendArg,
    instance_lod: Option<&InstanceLod>,
) -> anyhow::Result<(Aov, Vec<u8>, Value)> {
    let (ctx, scene) = build_gpu_scene(a, pkg, view, backend, instance_lod)?;
    let opts = gpu_render_options(a, lod, backend, 1, scene_shading(a, pkg, view));
    let mut live = motu_gpu::LiveRenderer::new(scene);
    let mut times = Vec::with_capacity(cams.len());
    let mut last = None;
    for (f, cam) in cams.iter().enumerate() {
        let out = live
            .render_frame(cam, &opts)
            .with_context(|| format!("rendering camera-path frame {f}"))?;
        times.push(out.stats.ms_per_frame);
        last = Some(out);
    }
    let out = last.context("empty camera path")?;
    let mut stats = serde_json::to_value(&out.stats)?;
    // The first frame is a warm-up (pipeline first use): left out of the median.
    let timed = if times.len() > 1 {
        &times[1..]
    } else {
        &times[..]
    };
    let mut timed = timed.to_vec();
    timed.sort_by(f64::total_cmp);
    stats["ms_per_frame"] = json!(timed[timed.len() / 2]);
    stats["frames"] = json!(cams.len());
    stats["path_ms_per_frame"] = json!(times);
    stats["resources"] = serde_json::to_value(live.scene().report())?;
    lod_pass_stats(&mut stats, live.scene().lod_instance_passes());
    drop(live);
    ctx.check_validation()
        .context("Vulkan validation reported errors")?;
    Ok((out.aov, out.rgba8, stats))
}

/// The CPU reference with instance-level LOD: per camera, each slot's level from the same rule
/// as the GPU's compute pass, then a trace of the rewritten hierarchy.
fn render_cpu_instance_lod(
    a: &RenderArgs,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    lod: LodParams,
    instance_lod: Option<&InstanceLod>,
    camera: CameraParams,
    recorded: &Option<Vec<CameraParams>>,
) -> anyhow::Result<(Aov, Vec<u8>, Value)> {
    let il = instance_lod.context("instance LOD")?;
    let meshes = PackageMeshes(pkg);
    let opts = motu_trace::RenderOptions {
        view: view_name(a.view).parse().map_err(anyhow::Error::msg)?,
        lod,
        max_traces_per_ray: a.max_traces_per_ray,
        shading: scene_shading(a, pkg, view),
        ..Default::default()
    };
    let cams = recorded
        .clone()
        .unwrap_or_else(|| vec![camera; a.frames as usize]);
    let (out, median_ms) = motu_render::render_cpu_instance_lod(view, &meshes, il, &opts, &cams)?;
    let mut stats = serde_json::to_value(&out.stats)?;
    stats["ms_per_frame"] = json!(median_ms);
    stats["frames"] = json!(cams.len());
    Ok((out.aov, out.rgba8, stats))
}

/// `query` where a device has ray queries (usually fastest on RTX), else `pipeline`, else the CPU.
pub fn best_backend(devices: &[motu_gpu::DeviceReport]) -> BackendArg {
    if devices.iter().any(|d| d.ray_query) {
        BackendArg::Query
    } else if devices.iter().any(|d| d.ray_pipeline) {
        BackendArg::Pipeline
    } else {
        BackendArg::Cpu
    }
}

fn view_name(v: ViewArg) -> &'static str {
    match v {
        ViewArg::Shaded => "shaded",
        ViewArg::Heatmap => "heatmap",
        ViewArg::Lod => "lod",
        ViewArg::Ids => "ids",
    }
}

/// Adds the contract's keys to a backend's stats object.
fn contract_stats(mut stats: Value, extra: Value) -> Value {
    if let (Some(s), Some(e)) = (stats.as_object_mut(), extra.as_object()) {
        for (k, v) in e {
            s.entry(k.clone()).or_insert(v.clone());
        }
    }
    stats
}

pub fn run(a: RenderArgs) -> anyhow::Result<()> {
    let mut outputs = vec![("-o", a.output.as_path())];
    outputs.extend(a.aov.as_deref().map(|p| ("--aov", p)));
    outputs.extend(a.stats.as_deref().map(|p| ("--stats", p)));
    output::check_outputs(&[("package", &a.package)], &outputs)?;
    let pkg = pipeline::open(&a.package)?;
    let base = pkg.view()?;
    let names: Vec<String> = pkg.meta().elements.iter().map(|e| e.name.clone()).collect();
    let subset = if a.subset.is_empty() {
        None
    } else {
        pipeline::resolve_subset(&a.subset, &names)?;
        // Records hold the imported scene's element ids; `meta` maps names to them.
        let keep: Vec<u32> = pkg
            .meta()
            .elements
            .iter()
            .filter(|e| a.subset.contains(&e.name))
            .map(|e| e.id)
            .collect();
        Some(
            RootSubset::new(&base, |e| keep.contains(&e))
                .context("filtering the root for --subset")?,
        )
    };
    let view = match &subset {
        Some(s) => s.view(&base),
        None => base,
    };
    let mut camera = camera_params(&pkg, &view, a.camera.as_deref(), a.width, a.height)?;
    // `--camera-path`: the recorded poses over --frames frames (default: one per pose).
    let recorded = recorded_cameras(&a, camera)?;
    if let Some(r) = &recorded {
        camera = *r.last().context("empty camera path")?;
    }
    let lod = LodParams {
        forced_lod: a
            .lod
            .map(|l| l as i32)
            .unwrap_or(motu_abi::lod::LOD_NOT_FORCED),
        r_max_px: a.lod_r_max,
        shadow_bias: a.shadow_lod_bias,
        stochastic: u32::from(a.lod_stochastic),
    };
    let r_max_ok = a.lod_r_max.is_finite() && a.lod_r_max > 0.0;
    let bias_ok = a.shadow_lod_bias.is_finite() && a.shadow_lod_bias >= 0.0;
    if !r_max_ok || !bias_ok {
        bail!("--lod-r-max must be a positive number of pixels and --shadow-lod-bias ≥ 0");
    }
    let backend = match a.backend {
        Some(b) => b,
        None => match motu_gpu::list_devices() {
            Ok(devices) => match a.device {
                Some(i) => best_backend(std::slice::from_ref(device_at(&devices, i)?)),
                None => best_backend(&devices),
            },
            Err(e) if a.device.is_some() => {
                return Err(anyhow::Error::new(e).context(format!(
                    "--device {} (or MOTU_DEVICE): no Vulkan device can be listed",
                    a.device.unwrap_or(0)
                )))
            }
            Err(e) => {
                eprintln!("warning: no Vulkan ray-tracing device ({e}); rendering on the CPU");
                BackendArg::Cpu
            }
        },
    };
    if backend == BackendArg::Cpu && a.backend.is_none() {
        eprintln!("warning: no device with ray tracing; rendering with the CPU reference backend");
    }
    if a.stream && backend == BackendArg::Cpu {
        bail!("--stream builds acceleration structures on a GPU: use --backend pipeline or query");
    }
    if !a.stream && stream_bounds(&a.stream_bounds).given() {
        bail!(
            "--stream-fallback, --stream-build-budget and --stream-build-ms bound streaming \
             frames: add --stream (with --vram-budget)"
        );
    }
    if a.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if !a.exposure.is_finite() {
        bail!("--exposure must be a finite number of stops");
    }
    let LodChoice {
        instance: instance_lod,
        mode: lod_mode,
        reason: lod_mode_reason,
        selector_pis,
    } = choose_lod_mode(&view, &lod, lod_mode(a.lod_mode), a.stream)?;
    if lod_mode == "traversal" && a.lod_mode == LodModeArg::Instance && a.lod_stochastic | a.stream
    {
        eprintln!("note: LOD runs in traversal mode: {lod_mode_reason}");
    }
    let (aov, rgba8, stats): (Aov, Vec<u8>, Value) = match backend {
        BackendArg::Cpu if instance_lod.is_some() => render_cpu_instance_lod(
            &a,
            &pkg,
            &view,
            lod,
            instance_lod.as_ref(),
            camera,
            &recorded,
        )?,
        BackendArg::Cpu => {
            let meshes = PackageMeshes(&pkg);
            let tracer =
                motu_trace::Tracer::new(view, &meshes).context("preparing the CPU tracer")?;
            let opts = motu_trace::RenderOptions {
                view: view_name(a.view).parse().map_err(anyhow::Error::msg)?,
                lod,
                max_traces_per_ray: a.max_traces_per_ray,
                shading: scene_shading(&a, &pkg, &view),
                ..Default::default()
            };
            let cams = recorded
                .clone()
                .unwrap_or_else(|| vec![camera; a.frames as usize]);
            let mut out = motu_trace::render_with(&tracer, &cams[0], &opts)
                .context("rendering on the CPU")?;
            let mut times = vec![out.stats.ms_per_frame];
            for cam in &cams[1..] {
                let o = motu_trace::render_with(
                    &tracer,
                    cam,
                    &motu_trace::RenderOptions {
                        prepare: false,
                        ..opts
                    },
                )?;
                times.push(o.stats.ms_per_frame);
                out = o;
            }
            times.sort_by(f64::total_cmp);
            let median = times[times.len() / 2];
            let mut stats = serde_json::to_value(&out.stats)?;
            stats["ms_per_frame"] = json!(median);
            stats["frames"] = json!(cams.len());
            (out.aov, out.rgba8, stats)
        }
        BackendArg::Pipeline | BackendArg::Query if a.stream => {
            render_streaming(&a, &pkg, &view, lod, backend, recorded.as_deref())?
        }
        BackendArg::Pipeline | BackendArg::Query if recorded.is_some() => {
            let cams = recorded.as_deref().unwrap_or_default();
            render_gpu_path(&a, &pkg, &view, cams, lod, backend, instance_lod.as_ref())?
        }
        BackendArg::Pipeline | BackendArg::Query => render_gpu(
            &a,
            &pkg,
            &view,
            &camera,
            lod,
            backend,
            instance_lod.as_ref(),
        )?,
    };
    let mut stats = stats;
    stats["lod_mode"] = json!(lod_mode);
    stats["lod_mode_reason"] = json!(lod_mode_reason);
    stats["lod_instances"] = json!(instance_lod.as_ref().map_or(0, |il| il.slots.len()));
    stats["lod_traversal_selectors"] = json!(instance_lod
        .as_ref()
        .map_or(selector_pis, |il| il.traversal_selectors));
    let stats = contract_stats(
        stats,
        json!({
            "backend": match backend { BackendArg::Cpu => "cpu", BackendArg::Pipeline => "pipeline", BackendArg::Query => "query" },
            "view": view_name(a.view),
            "vram_budget_bytes": a.vram_budget.unwrap_or(0),
            "vram_peak_bytes": 0,
            "allocation_count": 0,
            "as_bytes": 0,
            "passes": 1,
            "subset": a.subset,
            "package": a.package.display().to_string(),
        }),
    );
    // A truncated traversal is a wrong image: an error unless explicitly allowed.
    let truncated = stats["truncated_rays"].as_u64().unwrap_or(0);
    let overflows = stats["stack_overflows"].as_u64().unwrap_or(0);
    if truncated > 0 || overflows > 0 {
        let what = format!(
            "{truncated} ray(s) were cut short ({overflows} traversal stack overflows with --stack-size {}; --max-traces-per-ray {}): their hits may be wrong (exponentially deep instancing?)",
            a.stack_size, a.max_traces_per_ray
        );
        if !a.allow_truncated {
            bail!("{what}; nothing was written. Raise --stack-size/--max-traces-per-ray, or pass --allow-truncated to write the image anyway");
        }
        eprintln!("warning: {what}; written anyway (--allow-truncated)");
    }
    output::write_png(&a.output, camera.width, camera.height, &rgba8)?;
    if let Some(p) = &a.aov {
        output::write(p, &aov.to_bytes())?;
    }
    if let Some(p) = &a.stats {
        output::write(p, serde_json::to_string_pretty(&stats)?.as_bytes())?;
    }
    eprintln!(
        "rendered {} ({}×{}, {}): {:.1} ms/frame, {:.2} Mrays/s, {:.2} traces/ray",
        a.output.display(),
        camera.width,
        camera.height,
        stats["backend"].as_str().unwrap_or("?"),
        stats["ms_per_frame"].as_f64().unwrap_or(0.0),
        stats["rays_per_second"].as_f64().unwrap_or(0.0) / 1e6,
        stats["traces_per_ray"].as_f64().unwrap_or(0.0),
    );
    Ok(())
}

pub fn compare(a: CompareArgs) -> anyhow::Result<()> {
    if let Some(p) = &a.diff {
        output::check_outputs(&[("A", &a.a), ("B", &a.b)], &[("--diff", p)])?;
    }
    let x = Aov::load(&a.a).with_context(|| format!("reading {}", a.a.display()))?;
    let y = Aov::load(&a.b).with_context(|| format!("reading {}", a.b.display()))?;
    let r = motu_trace::compare(&x, &y, a.depth_epsilon).context("comparing")?;
    if let Some(p) = &a.diff {
        output::write_png(p, x.width, x.height, &r.diff_rgba8)?;
    }
    let ok = r.fraction <= a.max_mismatch;
    if a.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&json!({
                "mismatched": r.mismatched, "total": r.total, "fraction": r.fraction,
                "bbox": r.bbox, "max_mismatch": a.max_mismatch, "pass": ok,
            }))?
        );
    } else {
        let bbox = r
            .bbox
            .map(|b| format!(" in [{}, {}]–[{}, {}]", b[0], b[1], b[2], b[3]))
            .unwrap_or_default();
        println!(
            "mismatch {:.6} ({} of {} pixels){bbox}",
            r.fraction, r.mismatched, r.total
        );
    }
    if !ok {
        bail!(
            "mismatch fraction {:.6} is above --max-mismatch {}",
            r.fraction,
            a.max_mismatch
        );
    }
    Ok(())
}

/// Device `index` of `devices`, or an error naming the bad index and the devices there are.
pub fn device_at(
    devices: &[motu_gpu::DeviceReport],
    index: usize,
) -> anyhow::Result<&motu_gpu::DeviceReport> {
    devices.get(index).with_context(|| {
        let list: Vec<String> = devices
            .iter()
            .enumerate()
            .map(|(i, d)| format!("{i}: {}", d.name))
            .collect();
        format!(
            "--device {index} (or MOTU_DEVICE={index}): no such device; this machine has {} ({}); `motu devices` lists them",
            devices.len(),
            if list.is_empty() { "none".to_string() } else { list.join(", ") }
        )
    })
}
