//! `motu bench --camera-path FILE --package PKG`: a recorded flight (`motu view --record`) as a
//! benchmark: the structures are built once, then every frame of the path is rendered through
//! the viewer's renderer; GPU times per frame (timestamps) after untimed warm-up frames.

use crate::error::{gpu_err, BenchError};
use crate::plan::{best_backend, Backend};
use motu_render::{PackageMeshes, StreamBounds};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// `motu bench --camera-path FILE --package PKG`'s options.
#[derive(Clone, Debug)]
pub struct FlightOptions {
    pub package: PathBuf,
    pub camera_path: PathBuf,
    /// Image size; default: the path's recorded size, else the camera's.
    pub width: Option<u32>,
    pub height: Option<u32>,
    /// Frames along the path; default: one per recorded pose.
    pub frames: Option<u32>,
    /// Untimed warm-up frames; default 3.
    pub warmup: Option<u32>,
    pub backend: Option<Backend>,
    /// Fly through the streaming renderer (also with `vram_budget`).
    pub stream: bool,
    pub vram_budget: Option<u64>,
    pub stream_bounds: StreamBounds,
    /// How the frames are lit (`--ao-reach`, `--bounces`); default: `motu render`'s.
    pub shading: motu_render::ShadingOptions,
    /// Streaming: build–trace passes per frame (`--stream-passes`, as `motu view`'s). `Some(1)`:
    /// the viewer's flying mode, `render_progressive` (one trace with what is resident, then
    /// one build step toward the next frame; 30 ms of building when no build bound is given,
    /// as the viewer). `None`: `render_frame` under the default pass cap.
    pub stream_passes: Option<u32>,
    /// Streaming: the camera each frame names as the next one (its probe and prefetch).
    pub next_camera: NextCamera,
    /// Streaming: the path's last pose rendered this many more times after the path (a camera
    /// come to rest): the report says after how many of them a frame was complete.
    pub still_frames: u32,
}

/// The camera a streaming flight's frame names as the next one (`--next-camera`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum NextCamera {
    /// The path's next pose, known in a recorded flight (none after the last frame).
    #[default]
    Path,
    /// The viewer's guess (`motu view`): the camera one more step along the motion from the
    /// previous frame's (`CameraParams::extrapolated_from`, the camera itself at rest); none on the first frame, the camera
    /// itself while it stays where it was.
    Extrapolated,
}

impl NextCamera {
    pub fn name(self) -> &'static str {
        match self {
            NextCamera::Path => "path",
            NextCamera::Extrapolated => "extrapolated",
        }
    }
}

/// A measured flight: the JSON report and the text the CLI prints without `--json`.
#[derive(Clone, Debug)]
pub struct Flight {
    pub report: Value,
    /// Lines, each ending in a newline.
    pub text: String,
}

fn percentile(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return 0.0;
    }
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i.min(sorted.len() - 1)]
}

