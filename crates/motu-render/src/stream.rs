//! `--stream`: the streaming frame loop (build only what rays touch, evict under the budget,
//! frame by frame along a camera path) and its per-frame bounds (`--stream-fallback`,
//! `--stream-build-budget`, `--stream-build-ms`, `--stream-frame-ms`).

use crate::gpu::{gpu_context, gpu_render_options, PathStats, Rendered};
use crate::settings::{RenderEvent, RenderSettings, StreamSettings};
use crate::stats::{FrameStats, StreamFitStats, StreamRunStats, StreamStartup};
use crate::{camera_pose, scene_shading, Backend, PackageMeshes, RenderError};
use motu_abi::camera::{camera_path, CameraParams};
use motu_abi::HierarchyView;
use motu_gpu::MeshBlobSource as _;
use std::time::Instant;

/// Milliseconds of building per frame while flying (one trace with what is resident, then a
/// build step) when no build budget is given: `motu view`'s flying default, and `motu bench
/// --stream-passes 1`'s, which measures the viewer (at least one structure is built per frame).
pub const INTERACTIVE_BUILD_MS: f64 = 30.0;

/// What one streaming frame may build, and what it shows for what it did not build.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StreamBounds {
    pub fallback: motu_gpu::StreamFallback,
    /// Bytes one frame may build (`None`: unbounded).
    pub frame_build_bytes: Option<u64>,
    /// Milliseconds of building one frame may spend (`None`: unbounded).
    pub frame_build_ms: Option<f64>,
    /// `--stream-frame-ms`: milliseconds a whole frame aims at (`None`: no clock; see
    /// [`motu_gpu::StreamOptions::frame_ms`]).
    pub frame_ms: Option<f64>,
    /// `--stream-probe`: the next camera's probe stride (`None`: the default; 0: no probe).
    pub probe_stride: Option<u32>,
    /// `--stream-probe-rounds`: most probe rounds after a frame (`None`: the default).
    pub probe_rounds: Option<u32>,
    /// `--stream-probe-verify`: verifying probe rounds after those (`None`: the default).
    pub probe_verify: Option<u32>,
    /// `--stream-probe-later`: the rounds after the first when its prefetch evicted (`None`:
    /// the default).
    pub probe_later: Option<motu_gpu::ProbeLater>,
    /// `--stream-probe-paths`: where a probe round's open paths end (`None`: the default).
    pub probe_paths: Option<motu_gpu::ProbePaths>,
    /// `--stream-probe-pass-rows`: the probe's pass marks (`None`: the default, auto).
    pub pass_marks: Option<motu_gpu::PassMarks>,
    /// `--stream-tlas`: how TLASes follow residency.
    pub tlas_update: motu_gpu::TlasUpdate,
    /// `--stream-split-instances`: TLASes over this many instances are split into pieces when
    /// the package is loaded (`None`: [`motu_compile::STREAM_SPLIT_INSTANCES`]; 0: none).
    pub split_instances: Option<u32>,
    /// `--stream-defrag`: drain part-used memory blocks before evicting (off by default).
    pub defrag: bool,
    /// `--stream-prefetch-keeps-frame`: the prefetch also keeps the frame's working set while
    /// it fits (off by default).
    pub prefetch_keeps_frame: bool,
    /// `--stream-victims-by-frequency`: evict the least often used of the last 16 frames first.
    pub victims_by_frequency: bool,
    /// `--stream-mesh-memory`: where streamed meshes live.
    pub mesh_memory: motu_gpu::MeshMemory,
    /// `--stream-host-cache`: how evicted BLASes are kept in host memory.
    pub host_cache_mode: motu_gpu::HostCacheMode,
    /// `--stream-host-cache-policy`: which built BLASes the serialised host tier stores.
    pub host_store_policy: motu_gpu::HostStorePolicy,
    /// `--stream-rates`: rates the restore and store rules decide from instead of measuring
    /// them (`None`: measured).
    pub fixed_rates: Option<motu_gpu::DeviceRates>,
    /// `--stream-tlas-records`: where rebuilt TLASes' instance records come from.
    pub tlas_records: motu_gpu::TlasRecordsMode,
    /// `--stream-tlas-build`: what rebuilt streamed TLASes are built for.
    pub tlas_build: motu_gpu::TlasBuild,
    /// `--stream-tlas-compact`: whether rebuilt TLASes and their proxies are compacted (None:
    /// the default, on).
    pub tlas_compact: Option<bool>,
    /// `--stream-tlas-headroom`: spare storage of rebuilt TLAS pieces (None: the default).
    pub tlas_headroom: Option<f64>,
}

