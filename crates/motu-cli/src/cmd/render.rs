//! `motu render` and `motu compare`.

use crate::cli::{BackendArg, CompareArgs, LodModeArg, RenderArgs, ViewArg};
use crate::output;
use crate::pipeline;
use anyhow::{bail, Context};
use motu_abi::aov::Aov;
use motu_abi::camera::CameraParams;
use motu_abi::lod::LodParams;
use motu_abi::RootSubset;
use serde_json::json;

pub use motu_render::{
    camera_params, camera_pose, choose_lod_mode, load_camera_path, PackageMeshes,
};

/// The streaming bounds of `--stream-fallback`, `--stream-build-budget`, `--stream-build-ms`,
/// `--stream-frame-ms`,
/// `--stream-probe`, `--stream-probe-rounds`, `--stream-probe-verify`,
/// `--stream-probe-pass-rows`, `--stream-tlas`, `--stream-split-instances`, `--stream-defrag`
/// and `--stream-mesh-memory`.
pub fn stream_bounds(b: &crate::cli::StreamBoundArgs) -> motu_render::StreamBounds {
    motu_render::StreamBounds {
        fallback: match b.stream_fallback {
            crate::cli::FallbackArg::Off => motu_gpu::StreamFallback::Off,
            crate::cli::FallbackArg::Coarse => motu_gpu::StreamFallback::Coarse,
        },
        frame_build_bytes: b.stream_build_budget,
        frame_build_ms: b.stream_build_ms,
        frame_ms: b.stream_frame_ms,
        probe_stride: b.stream_probe,
        probe_rounds: b.stream_probe_rounds,
        probe_verify: b.stream_probe_verify,
        probe_later: b.stream_probe_later.map(Into::into),
        probe_paths: b.stream_probe_paths.map(Into::into),
        pass_marks: b.stream_probe_pass_rows,
        tlas_update: b.stream_tlas.into(),
        split_instances: b.stream_split_instances,
        defrag: b.stream_defrag,
        prefetch_keeps_frame: b.stream_prefetch_keeps_frame,
        victims_by_frequency: b.stream_victims_by_frequency,
        mesh_memory: b.stream_mesh_memory.into(),
        host_cache_mode: b.stream_host_cache.into(),
        host_store_policy: b.stream_host_cache_policy.into(),
        fixed_rates: b.stream_rates.0,
        tlas_records: b.stream_tlas_records.into(),
        tlas_build: b.stream_tlas_build.into(),
        tlas_compact: Some(b.stream_tlas_compact == crate::cli::OnOffArg::On),
        tlas_headroom: b.stream_tlas_headroom,
    }
}

/// A recorded camera path is JSON of poses (~100 B each): a bigger file is not one, and a
/// device such as `/dev/zero` is refused before it is read.
pub const CAMERA_PATH_MAX_BYTES: u64 = 256 << 20;

/// `--lod-mode` as the library's request.
pub(crate) fn lod_mode(m: LodModeArg) -> motu_render::LodMode {
    match m {
        LodModeArg::Instance => motu_render::LodMode::Instance,
        LodModeArg::Traversal => motu_render::LodMode::Traversal,
    }
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
    output::check_input("--camera-path", p, Some(CAMERA_PATH_MAX_BYTES))?;
    let path = load_camera_path(p)?;
    let path_size = a.width.is_none() && a.height.is_none();
    Ok(Some(motu_render::recorded_path_cameras(
        &path, &camera, path_size, a.frames,
    )))
}

/// `query` where a device has ray queries (usually fastest on RTX), else `pipeline`, else the CPU
/// ([`motu_render::best_backend`]) as `--backend`'s value.
/// The device flags: `--device`, `--vram-budget`, `--max-allocations`, `--blas-build`,
/// `--pipeline-stats`.
pub(crate) fn device_request(a: &RenderArgs) -> motu_render::DeviceRequest {
    motu_render::DeviceRequest {
        index: a.device,
        vram_budget_bytes: a.vram_budget,
        max_allocations: a.max_allocations,
        blas_build: a.blas_build.map(Into::into),
        pipeline_stats: a.pipeline_stats,
    }
}