/// Builds the structures once (or streams them), renders every frame of the path after untimed
/// warm-up frames, and reports GPU times per frame.
pub fn run_flight(a: &FlightOptions) -> Result<Flight, BenchError> {
    // Before any work: the streaming-only options need streaming.
    let streaming = a.stream || a.vram_budget.is_some();
    if !streaming
        && (a.stream_passes.is_some() || a.next_camera != NextCamera::Path || a.still_frames > 0)
    {
        bail!("--stream-passes, --next-camera and --still-frames need --stream");
    }
    if a.stream_passes == Some(0) {
        bail!("--stream-passes must be at least 1 (1: the viewer's flying mode)");
    }
    let (package, path_file) = (a.package.as_path(), a.camera_path.as_path());
    let path = motu_render::load_camera_path(path_file)?;
    let pkg = motu_pack::ScenePackage::open(package).map_err(|source| BenchError::Package {
        what: format!("opening package {}", package.display()),
        source,
    })?;
    let view = pkg.view().map_err(BenchError::PackageData)?;
    let base = motu_render::camera_params(&pkg, &view, None, None, None)?;
    let (w, h) = match (a.width, a.height, path.width, path.height) {
        (Some(w), Some(h), _, _) => (w, h),
        (None, None, Some(w), Some(h)) => (w, h),
        _ => (base.width, base.height),
    };
    let n = a.frames.unwrap_or(path.poses.len() as u32).max(1);
    let warmup = a.warmup.unwrap_or(3);
    let backend = match a.backend {
        Some(Backend::Cpu) => {
            bail!("a flight benchmark runs on the GPU (--backend pipeline or query)")
        }
        Some(b) => b,
        None => best_backend(&motu_gpu::list_devices().map_err(|e| BenchError::Devices(e.into()))?),
    };
    let gpu_backend = match backend {
        Backend::Query => motu_gpu::Backend::Query,
        Backend::Pipeline => motu_gpu::Backend::Pipeline,
        Backend::Cpu => bail!("no Vulkan device with ray tracing (`motu devices`)"),
    };
    let ctx = motu_gpu::Context::new(&motu_gpu::ContextOptions {
        require: match gpu_backend {
            motu_gpu::Backend::Query => motu_gpu::Requirement::RayQuery,
            motu_gpu::Backend::Pipeline => motu_gpu::Requirement::RayPipeline,
        },
        ..Default::default()
    })
    .map_err(gpu_err(
        "opening a Vulkan device for ray tracing (`motu devices` lists them)",
    ))?;
    let meshes = PackageMeshes(&pkg);
    // Lit like `motu render`'s shaded view with the same options (its default AO ray
    // included), so a flight's frames cost what rendered frames cost.
    let shading = motu_render::scene_shading(a.shading, &pkg, &view);
    if streaming {
        return run_streaming(
            a,
            package,
            path_file,
            &path,
            &view,
            &meshes,
            &ctx,
            (gpu_backend, shading),
            (w, h, n, warmup),
        );
    }
    if a.stream_bounds.given() {
        bail!(
            "--stream-fallback, --stream-build-budget, --stream-build-ms and --stream-probe need \
             --stream"
        );
    }
    let scene = motu_gpu::GpuScene::build(&ctx, &view, &meshes, &motu_gpu::BuildOptions::default())
        .map_err(gpu_err("building acceleration structures"))?;
    let build_ms = scene.report().build_ms;
    let mut live = motu_gpu::LiveRenderer::new(scene);
    let opts = motu_gpu::RenderOptions {
        backend: gpu_backend,
        shading,
        ..Default::default()
    };
    let cams: Vec<_> = (0..n).map(|f| path.sample(f, n).params(w, h)).collect();
    for _ in 0..warmup {
        live.render_frame(&cams[0], &opts)
            .map_err(gpu_err("warm-up frame"))?;
    }
    let mut ms = Vec::with_capacity(cams.len());
    let mut mrays = Vec::with_capacity(cams.len());
    let mut traces = 0f64;
    for (f, cam) in cams.iter().enumerate() {
        let out = live
            .render_frame(cam, &opts)
            .map_err(|source| BenchError::GpuFrame {
                what: format!("flight frame {f}"),
                source,
            })?;
        ms.push(out.stats.ms_per_frame);
        mrays.push(out.stats.rays_per_second / 1e6);
        traces += out.stats.traces_per_ray;
    }
    drop(live);
    ctx.check_validation()
        .map_err(gpu_err("Vulkan validation reported errors"))?;
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
    // Writing to a String cannot fail.
    let mut text = String::new();
    {
        let _ = writeln!(
            text,
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
    Ok(Flight { report, text })
}

/// A flight through the streaming renderer: per-frame rows (passes, bytes built, build and
/// trace ms, GPU ms, fallback pixels, where the frame's time went) and their means. Warm-up
/// frames run on a renderer that is then dropped, so the timed flight starts with nothing
/// resident, as a user's would. `--stream-passes 1` renders each frame as the viewer flies
/// (`render_progressive`); `--still-frames K` repeats the last pose K times after the path.
#[allow(clippy::too_many_arguments)]
fn run_streaming(
    a: &FlightOptions,
    package: &Path,
    path_file: &Path,
    path: &motu_abi::camera::RecordedPath,
    view: &motu_abi::HierarchyView<'_>,
    meshes: &PackageMeshes<'_>,
    ctx: &motu_gpu::Context,
    (backend, shading): (motu_gpu::Backend, motu_abi::shade::Shading),
    (w, h, n, warmup): (u32, u32, u32, u32),
) -> Result<Flight, BenchError> {
    let progressive = a.stream_passes == Some(1);
    let bounded = opts_with_passes(a);
    let opts = motu_gpu::StreamOptions {
        budget_bytes: a.vram_budget.unwrap_or(u64::MAX),
        ..bounded
    };
    let ropts = motu_gpu::RenderOptions {
        backend,
        shading,
        ..Default::default()
    };
    let mut cams: Vec<_> = (0..n).map(|f| path.sample(f, n).params(w, h)).collect();
    // A camera come to rest: the last pose again, as a viewer's still frames.
    let rest = cams[cams.len() - 1];
    cams.extend(std::iter::repeat_n(rest, a.still_frames as usize));
    // The hierarchy the streamer renders (large TLASes split into pieces; the split the import
    // stored when `view` is the package's own), as `render --stream`.
    let (cap, _) = motu_render::package_split_cap(meshes.0, a.stream_bounds.split_instances);
    let split = motu_render::package_stream_split(meshes.0, view, cap)?;
    let view = &split.as_ref().map_or(*view, |s| s.view(view));
    // The viewer's flying mode traces once and builds toward the next frame.
    let frame = |sr: &mut motu_gpu::StreamingRenderer<'_>, cam: &motu_abi::camera::CameraParams| {
        if progressive {
            sr.render_progressive(cam, &ropts)
        } else {
            sr.render_frame(cam, &ropts)
        }
    };
    if warmup > 0 {
        let mut sr = motu_gpu::StreamingRenderer::new(ctx, *view, meshes, &opts).map_err(
            gpu_err("setting up streaming (the resident skeleton must fit the budget)"),
        )?;
        for _ in 0..warmup {
            frame(&mut sr, &cams[0]).map_err(gpu_err("warm-up frame"))?;
        }
    }
    let mut sr = motu_gpu::StreamingRenderer::new(ctx, *view, meshes, &opts).map_err(gpu_err(
        "setting up streaming (the resident skeleton must fit the budget)",
    ))?;
    let mut rows = Vec::with_capacity(cams.len());
    for (f, cam) in cams.iter().enumerate() {
        let t0 = std::time::Instant::now();
        // Each frame ends with a probe of the camera it names as the next one (prefetch): the
        // path's next pose, or the viewer's extrapolation of the motion (the camera itself while still).
        let next = match a.next_camera {
            NextCamera::Path => cams.get(f + 1).copied(),
            NextCamera::Extrapolated => f.checked_sub(1).map(|p| cam.extrapolated_from(&cams[p])),
        };
        sr.set_next_camera(next);
        let (out, st) = frame(&mut sr, cam).map_err(|source| BenchError::GpuFrame {
            what: format!("flight frame {f}"),
            source,
        })?;
        let wall_ms = t0.elapsed().as_secs_f64() * 1e3;
        rows.push(stream_row(
            f,
            &st,
            out.stats.ms_per_frame,
            wall_ms,
            next.is_some(),
        ));
    }
    let totals = sr.totals();
    drop(sr);
    ctx.check_validation()
        .map_err(gpu_err("Vulkan validation reported errors"))?;
    // The means are the path's frames' (the still tail has its own count below).
    let moving = &rows[..n as usize];
    let still = &rows[n as usize..];
    let mean = |key: &str, skip: usize| -> f64 {
        let v: Vec<f64> = moving
            .iter()
            .skip(skip)
            .filter_map(|r| r[key].as_f64())
            .collect();
        if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let sorted = |key: &str, skip: usize| -> Vec<f64> {
        let mut v: Vec<f64> = moving
            .iter()
            .skip(skip)
            .filter_map(|r| r[key].as_f64())
            .collect();
        v.sort_by(f64::total_cmp);
        v
    };
    let incomplete = moving.iter().filter(|r| r["complete"] == false).count();
    // Frames of the still tail until one is complete (1: the first still frame); None: none.
    let still_to_complete = still
        .iter()
        .position(|r| r["complete"] == true)
        .map(|i| i + 1);
    let wall_after_first = sorted("wall_ms", 1);
    let mut report = json!({
        "kind": "flight-stream",
        "package": package.display().to_string(),
        "camera_path": path_file.display().to_string(),
        "device": ctx.device_name(),
        "backend": backend_name(backend),
        "width": w,
        "height": h,
        "frames": n,
        "warmup_frames": warmup,
        "vram_budget_bytes": totals.vram_budget_bytes,
        "vram_peak_bytes": totals.vram_peak_bytes,
        "mean_passes": mean("passes", 0),
        "mean_passes_after_first": mean("passes", 1),
        "mean_built_bytes": mean("built_bytes", 0),
        "mean_built_bytes_after_first": mean("built_bytes", 1),
        "mean_build_ms": mean("build_ms", 0),
        "mean_tlas_ms": mean("tlas_ms", 0),
        "tlas_mode": totals.tlas_mode,
        "tlas_records_mode": totals.tlas_records_mode,
        "tlas_records_kept_bytes": totals.tlas_records_kept_bytes,
        "mesh_memory": totals.mesh_memory,
        "host_mesh_peak_bytes": totals.host_mesh_peak_bytes,
        "mean_trace_ms": mean("trace_ms", 0),
        "mean_probe_ms": mean("probe_ms", 0),
        "mean_wall_ms": mean("wall_ms", 0),
        "mean_wall_ms_after_first": mean("wall_ms", 1),
        "incomplete_frames": incomplete,
        "fallback_pixels": totals.fallback_pixels,
        "totals": motu_render::stats::StreamTotals::from(&totals),
        "per_frame": rows,
    });
    // One object more: `json!` nests too deep for one.
    let mode = json!({
        // How frames were rendered: `progressive` is the viewer's flying mode
        // (`--stream-passes 1`), else `render_frame` under `max_passes`.
        "stream_passes": a.stream_passes,
        "progressive": progressive,
        "max_passes": opts.max_passes,
        "frame_build_ms": opts.frame_build_ms,
        "frame_build_bytes": opts.frame_build_bytes,
        "frame_ms": opts.frame_ms,
        "next_camera": a.next_camera.name(),
        // Of the path's frames after the first (the cold start): what a flight's frames cost.
        "median_wall_ms_after_first": percentile(&wall_after_first, 0.5),
        "p95_wall_ms_after_first": percentile(&wall_after_first, 0.95),
        "median_frame_ms_after_first": percentile(&sorted("frame_ms", 1), 0.5),
        "median_fallback_pixels": percentile(&sorted("fallback_pixels", 0), 0.5),
        "still_frames": a.still_frames,
        "still_frames_to_complete": still_to_complete,
    });
    if let (Value::Object(r), Value::Object(m)) = (&mut report, mode) {
        r.extend(m);
    }
    // Writing to a String cannot fail.
    let mut text = String::new();
    {
        let _ = writeln!(
            text,
            "streaming flight {} on {} ({}, {}×{}, budget {}): {} frames{}, {}",
            path_file.display(),
            ctx.device_name(),
            backend_name(backend),
            w,
            h,
            motu_report::format_size(totals.vram_budget_bytes),
            n,
            match a.still_frames {
                0 => String::new(),
                k => format!(" + {k} still"),
            },
            if progressive {
                "one pass a frame (the viewer's flying mode)"
            } else {
                "passes until complete or the build budget is spent"
            },
        );
        text.push_str(&frame_table(&rows));
        let _ = writeln!(
            text,
            "mean: {:.3} passes ({:.3} after the first frame), {} built, {:.2} ms building, {:.2} ms tracing, {:.2} ms wall per frame; {} frames incomplete",
            mean("passes", 0),
            mean("passes", 1),
            motu_report::format_size(mean("built_bytes", 0) as u64),
            mean("build_ms", 0),
            mean("trace_ms", 0),
            mean("wall_ms", 0),
            incomplete
        );
        let _ = writeln!(
            text,
            "after the first frame: median {:.2} ms, p95 {:.2} ms wall; median fallback {} px",
            percentile(&wall_after_first, 0.5),
            percentile(&wall_after_first, 0.95),
            percentile(&sorted("fallback_pixels", 0), 0.5),
        );
        if a.still_frames > 0 {
            let _ = writeln!(
                text,
                "at rest: {}",
                match still_to_complete {
                    Some(k) => format!("complete after {k} of {} still frames", a.still_frames),
                    None => format!("not complete after {} still frames", a.still_frames),
                }
            );
        }
    }
    Ok(Flight { report, text })
}

/// The stream options of `a` with its pass cap: `--stream-passes N` as the viewer takes it
/// (`N` passes; 1 also gives a flying frame the viewer's build budget when none is given).
fn opts_with_passes(a: &FlightOptions) -> motu_gpu::StreamOptions {
    let o = a.stream_bounds.options();
    let b = &a.stream_bounds;
    motu_gpu::StreamOptions {
        max_passes: a.stream_passes.unwrap_or(o.max_passes),
        frame_build_ms: if a.stream_passes == Some(1) && b.build_unbounded() {
            motu_render::INTERACTIVE_BUILD_MS
        } else {
            o.frame_build_ms
        },
        ..o
    }
}

/// One streaming frame's row: what it built and evicted, and where its time went.
fn stream_row(
    f: usize,
    st: &motu_gpu::FrameStreamStats,
    gpu_ms: f64,
    wall_ms: f64,
    next_camera: bool,
) -> Value {
    let first = st.pass_log.first();
    let mut row = json!({
        "frame": f,
        "passes": st.passes,
        "complete": st.complete,
        "incomplete_pixels": st.incomplete_pixels,
        "fallback_pixels": st.fallback_pixels,
        "build_budget_spent": st.build_budget_spent,
        "built_bytes": st.built_bytes,
        "bytes_streamed": st.bytes_streamed,
        "blas_built": st.blas_built,
        "evicted": st.evicted,
        "evicted_bytes": st.evicted_bytes,
        "evicted_for_tlas": st.evicted_for_tlas,
        "evicted_on_refusal": st.evicted_on_refusal,
        "build_ms": st.build_ms,
        // Of build_ms: TLAS rebuilds, or updates of persistent TLASes (`--stream-tlas`).
        "tlas_ms": st.tlas_ms,
        "tlas_builds": st.tlas_builds,
        "tlas_updates": st.tlas_updates,
        "trace_ms": st.trace_ms,
        "probe_rays": st.probe_rays,
        "probe_ms": st.probe_ms,
        "probe_rounds": st.probe_rounds,
        "probe_verify_rounds": st.probe_verify_rounds,
        // Pass marks (`--stream-probe-pass-rows`, auto by default): the probe's row
        // stride (0: none) and the resident structures its rows passed and refreshed.
        "probe_pass_rows": st.probe_pass_rows,
        "probe_pass_marks": st.probe_pass_marks,
        // What of the resident set the probe's rays used: the next frame's one-pass need
        // when everything is resident and every row marks.
        "probe_need_blases": st.probe_need_blases,
        "probe_need_bytes": st.probe_need_bytes,
        "probe_need_mesh_bytes": st.probe_need_mesh_bytes,
        "wall_ms": wall_ms,
        "gpu_ms": gpu_ms,
        "vram_peak_bytes": st.vram_peak_bytes,
        // Meshes in host memory outside the budget (`--stream-mesh-memory`).
        "resident_host_mesh_bytes": st.resident_host_mesh_bytes,
        // Above the room, the frame's rays cannot all be served in one pass.
        "working_set_bytes": st.working_set_bytes,
        "working_set_mesh_bytes": st.working_set_mesh_bytes,
        "room_bytes": st.room_bytes,
        // Why the first pass missed what it needed (another pass follows).
        "first_pass_missed_evicted": st.first_pass_missed_evicted,
        "first_pass_missed_unprobed": st.first_pass_missed_unprobed,
        "first_pass_missed_probed": st.first_pass_missed_probed,
        // What the prefetch built, and what it wanted but found no room for.
        "prefetched": st.prefetched,
        "prefetch_skipped": st.prefetch_skipped,
    });
    // Where the frame's time went (one object more: `json!` nests too deep for one).
    let phases = json!({
        // TLASes (split roots' pieces) rebuilt, and the queue submissions and fence waits of
        // those rebuilds (of `submits` and `fence_waits`: every one of the frame).
        "tlas_rebuilt": st.tlas_rebuilt,
        "tlas_submits": st.tlas_submits,
        "tlas_fence_waits": st.tlas_fence_waits,
        "submits": st.submits,
        "fence_waits": st.fence_waits,
        // Rebuilds run in groups (a split root piece by piece): their transient is one
        // group's.
        "tlas_rebuild_groups": st.tlas_rebuild_groups,
        "tlas_rebuild_transient_bytes": st.tlas_rebuild_transient_bytes,
        // The renderer's own clock of the frame (wall_ms adds the image's conversion), its
        // host work outside traces and builds, and of build_ms: meshes streamed, BLAS builds,
        // the per-step tables.
        "frame_ms": st.frame_ms,
        "host_ms": st.host_ms,
        "mesh_ms": st.mesh_ms,
        // Of mesh_ms: allocations, prepare, reads, mapped copies, staged copies
        // (`scene/upload/group.rs`); bytes, new memory blocks, page faults.
        "mesh_alloc_ms": st.mesh_alloc_ms,
        "mesh_prepare_ms": st.mesh_prepare_ms,
        "mesh_read_ms": st.mesh_read_ms,
        "mesh_copy_ms": st.mesh_copy_ms,
        "mesh_staged_ms": st.mesh_staged_ms,
        "mesh_upload_bytes": st.mesh_upload_bytes,
        "mesh_blocks_created": st.mesh_blocks_created,
        "mesh_block_bytes_created": st.mesh_block_bytes_created,
        "mesh_blocks_from_spare": st.mesh_blocks_from_spare,
        "mesh_read_faults": st.mesh_read_faults,
        "mesh_copy_faults": st.mesh_copy_faults,
        "mesh_chunk_decodes": st.mesh_chunk_decodes,
        "mesh_chunk_checks": st.mesh_chunk_checks,
        "mesh_chunk_checked_bytes": st.mesh_chunk_checked_bytes,
        "blas_ms": st.blas_ms,
        "tables_ms": st.tables_ms,
        "build_steps": st.build_steps,
        "build_groups": st.build_groups,
        // The first pass: its trace, and the mark walks of its rays left open (a progressive
        // frame's one pass is last but its build budget is not yet spent, so it marks).
        "first_pass_trace_ms": first.map_or(0.0, |p| p.trace_ms),
        "mark_walks": first.map_or(0, |p| p.mark_walks),
        "mark_tlas_walks": first.map_or(0, |p| p.mark_tlas_walks),
        // Counting mode only (MOTU_PROXY_TESTS=count; else null): the first pass's proxy
        // work by ray kind and outcome.
        "first_pass_proxy_calls": first.map_or(Value::Null, proxy_calls_json),
        // The frame named a next camera (a probe of it follows a complete frame).
        "next_camera": next_camera,
        // On the clock while moving: build queues stopped at the free room (nothing is
        // evicted), and a complete frame's probe the clock had no room for.
        "flying_no_room": st.flying_no_room,
        "probe_skipped_clock": st.probe_skipped_clock,
    });
    if let (Value::Object(r), Value::Object(p)) = (&mut row, phases) {
        r.extend(p);
    }
    row
}

/// A pass's counting-mode counts (`motu_gpu::PassStats::proxy_calls_*`) as
/// `{kind: {outcome: {rays, calls, reports, member_tests, exact_tests}}}`; null when the pass
/// counted nothing (no counting mode).
fn proxy_calls_json(p: &motu_gpu::PassStats) -> Value {
    let kinds = p.proxy_calls_by_kind();
    if kinds.iter().all(|(_, c)| c.total().rays == 0) {
        return Value::Null;
    }
    let work = |w: motu_gpu::ProxyWork| {
        json!({"rays": w.rays, "calls": w.calls, "reports": w.reports,
               "member_tests": w.member_tests, "exact_tests": w.exact_tests})
    };
    Value::Object(
        kinds
            .iter()
            .map(|(k, c)| {
                let v =
                    json!({"open": work(c.open), "closed": work(c.closed), "miss": work(c.miss)});
                (k.to_string(), v)
            })
            .collect(),
    )
}

/// The per-frame rows of a streaming flight as a text table.
fn frame_table(rows: &[Value]) -> String {
    // Writing to a String cannot fail.
    let mut text = String::new();
    let _ = writeln!(
        text,
        "frame  passes  working set  room         built        build ms  TLAS ms  trace ms  wall ms  fallback px  host ms  TLASes  fences"
    );
    for r in rows {
        let bytes = |k: &str| motu_report::format_size(r[k].as_u64().unwrap_or(0));
        let ms = |k: &str| r[k].as_f64().unwrap_or(0.0);
        let _ = writeln!(
            text,
            "{:>5}  {:>6}  {:>11}  {:>11}  {:>11}  {:>8.2}  {:>7.2}  {:>8.2}  {:>7.2}  {:>11}  {:>7.2}  {:>6}  {:>6}",
            r["frame"].as_u64().unwrap_or(0),
            r["passes"].as_u64().unwrap_or(0),
            // A working set above its room cannot be resident at once: passes follow.
            bytes("working_set_bytes"),
            bytes("room_bytes"),
            bytes("built_bytes"),
            ms("build_ms"),
            // Of the build: the TLASes' rebuilds or updates.
            ms("tlas_ms"),
            ms("trace_ms"),
            ms("wall_ms"),
            r["fallback_pixels"].as_u64().unwrap_or(0),
            ms("host_ms"),
            // TLASes rebuilt, and the frame's fence waits (each a CPU–GPU round trip).
            r["tlas_rebuilt"].as_u64().unwrap_or(0),
            r["fence_waits"].as_u64().unwrap_or(0),
        );
    }
    text
}

fn backend_name(b: motu_gpu::Backend) -> &'static str {
    b.name()
}

#[cfg(test)]
mod tests;