impl StreamBounds {
    /// The streaming options with these bounds (the rest default).
    pub fn options(&self) -> motu_gpu::StreamOptions {
        let d = motu_gpu::StreamOptions::default();
        motu_gpu::StreamOptions {
            fallback: self.fallback,
            frame_build_bytes: self.frame_build_bytes.unwrap_or(0),
            frame_build_ms: self.frame_build_ms.unwrap_or(0.0),
            frame_ms: self.frame_ms.unwrap_or(0.0),
            probe_stride: self.probe_stride.unwrap_or(d.probe_stride),
            probe_rounds: self.probe_rounds.unwrap_or(d.probe_rounds),
            probe_verify_rounds: self.probe_verify.unwrap_or(d.probe_verify_rounds),
            // On the clock a cheaper probe, except where a setting was given.
            clocked_probe: Some(motu_gpu::ProbeSettings {
                stride: self.probe_stride.unwrap_or(motu_gpu::CLOCKED_PROBE.stride),
                rounds: self.probe_rounds.unwrap_or(motu_gpu::CLOCKED_PROBE.rounds),
                verify_rounds: self
                    .probe_verify
                    .unwrap_or(motu_gpu::CLOCKED_PROBE.verify_rounds),
            }),
            probe_later: self.probe_later.unwrap_or(d.probe_later),
            probe_paths: self.probe_paths.unwrap_or(d.probe_paths),
            pass_marks: self.pass_marks.unwrap_or(d.pass_marks),
            tlas_update: self.tlas_update,
            defrag: self.defrag,
            prefetch_keeps_frame: self.prefetch_keeps_frame,
            victims_by_frequency: self.victims_by_frequency,
            mesh_memory: self.mesh_memory,
            host_cache_mode: self.host_cache_mode,
            host_store_policy: self.host_store_policy,
            fixed_rates: self.fixed_rates,
            tlas_records: self.tlas_records,
            tlas_build: self.tlas_build,
            tlas_compact: self.tlas_compact.unwrap_or(d.tlas_compact),
            tlas_headroom: self.tlas_headroom.unwrap_or(d.tlas_headroom),
            ..d
        }
    }

    /// Whether no bound limits a frame's building (no build budget, no frame clock): a
    /// flying frame then gets [`INTERACTIVE_BUILD_MS`] (`motu view`, `motu bench
    /// --stream-passes 1`).
    pub fn build_unbounded(&self) -> bool {
        self.frame_build_bytes.is_none() && self.frame_build_ms.is_none() && self.frame_ms.is_none()
    }

    /// Bounds that contradict each other, as the message to refuse them with.
    pub fn conflict(&self) -> Option<String> {
        match (self.probe_stride, self.pass_marks) {
            (Some(0), Some(m)) if m != motu_gpu::PassMarks::Off => Some(format!(
                "--stream-probe-pass-rows {} marks rows of the next camera's probe, which \
                 --stream-probe 0 turns off: drop one of them",
                match m {
                    motu_gpu::PassMarks::Rows(n) => n.to_string(),
                    _ => "auto".into(),
                }
            )),
            _ => None,
        }
    }

    /// Whether any bound is set (they need streaming).
    pub fn given(&self) -> bool {
        self.fallback != motu_gpu::StreamFallback::Off
            || self.frame_build_bytes.is_some()
            || self.frame_build_ms.is_some()
            || self.frame_ms.is_some()
            || self.probe_stride.is_some()
            || self.probe_rounds.is_some()
            || self.probe_verify.is_some()
            || self.probe_later.is_some()
            || self.probe_paths.is_some()
            || self.pass_marks.is_some()
            || self.tlas_update != motu_gpu::TlasUpdate::Auto
            || self.split_instances.is_some()
            || self.defrag
            || self.prefetch_keeps_frame
            || self.victims_by_frequency
            || self.mesh_memory != motu_gpu::MeshMemory::Auto
            || self.host_cache_mode != motu_gpu::HostCacheMode::Auto
            || self.host_store_policy != motu_gpu::HostStorePolicy::Measured
            || self.fixed_rates.is_some()
            || self.tlas_records != motu_gpu::TlasRecordsMode::Host
            || self.tlas_build != motu_gpu::TlasBuild::FastTrace
            || self.tlas_compact == Some(true)
            || self.tlas_headroom.is_some()
    }
}