pub fn best_backend(devices: &[motu_gpu::DeviceReport]) -> BackendArg {
    match motu_render::best_backend(devices) {
        motu_render::Backend::Query => BackendArg::Query,
        motu_render::Backend::Pipeline => BackendArg::Pipeline,
        motu_render::Backend::Cpu => BackendArg::Cpu,
    }
}

/// `--view` as the GPU's view (the CPU tracer's is mapped from it).
fn gpu_view(v: ViewArg) -> motu_gpu::View {
    match v {
        ViewArg::Shaded => motu_gpu::View::Shaded,
        ViewArg::Ids => motu_gpu::View::Ids,
        ViewArg::Lod => motu_gpu::View::Lod,
        ViewArg::Heatmap => motu_gpu::View::Heatmap,
        ViewArg::Albedo => motu_gpu::View::Albedo,
    }
}

/// Prints what a render reports while it runs: each streamed frame's line, and the loud
/// warnings of opted-in inexact output.
fn print_event(e: motu_render::RenderEvent<'_>, allow_incomplete: bool) {
    use motu_render::RenderEvent;
    match e {
        RenderEvent::StreamFullBuild {
            budget_bytes,
            upper_bytes,
        } => {
            eprintln!(
                "--stream: the budget ({}) holds the whole scene (at most {} built in full): \
                 rendering the full build (--stream-always streams anyway)",
                crate::size::format_size(budget_bytes),
                crate::size::format_size(upper_bytes)
            );
        }
        RenderEvent::StreamFullBuildRefused { what } => {
            eprintln!(
                "warning: --stream: the full build did not fit after all ({what}); streaming"
            );
        }
        RenderEvent::StreamSppIgnored { spp } => {
            eprintln!("warning: --stream renders one sample per pixel (--spp {spp} ignored)");
        }
        RenderEvent::StreamFrame {
            index: f,
            stats: st,
        } => {
            let why = if st.complete {
                ""
            } else if st.build_budget_spent {
                " (incomplete: frame build budget spent)"
            } else {
                " (incomplete: pass cap)"
            };
            eprintln!(
                "frame {f}: {} passes{why}{}, {}, {} BLAS + {} TLAS built ({}), {} evicted{}, {} streamed, {:.1} ms building, VRAM {} of {}, {:.1} ms tracing, {:.1} ms frame",
                st.passes,
                first_pass_misses(
                    st.first_pass_missed_probed,
                    st.first_pass_missed_unprobed,
                    st.first_pass_missed_evicted
                ),
                working_set_note(st.working_set_bytes, st.room_bytes),
                st.blas_built,
                st.tlas_built,
                crate::size::format_size(st.built_bytes),
                st.evicted,
                evicted_causes(st.evicted_for_tlas, st.evicted_on_refusal),
                crate::size::format_size(st.bytes_streamed),
                st.build_ms,
                crate::size::format_size(st.vram_peak_bytes),
                crate::size::format_size(st.vram_budget_bytes),
                st.trace_ms,
                st.frame_ms,
            );
            if !st.complete && st.fallback_pixels > 0 {
                // Opt-in (--stream-fallback): loud and counted, refined by later frames.
                eprintln!(
                    "WARNING: frame {f}: {} pixels show the coarse FALLBACK (bounds of structures not \
                     resident yet{}{}): this frame is not exact (--stream-fallback coarse)",
                    st.fallback_pixels,
                    if st.build_budget_spent {
                        "; the frame's build budget is spent"
                    } else {
                        ""
                    },
                    stale_note(st.stale_blocked_pixels, st.tlas_pieces_stale),
                );
            } else if !st.complete && st.incomplete_pixels == 0 && st.tlas_pieces_stale > 0 {
                // Exact, but later frames still rebuild TLASes (--stream-build-ms).
                eprintln!(
                    "warning: frame {f}: exact, but {} TLAS pieces are left stale for later frames \
                     to rebuild (--stream-build-ms)",
                    st.tlas_pieces_stale
                );
            } else if !st.complete && allow_incomplete {
                // Without --allow-incomplete the library refuses the frame after this line.
                eprintln!(
                    "WARNING: frame {f}: {} pixels UNFINISHED after {} passes (pass cap): written as \
                     magenta misses (--allow-incomplete)",
                    st.incomplete_pixels, st.passes
                );
            }
        }
        RenderEvent::TruncatedWritten { what } => {
            eprintln!("warning: {what}; written anyway (--allow-truncated)");
        }
        // Written by the caller (`ImageOut::write`).
        RenderEvent::Image { .. } => {}
    }
}