/// Where a streamed render's split cap (`--stream-split-instances`) came from
/// (`stream.startup.split_instances_source` in `--stats`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SplitCapSource {
    /// Given on the command line.
    Flag,
    /// The cap `motu import --stream-split-instances` recorded in the package
    /// (`meta.stream_split.cap_instances`), which its stored split, proxy boxes and clusters
    /// were made for.
    Package,
    /// A package written before the cap was recorded: [`motu_compile::STREAM_SPLIT_INSTANCES`].
    Default,
}

impl SplitCapSource {
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Flag => "flag",
            Self::Package => "package",
            Self::Default => "default",
        }
    }
}

/// The cap a streamed render of `pkg` splits TLASes at: `flag` (`--stream-split-instances`)
/// when given, else the one the import recorded (so the split, proxy boxes and clusters it
/// stored are the hierarchy drawn), else [`motu_compile::STREAM_SPLIT_INSTANCES`].
pub fn package_split_cap(
    pkg: &motu_pack::ScenePackage,
    flag: Option<u32>,
) -> (u32, SplitCapSource) {
    if let Some(cap) = flag {
        return (cap, SplitCapSource::Flag);
    }
    match &pkg.meta().stream_split {
        Some(m) => (m.cap_instances, SplitCapSource::Package),
        None => (
            motu_compile::STREAM_SPLIT_INSTANCES,
            SplitCapSource::Default,
        ),
    }
}

/// [`stream_split`] of `pkg`'s own hierarchy at the resolved cap `cap`
/// ([`package_split_cap`]), read back from the split the import stored for this cap (FORMAT.md
/// sections 13–17) instead of made again: a binned SAH over every instance of a large root
/// (10 s of island 0.63's start on the H200 host) becomes a table read. Any other view (a
/// subset), another cap, or a package written before splits were stored is split here, as
/// before.
pub fn package_stream_split(
    pkg: &motu_pack::ScenePackage,
    view: &HierarchyView<'_>,
    cap: u32,
) -> Result<Option<motu_compile::StreamSplit>, RenderError> {
    let t0 = std::time::Instant::now();
    // The stored split indexes the package's own tables: only a view that is those tables
    // (the same memory, not a copy or a subset) may use it.
    let own = pkg
        .view()
        .map_err(|source| RenderError::StoredSplitRead { cap, source })?;
    let known = if own.same_instancing(view) {
        stored_stream_split_or_none(pkg, view, cap)?
    } else {
        None
    };
    let Some(split) = known else {
        return stream_split(view, Some(cap));
    };
    if let Some(s) = &split {
        let (tlases, pieces) = s.counts();
        let split_ms = t0.elapsed().as_secs_f64() * 1e3;
        tracing::info!(
            cap,
            tlases,
            pieces,
            split_ms,
            "TLASes split for streaming (stored at import)"
        );
    }
    Ok(split)
}

/// The split of `pkg`'s own `view` at `cap` when nothing must be split to know it: `Some(None)`
/// when `cap` is 0 (no TLAS is split) or the import stored that no TLAS is over it,
/// `Some(Some(_))` the split it stored ([`stored_stream_split`]), `None` when it must be
/// computed ([`stream_split`]). `motu report` tells its stored split from a computed one by it.
pub fn stored_stream_split_or_none(
    pkg: &motu_pack::ScenePackage,
    view: &HierarchyView<'_>,
    cap: u32,
) -> Result<Option<Option<motu_compile::StreamSplit>>, RenderError> {
    if cap == 0 {
        return Ok(Some(None));
    }
    stored_stream_split(pkg, view, cap)
}