/// The image outputs (`-o`, `--aov`) of a render, written and committed together: as soon as
/// a streamed render has its final image (before its structure cache is persisted), else
/// after the render. `--stats` is committed after the render; should that fail, the image's
/// targets get their old contents back (`Outputs`): the outputs stay all or nothing.
struct ImageOut<'a> {
    png: &'a std::path::Path,
    aov: Option<&'a std::path::Path>,
    width: u32,
    height: u32,
    /// The write's milliseconds, once written (`stream.startup.write_ms`), or its error.
    written: Option<anyhow::Result<f64>>,
}

impl ImageOut<'_> {
    fn write(&mut self, outs: &mut output::Outputs, aov: &Aov, rgba8: &[u8]) {
        if self.written.is_some() {
            return;
        }
        let t = std::time::Instant::now();
        let r = (|| -> anyhow::Result<f64> {
            outs.write_png(self.png, self.width, self.height, rgba8)?;
            if let Some(p) = self.aov {
                outs.write(p, &aov.to_bytes())?;
            }
            let mut paths = vec![self.png];
            paths.extend(self.aov);
            outs.commit_some(&paths)?;
            Ok(t.elapsed().as_secs_f64() * 1e3)
        })();
        self.written = Some(r);
    }
}

pub fn run(a: RenderArgs) -> anyhow::Result<()> {
    let started = std::time::Instant::now();
    let mut outputs = vec![("-o", a.output.as_path())];
    outputs.extend(a.aov.as_deref().map(|p| ("--aov", p)));
    outputs.extend(a.stats.as_deref().map(|p| ("--stats", p)));
    // Every output is checked and its temp file created before any work; the image's (PNG and
    // AOV) are renamed into place together once both are written (a failed AOV never leaves a
    // new PNG beside an old AOV), `--stats` after the render.
    let mut outs = output::Outputs::begin(&[("package", &a.package)], &outputs)?;
    if let Some(p) = &a.camera_path {
        output::check_input("--camera-path", p, Some(CAMERA_PATH_MAX_BYTES))?;
    }
    let opened = file_stamp(&a.package);
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
            "--stream-fallback, --stream-build-budget, --stream-build-ms and --stream-probe* bound \
             streaming frames: add --stream (with --vram-budget)"
        );
    }
    if let Some(why) = crate::cmd::render::stream_bounds(&a.stream_bounds).conflict() {
        bail!(why);
    }
    if a.frames == 0 {
        bail!("--frames must be at least 1");
    }
    if a.denoise && a.view != ViewArg::Shaded {
        bail!("--denoise filters the shaded view's sampling noise: drop it or use --view shaded");
    }
    let lod_choice = choose_lod_mode(&view, &lod, lod_mode(a.lod_mode), a.stream)?;
    if lod_choice.mode == "traversal"
        && a.lod_mode == LodModeArg::Instance
        && a.lod_stochastic | a.stream
    {
        eprintln!("note: LOD runs in traversal mode: {}", lod_choice.reason);
    }
    let settings = motu_render::RenderSettings {
        backend: backend.into(),
        view: gpu_view(a.view),
        lod,
        limits: motu_render::TraversalLimits {
            stack_size: a.stack_size,
            max_traces_per_ray: a.max_traces_per_ray,
            allow_truncated: a.allow_truncated,
        },
        frames: a.frames,
        shading: motu_render::ShadingOptions {
            ao_samples: a.ao_samples,
            spp: a.spp,
            exposure_ev: match a.exposure {
                crate::cli::ExposureArg::Ev(ev) => ev,
                crate::cli::ExposureArg::Auto => 0.0,
            },
            auto_exposure: a.exposure == crate::cli::ExposureArg::Auto,
            bounces: a.bounces,
            ao_reach_of_diagonal: a.ao_reach,
        },
        camera: motu_render::CameraRequest {
            name: a.camera.clone(),
            width: a.width,
            height: a.height,
        },
        device: device_request(&a),
        stream: a.stream.then(|| motu_render::StreamSettings {
            max_passes: a.stream_max_passes,
            bounds: stream_bounds(&a.stream_bounds),
            allow_incomplete: a.allow_incomplete,
            cache: cache_settings(&a.as_cache),
            always: a.stream_always,
        }),
        denoise: a.denoise,
    };
    let job = motu_render::RenderJob {
        package: &pkg,
        package_path: &a.package,
        subset: &a.subset,
        view: &view,
        camera,
        recorded: recorded.as_deref(),
        lod: &lod_choice,
        started: Some(started),
    };
    let mut image = ImageOut {
        png: &a.output,
        aov: a.aov.as_deref(),
        width: camera.width,
        height: camera.height,
        written: None,
    };
    let rendered = motu_render::render(&job, &settings, &mut |e| match e {
        // A streamed image is written before the structure cache is persisted (seconds).
        motu_render::RenderEvent::Image { aov, rgba8 } => image.write(&mut outs, aov, rgba8),
        e => print_event(e, a.allow_incomplete),
    });
    let mut out = rendered
        .map_err(|e| below_floor_hint(e, &a, &pkg))
        .map_err(|e| package_changed_hint(e, &a.package, &opened))?;
    image.write(&mut outs, &out.aov, &out.rgba8);
    let write_ms = image.written.take().expect("written above")?;
    if let Some(stream) = &mut out.stats.stream {
        // The image's write closes the time to first pixel the render measured.
        stream.startup.write_ms = Some(write_ms);
    }
    if let Some(p) = &a.stats {
        outs.write(p, serde_json::to_string_pretty(&out.stats)?.as_bytes())?;
    }
    outs.commit()?;
    // The structure cache's queued directory writes, after the outputs (dropping waits).
    if let Some(pending) = out.pending_cache_writes.take() {
        let t = std::time::Instant::now();
        drop(pending);
        tracing::info!(
            ms = t.elapsed().as_secs_f64() * 1e3,
            "structure cache written"
        );
    }
    eprintln!(
        "rendered {} ({}×{}, {}): {:.1} ms/frame, {:.2} Mrays/s, {:.2} traces/ray",
        a.output.display(),
        camera.width,
        camera.height,
        out.stats.frame.backend,
        out.ms_per_frame(),
        out.rays_per_second() / 1e6,
        out.traces_per_ray(),
    );
    Ok(())
}