/// The split the import stored in `pkg` for `cap` instances, made into a [`motu_compile::StreamSplit`] of
/// `view` (the package's own tables) without splitting: `None` when the package stored none
/// for this cap (written before splits were stored), `Some(None)` when it stored that no TLAS
/// is over the cap. `motu report` reads it too.
pub fn stored_stream_split(
    pkg: &motu_pack::ScenePackage,
    view: &HierarchyView<'_>,
    cap: u32,
) -> Result<Option<Option<motu_compile::StreamSplit>>, RenderError> {
    let Some(stored) = pkg
        .stored_stream_split(cap)
        .map_err(|source| RenderError::StoredSplitRead { cap, source })?
    else {
        return Ok(None);
    };
    let Some(t) = stored else {
        return Ok(Some(None));
    };
    let meta = pkg.meta().stream_split.clone().unwrap_or_default();
    let stored = motu_compile::StoredStreamSplit {
        tlases_split: meta.tlases_split,
        pieces: meta.pieces,
        tlases: t.tlases.to_vec(),
        blases: t.blases.to_vec(),
        pis: t.pis.to_vec(),
        instance_source: t.instance_source.to_vec(),
        extra_instances: t.extra_instances.to_vec(),
    };
    let split = motu_compile::StreamSplit::from_stored(view, &stored).map_err(|source| {
        RenderError::StoredSplit {
            cap,
            path: pkg.path().to_string(),
            source,
        }
    })?;
    Ok(Some(Some(split)))
}

/// The hierarchy a streamer renders for `view`: every TLAS over `split_instances` instances
/// (`None`: [`motu_compile::STREAM_SPLIT_INSTANCES`]; 0: none) split into spatial pieces, which
/// the streamer rebuilds one at a time, so a rebuild takes one piece's room from resident
/// BLASes, not the whole root's ([`motu_compile::split_for_streaming`]). `None`: `view` as is.
/// The renderer, the floor it enforces and `motu report`'s floor all use this view.
pub fn stream_split(
    view: &HierarchyView<'_>,
    split_instances: Option<u32>,
) -> Result<Option<motu_compile::StreamSplit>, RenderError> {
    let cap = split_instances.unwrap_or(motu_compile::STREAM_SPLIT_INSTANCES);
    if cap == 0 {
        return Ok(None);
    }
    let t0 = std::time::Instant::now();
    let split = motu_compile::split_for_streaming(view, cap)
        .map_err(|source| RenderError::StreamSplit { cap, source })?;
    if let Some(s) = &split {
        let (tlases, pieces) = s.counts();
        let split_ms = t0.elapsed().as_secs_f64() * 1e3;
        tracing::info!(cap, tlases, pieces, split_ms, "TLASes split for streaming");
    }
    Ok(split)
}

fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// `--stream`: builds only what rays touch, evicting under the budget, frame by frame along a
/// camera path (`frames`; one frame renders the camera itself). Each frame is reported to
/// `progress` before its completeness is checked.
/// A streamed render: the image, its camera, and the structure cache (directory writes maybe
/// still queued; `None` without one) for the caller to drop after its outputs.
pub(crate) struct Streamed {
    pub rendered: Rendered,
    pub camera: CameraParams,
    pub cache: Option<motu_gpu::StructureCache>,
}