/// `--host-cache`, `--as-cache`, `--no-as-cache` as the streamer's cache settings.
pub fn cache_settings(a: &crate::cli::AsCacheArgs) -> motu_render::CacheSettings {
    motu_render::CacheSettings {
        host_bytes: a.host_cache,
        dir: match (&a.as_cache, a.no_as_cache) {
            (_, true) => motu_render::CacheDir::Off,
            (Some(d), false) => motu_render::CacheDir::At(d.clone()),
            (None, false) => motu_render::CacheDir::Default,
        },
    }
}

/// What identifies a file's contents cheaply: device, inode, length, modification time.
fn file_stamp(path: &std::path::Path) -> Option<(u64, u64, u64, std::time::SystemTime)> {
    use std::os::unix::fs::MetadataExt;
    let m = std::fs::metadata(path).ok()?;
    Some((m.dev(), m.ino(), m.len(), m.modified().ok()?))
}

/// A render that failed on the package's data names the package, and says so when the file
/// was replaced or rewritten while it was read (a mesh record pointing past its vertices is
/// then a mix of two packages, not a damaged import).
fn package_changed_hint(
    e: anyhow::Error,
    package: &std::path::Path,
    opened: &Option<(u64, u64, u64, std::time::SystemTime)>,
) -> anyhow::Error {
    if opened.is_some() && file_stamp(package) != *opened {
        e.context(format!(
            "rendering {}: the package file changed while it was read (replaced or rewritten during the render); render again once it is complete",
            package.display()
        ))
    } else {
        e.context(format!("rendering {}", package.display()))
    }
}

/// A refusal below the streaming floor where the whole scene's full build fits the budget
/// (small scenes: the floor holds a build, TLAS rebuilds and frame buffers at once) says so.
fn below_floor_hint(
    e: motu_render::RenderError,
    a: &RenderArgs,
    pkg: &motu_pack::ScenePackage,
) -> anyhow::Error {
    let motu_render::RenderError::BelowFloor {
        budget_bytes,
        width,
        height,
        ..
    } = &e
    else {
        return e.into();
    };
    let (budget, image) = (*budget_bytes, (*width, *height));
    let peak = a
        .subset
        .is_empty()
        .then(|| motu_report::size_source_for_cli(a.device).ok())
        .flatten()
        .and_then(|sizes| motu_report::build_report_at(pkg, sizes.as_ref(), None, Some(image)).ok())
        .and_then(|r| r.variants.first().map(|v| v.cost.peak_bytes));
    match peak {
        Some(p) if p <= budget => anyhow::anyhow!(
            "{e}; the full build fits this budget (motu report: peak {} at {}×{}): render \
             without --stream",
            crate::size::format_size(p),
            image.0,
            image.1
        ),
        _ => e.into(),
    }
}

pub fn compare(a: CompareArgs) -> anyhow::Result<()> {
    let outputs: Vec<(&str, &std::path::Path)> = a
        .diff
        .as_deref()
        .map(|p| ("--diff", p))
        .into_iter()
        .collect();
    let mut outs = output::Outputs::begin(&[("A", &a.a), ("B", &a.b)], &outputs)?;
    // A FIFO or device named as an AOV is refused before it is opened (opening one blocks).
    output::check_input("A", &a.a, None)?;
    output::check_input("B", &a.b, None)?;
    let x = Aov::load(&a.a).with_context(|| format!("reading {}", a.a.display()))?;
    let y = Aov::load(&a.b).with_context(|| format!("reading {}", a.b.display()))?;
    let r = motu_trace::compare(&x, &y, a.depth_epsilon).context("comparing")?;
    if let Some(p) = &a.diff {
        outs.write_png(p, x.width, x.height, &r.diff_rgba8)?;
    }
    outs.commit()?;
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

/// What the frame's rays met against the room streamed structures have under the budget: a
/// working set over its room cannot be resident at once, so its frame takes several passes
/// whatever the prefetch does (a larger budget or a narrower view buys them back).
fn working_set_note(working_set_bytes: u64, room_bytes: u64) -> String {
    let (ws, room) = (
        crate::size::format_size(working_set_bytes),
        crate::size::format_size(room_bytes),
    );
    if working_set_bytes > room_bytes {
        format!("working set {ws} OVER its room of {room}")
    } else {
        format!("working set {ws} in a room of {room}")
    }
}

/// Why the first pass left pixels open (what it needed and was not resident), when it did:
/// the probe asked for it but the room did not hold it; no probe ray met it; it was resident,
/// passed by the probe's rays without a hit (so unseen) and evicted.
fn first_pass_misses(probed: u32, unprobed: u32, evicted: u32) -> String {
    let total = probed + unprobed + evicted;
    if total == 0 {
        return String::new();
    }
    let parts: Vec<String> = [
        (probed, "the probe asked for"),
        (unprobed, "no probe ray met"),
        (evicted, "passed unseen and evicted"),
    ]
    .iter()
    .filter(|(n, _)| *n > 0)
    .map(|(n, what)| format!("{n} {what}"))
    .collect();
    format!(
        " (first pass missed {total} structures: {})",
        parts.join(", ")
    )
}

/// The causes of a frame's evictions beside their count, when any is not a BLAS build's room.
fn evicted_causes(for_tlas: u32, on_refusal: u32) -> String {
    match (for_tlas, on_refusal) {
        (0, 0) => String::new(),
        (t, 0) => format!(" ({t} for TLAS rebuilds)"),
        (0, r) => format!(" ({r} after refused allocations)"),
        (t, r) => format!(" ({t} for TLAS rebuilds, {r} after refused allocations)"),
    }
}

#[cfg(test)]
mod tests;

/// The fallback warning's note on stale TLAS pieces (frames with `--stream-build-ms`): pixels
/// waiting for a resident structure's TLAS piece to be rebuilt, and the pieces left stale.
fn stale_note(blocked_pixels: u64, pieces: u32) -> String {
    if pieces == 0 && blocked_pixels == 0 {
        return String::new();
    }
    format!(
        "; {blocked_pixels} of them wait for a stale TLAS piece, {pieces} left stale for later frames"
    )
}