pub(crate) fn render_streaming(
    s: &RenderSettings,
    stream: &StreamSettings,
    job: &crate::RenderJob<'_>,
    backend: Backend,
    progress: &mut dyn FnMut(RenderEvent<'_>),
) -> Result<Streamed, RenderError> {
    let (pkg, view, recorded, started) = (job.package, job.view, job.recorded, job.started);
    let _span = tracing::info_span!("stream_render").entered();
    let mut startup = StreamStartup {
        before_render_ms: started.map_or(0.0, ms_since),
        ..Default::default()
    };
    let t = Instant::now();
    let ctx = tracing::info_span!("device").in_scope(|| gpu_context(s, backend))?;
    startup.device_ms = ms_since(t);
    let mut stream_fit = None;
    if !stream.always {
        match render_full_if_it_fits(s, job, backend, &ctx, progress)? {
            Fit::Rendered(done) => {
                let (rendered, camera) = *done;
                return Ok(Streamed {
                    rendered,
                    camera,
                    cache: None,
                });
            }
            Fit::Streams(fit) => stream_fit = Some(fit),
        }
    }
    let t = Instant::now();
    let (cap, cap_source) = package_split_cap(pkg, stream.bounds.split_instances);
    startup.split_instances = cap;
    startup.split_instances_source = cap_source.as_str();
    let split = tracing::info_span!("split").in_scope(|| package_stream_split(pkg, view, cap))?;
    startup.split_ms = ms_since(t);
    (startup.split_tlases, startup.split_pieces) = split.as_ref().map_or((0, 0), |s| s.counts());
    let view = &split.as_ref().map_or(*view, |sp| sp.view(view));
    let (pose, w, h) = camera_pose(
        pkg,
        view,
        s.camera.name.as_deref(),
        s.camera.width,
        s.camera.height,
    )?;
    let path = crate::sweep_around_root(view, &pose);
    let meshes = PackageMeshes(pkg);
    let opts = motu_gpu::StreamOptions {
        budget_bytes: s.device.vram_budget_bytes.unwrap_or(u64::MAX),
        max_allocations: s
            .device
            .max_allocations
            .unwrap_or(motu_gpu::StreamOptions::default().max_allocations),
        max_passes: stream.max_passes.unwrap_or(0),
        blas_build: s.blas_build(),
        ..stream.bounds.options()
    };
    // A recorded path renders at its cameras' size, not the package camera's.
    let (w, h) = match recorded {
        Some(r) if !r.is_empty() => r
            .iter()
            .fold((0, 0), |(w, h), c| (w.max(c.width), h.max(c.height))),
        _ => (w, h),
    };
    // Refused up front below the floor: under it some frame could not complete.
    // Opened before the start: the proxy clusters and boxes are kept in it too.
    let mut cache = stream.cache.open(pkg);
    let t = Instant::now();
    // The package's stored clusters, else the structure cache's, else made.
    let plan = motu_gpu::StreamPlan::load(view, meshes.stored_proxy_clusters(), cache.as_mut());
    startup.clusters_ms = ms_since(t);
    startup.clusters_cached = plan.from_cache();
    startup.clusters_source = plan.source().as_str();
    startup.clusters_stale_tlases = plan.stale_tlases();
    let t = Instant::now();
    let floor = tracing::info_span!("floor")
        .in_scope(|| motu_gpu::streaming_floor_planned(view, &plan, &ctx, w, h, opts.staging_bytes))
        .map_err(RenderError::Floor)?;
    startup.floor_ms = ms_since(t);
    if let Some(budget) = s.device.vram_budget_bytes {
        if budget < floor.min_resident_bytes {
            return Err(RenderError::BelowFloor {
                budget_bytes: budget,
                width: w,
                height: h,
                floor: Box::new(floor),
            });
        }
    }
    let t = Instant::now();
    let mut sr = tracing::info_span!("init")
        .in_scope(|| {
            motu_gpu::StreamingRenderer::with_plan_and_cache(
                &ctx, *view, plan, &meshes, &opts, cache,
            )
        })
        .map_err(|source| RenderError::StreamSetup {
            floor_bytes: floor.min_resident_bytes,
            source,
        })?;
    startup.init_ms = ms_since(t);
    let ropts = gpu_render_options(s, s.lod, backend, 1, scene_shading(s.shading, pkg, view));
    if s.shading.spp > 1 {
        progress(RenderEvent::StreamSppIgnored { spp: s.shading.spp });
    }
    let mut frames = Vec::new();
    let mut last = None;
    let frame_count = recorded.map_or(s.frames, |r| r.len() as u32);
    let camera_at = |f: u32| match recorded {
        Some(r) => r[f as usize],
        None => camera_path(&pose, &path, f, s.frames).params(w, h),
    };
    for f in 0..frame_count {
        let cam = camera_at(f);
        // The path's next camera is known: the frame ends with a probe of it (prefetch).
        sr.set_next_camera((f + 1 < frame_count).then(|| camera_at(f + 1)));
        // The last frame builds nothing for a next one (its image goes out sooner).
        sr.set_last_frame(f + 1 == frame_count);
        let t = Instant::now();
        let (out, st) = tracing::info_span!("frame", index = f)
            .in_scope(|| sr.render_frame(&cam, &ropts))
            .map_err(|source| RenderError::StreamFrame { frame: f, source })?;
        if f == 0 {
            startup.first_frame_ms = ms_since(t);
            startup.to_first_pixel_ms = started.map_or(0.0, ms_since);
            let totals = sr.totals();
            startup.proxy_boxes_ms = totals.proxy_boxes_ms;
            startup.proxy_boxes_source = totals.proxy_boxes_source;
            startup.derived_ms = totals.derived_ms;
            startup.persistent_choice_ms = totals.persistent_choice_ms;
            startup.skeleton_ms = totals.skeleton_ms;
            tracing::info!(
                device_ms = startup.device_ms,
                split_ms = startup.split_ms,
                split_instances = startup.split_instances,
                split_instances_source = startup.split_instances_source,
                clusters_ms = startup.clusters_ms,
                clusters_source = startup.clusters_source,
                floor_ms = startup.floor_ms,
                init_ms = startup.init_ms,
                derived_ms = startup.derived_ms,
                persistent_choice_ms = startup.persistent_choice_ms,
                proxy_boxes_ms = startup.proxy_boxes_ms,
                proxy_boxes_source = startup.proxy_boxes_source,
                skeleton_ms = startup.skeleton_ms,
                first_frame_ms = startup.first_frame_ms,
                to_first_pixel_ms = startup.to_first_pixel_ms,
                "first streamed frame done"
            );
        }
        progress(RenderEvent::StreamFrame {
            index: f,
            stats: &st,
        });
        // A wrong image never exits 0 silently (fallback pixels are opt-in and counted).
        // A frame left not complete only by stale TLASes (no pixel open) is exact.
        let open = st.incomplete_pixels > 0;
        if !st.complete && open && st.fallback_pixels == 0 && !stream.allow_incomplete {
            let cause = if st.build_budget_spent {
                "its build budget (--stream-build-budget/--stream-build-ms) spent".to_string()
            } else {
                format!("the pass cap, {}", sr.max_passes())
            };
            return Err(RenderError::IncompleteFrame {
                frame: f,
                pixels: st.incomplete_pixels,
                passes: st.passes,
                cause,
            });
        }
        frames.push(st);
        last = Some((out, cam));
    }
    let (out, last_camera) = last.ok_or(RenderError::NoFrame)?;
    let written = frames.last();
    // The image goes out before the structures are persisted, where nothing after this changes
    // or refuses it (`--denoise` filters it; a cut ray refuses it unless allowed: session.rs).
    let truncated = written.map_or(0, |f| f.truncated_rays) > 0 || out.stats.stack_overflows > 0;
    let denoised = s.denoise && matches!(s.view, motu_gpu::View::Shaded);
    if !denoised && (!truncated || s.limits.allow_truncated) {
        progress(RenderEvent::Image {
            aov: &out.aov,
            rgba8: &out.rgba8,
        });
    }
    // The cache leaves with the image (its queued directory writes finish after the outputs).
    // Structures are serialised at eviction by default and not at all with host clones:
    // taking the cache writes this run's remaining structures to the directory, once, after
    // the image and before the totals below count them (a failure is a warning: a cache never
    // fails a render).
    let cache = tracing::info_span!("persist_cache").in_scope(|| sr.take_cache());
    let after_first: Vec<f64> = frames.iter().skip(1).map(|f| f64::from(f.passes)).collect();
    let stats = PathStats {
        // The last frame is the image written: its cut rays decide (render's common check).
        truncated_rays: Some(written.map_or(0, |f| f.truncated_rays)),
        // The written frame's fallback pixels (not exact; 0 unless --stream-fallback).
        fallback_pixels: Some(written.map_or(0, |f| f.fallback_pixels)),
        stream: Some(StreamRunStats {
            frames: frames.iter().map(Into::into).collect(),
            totals: (&sr.totals()).into(),
            floor: (&floor).into(),
            max_passes: sr.max_passes(),
            startup,
            cache: cache.as_ref().map(|c| (&c.stats()).into()),
            mean_passes_after_first: (!after_first.is_empty())
                .then(|| after_first.iter().sum::<f64>() / after_first.len() as f64),
        }),
        stream_fit,
        pipeline_executables: crate::stats::captured_pipelines(&ctx),
        ..PathStats::new(FrameStats::gpu(&out.stats))
    };
    drop(sr);
    ctx.check_validation()
        .map_err(|e| RenderError::Validation(e.into()))?;
    Ok(Streamed {
        rendered: (out.aov, out.rgba8, stats),
        camera: last_camera,
        cache,
    })
}

/// The settings of the full build that renders a `--stream` job whose budget holds the whole
/// scene: the same, without streaming (so BLASes build as a full build's unless
/// `--blas-build` says otherwise).
pub(crate) fn full_build_settings(s: &RenderSettings) -> RenderSettings {
    RenderSettings {
        stream: None,
        ..s.clone()
    }
}

/// What [`render_full_if_it_fits`] did.
enum Fit {
    /// The full build rendered the job (the image and the last camera).
    Rendered(Box<(Rendered, CameraParams)>),
    /// The budget does not hold the scene (or the full build was refused): stream it.
    Streams(StreamFitStats),
}

/// A streamed render is never slower than the full build: when the budget holds the whole
/// scene (an upper bound of the full build's peak, `motu_gpu::full_build_fits`), the full build
/// renders the same cameras the stream would (the sweep or the recorded path), on the device
/// already open. A full build the allocator refuses after all falls back to streaming, said.
fn render_full_if_it_fits(
    s: &RenderSettings,
    job: &crate::RenderJob<'_>,
    backend: Backend,
    ctx: &motu_gpu::Context,
    progress: &mut dyn FnMut(RenderEvent<'_>),
) -> Result<Fit, RenderError> {
    let (pkg, view) = (job.package, job.view);
    let full = full_build_settings(s);
    let (pose, w, h) = camera_pose(
        pkg,
        view,
        s.camera.name.as_deref(),
        s.camera.width,
        s.camera.height,
    )?;
    let cams: Vec<CameraParams> = match job.recorded {
        Some(r) => r.to_vec(),
        None => {
            let path = crate::sweep_around_root(view, &pose);
            (0..s.frames)
                .map(|f| camera_path(&pose, &path, f, s.frames).params(w, h))
                .collect()
        }
    };
    let (w, h) = cams
        .iter()
        .fold((w, h), |(w, h), c| (w.max(c.width), h.max(c.height)));
    let t = Instant::now();
    let fit = tracing::info_span!("full_build_fits")
        .in_scope(|| {
            motu_gpu::full_build_fits(
                ctx,
                view,
                w,
                h,
                s.device.vram_budget_bytes.unwrap_or(u64::MAX),
                full.blas_build(),
            )
        })
        .map_err(RenderError::Build)?;
    let mut stats = StreamFitStats {
        budget_bytes: fit.budget_bytes,
        full_build_upper_bytes: fit.upper_bytes,
        full_build: fit.fits(),
        check_ms: ms_since(t),
    };
    tracing::info!(
        budget_bytes = fit.budget_bytes,
        upper_bytes = fit.upper_bytes,
        fits = fit.fits(),
        ms = stats.check_ms,
        "does the budget hold the full build?"
    );
    if !fit.fits() {
        return Ok(Fit::Streams(stats));
    }
    progress(RenderEvent::StreamFullBuild {
        budget_bytes: fit.budget_bytes,
        upper_bytes: fit.upper_bytes,
    });
    let instance_lod = job.lod.instance.as_ref();
    let last = *cams.last().ok_or(RenderError::NoFrame)?;
    // One camera renders as `render` does (a recorded path of one camera too). Both renderers
    // give the same image (tests/path_textured.rs); the path renderer once lost textures.
    let rendered = if cams.len() == 1 {
        crate::gpu::render_gpu(
            &full,
            pkg,
            view,
            &last,
            backend,
            instance_lod,
            Some(ctx.clone()),
        )
    } else {
        crate::gpu::render_gpu_path(
            &full,
            pkg,
            view,
            &cams,
            backend,
            instance_lod,
            Some(ctx.clone()),
        )
    };
    match rendered {
        Ok((aov, rgba8, mut path)) => {
            path.stream_fit = Some(stats);
            Ok(Fit::Rendered(Box::new(((aov, rgba8, path), last))))
        }
        Err(e @ RenderError::BuildOverBudget { .. }) => {
            let what = e.to_string();
            progress(RenderEvent::StreamFullBuildRefused { what: &what });
            stats.full_build = false;
            Ok(Fit::Streams(stats))
        }
        Err(e) => Err(e),
    }
}
