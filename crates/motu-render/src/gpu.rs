//! Full GPU builds and renders: the device under `--vram-budget`, the package's structures
//! built on it, one frame (timed over `frames`) or one per recorded camera.

use crate::settings::RenderSettings;
use crate::stats::{FrameStats, FullBuildStats, StreamRunStats};
use crate::{scene_shading, Backend, PackageMeshes, RenderError};
use motu_abi::aov::Aov;
use motu_abi::camera::CameraParams;
use motu_abi::lod::LodParams;
use motu_abi::lod_instance::InstanceLod;
use motu_abi::HierarchyView;
use motu_pack::ScenePackage;

/// An image and its render path's `--stats` keys.
pub(crate) type Rendered = (Aov, Vec<u8>, PathStats);

/// What a render path reports: the frame written and the path's own keys (the session adds
/// its keys to make [`crate::stats::RenderStats`]).
#[derive(Debug)]
pub(crate) struct PathStats {
    pub frame: FrameStats,
    pub truncated_rays: Option<u64>,
    pub full_build: Option<FullBuildStats>,
    pub path_ms_per_frame: Option<Vec<f64>>,
    pub fallback_pixels: Option<u64>,
    pub stream: Option<StreamRunStats>,
    pub stream_fit: Option<crate::stats::StreamFitStats>,
    /// `--pipeline-stats`: the pipelines the path made.
    pub pipeline_executables: Option<Vec<crate::stats::PipelineStats>>,
}

impl PathStats {
    /// `frame` and none of the paths' keys.
    pub fn new(frame: FrameStats) -> Self {
        Self {
            frame,
            truncated_rays: None,
            full_build: None,
            path_ms_per_frame: None,
            fallback_pixels: None,
            stream: None,
            stream_fit: None,
            pipeline_executables: None,
        }
    }
}

pub(crate) fn gpu_context(
    s: &RenderSettings,
    backend: Backend,
) -> Result<motu_gpu::Context, RenderError> {
    use motu_gpu::{ContextOptions, LimitOverrides, Requirement};
    let ctx = motu_gpu::Context::new(&ContextOptions {
        device_index: s.device.index,
        limit_overrides: LimitOverrides {
            max_memory_allocation_count: s.device.max_allocations,
            ..Default::default()
        },
        require: match backend {
            Backend::Query => Requirement::RayQuery,
            _ => Requirement::RayPipeline,
        },
        pipeline_stats: s.device.pipeline_stats,
        ..Default::default()
    })
    .map_err(|e| RenderError::Device(e.into()))?;
    check_vram_budget(s.device.vram_budget_bytes, &ctx)?;
    Ok(ctx)
}

/// `--vram-budget` above what the device has is a mistake (a unit typo), not a wish to clamp.
fn check_vram_budget(budget: Option<u64>, ctx: &motu_gpu::Context) -> Result<(), RenderError> {
    let Some(b) = budget else { return Ok(()) };
    let device_bytes = ctx
        .heaps()
        .iter()
        .filter(|h| h.device_local)
        .map(|h| h.size_bytes)
        .max()
        .unwrap_or(0);
    if device_bytes > 0 && b > device_bytes {
        return Err(RenderError::BudgetAboveDevice {
            budget_bytes: b,
            device: ctx.device_name().to_string(),
            device_bytes,
        });
    }
    Ok(())
}

pub(crate) fn gpu_render_options(
    s: &RenderSettings,
    lod: LodParams,
    backend: Backend,
    frames: u32,
    shading: motu_abi::shade::Shading,
) -> motu_gpu::RenderOptions {
    motu_gpu::RenderOptions {
        backend: match backend {
            Backend::Query => motu_gpu::Backend::Query,
            _ => motu_gpu::Backend::Pipeline,
        },
        view: s.view,
        lod,
        stack_size: s.limits.stack_size,
        max_traces_per_ray: s.limits.max_traces_per_ray,
        frames,
        shading,
        ..Default::default()
    }
}

/// The device and the package's structures built on it (a full build: `render` and
/// `render --camera-path`).
fn build_gpu_scene(
    s: &RenderSettings,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    backend: Backend,
    instance_lod: Option<&InstanceLod>,
    ctx: Option<motu_gpu::Context>,
) -> Result<(motu_gpu::Context, motu_gpu::GpuScene), RenderError> {
    let ctx = match ctx {
        Some(c) => c,
        None => gpu_context(s, backend)?,
    };
    let meshes = PackageMeshes(pkg);
    let scene = build_scene(
        &ctx,
        view,
        &meshes,
        s.device.vram_budget_bytes,
        s.device.max_allocations,
        s.blas_build(),
        instance_lod,
    )?;
    Ok((ctx, scene))
}

/// `view`'s structures built on `ctx` under `--vram-budget` and `--max-allocations` (a full
/// build: `motu render` and `motu view`); with instance-level LOD the rewritten hierarchy is
/// built and a per-frame pass picks each LOD instance's level.
pub fn build_scene(
    ctx: &motu_gpu::Context,
    view: &HierarchyView<'_>,
    meshes: &dyn motu_gpu::MeshBlobSource,
    vram_budget_bytes: Option<u64>,
    max_allocations: Option<u32>,
    blas_build: motu_gpu::BlasBuild,
    instance_lod: Option<&InstanceLod>,
) -> Result<motu_gpu::GpuScene, RenderError> {
    let budget = vram_budget_bytes.unwrap_or(u64::MAX);
    let build = motu_gpu::BuildOptions {
        budget_bytes: budget,
        max_allocations: max_allocations
            .unwrap_or(motu_gpu::BuildOptions::default().max_allocations),
        blas_build,
        // The staging ring (64 MiB, less under a budget) is motu-gpu's policy, the one
        // `motu report` counts.
        ..Default::default()
    };
    let built = match instance_lod {
        Some(il) => il.view(view),
        None => *view,
    };
    let mut scene =
        motu_gpu::GpuScene::build(ctx, &built, meshes, &build).map_err(|e| match e {
            motu_gpu::GpuError::Budget(_) => RenderError::BuildOverBudget {
                blas_build: blas_build.name(),
                source: e,
            },
            e => RenderError::Build(e),
        })?;
    if let Some(il) = instance_lod {
        scene
            .enable_instance_lod(view, il)
            .map_err(RenderError::InstanceLodSetup)?;
    }
    Ok(scene)
}

/// Builds the package's structures on the GPU under the budget and renders with a traversal
/// shader backend.
pub(crate) fn render_gpu(
    s: &RenderSettings,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    camera: &CameraParams,
    backend: Backend,
    instance_lod: Option<&InstanceLod>,
    ctx: Option<motu_gpu::Context>,
) -> Result<Rendered, RenderError> {
    let (ctx, scene) = build_gpu_scene(s, pkg, view, backend, instance_lod, ctx)?;
    let opts = gpu_render_options(
        s,
        s.lod,
        backend,
        s.frames,
        scene_shading(s.shading, pkg, view),
    );
    let (out, counts) =
        motu_gpu::render_counted(&ctx, &scene, camera, &opts).map_err(RenderError::Gpu)?;
    let stats = PathStats {
        truncated_rays: Some(counts.truncated_rays),
        full_build: Some(FullBuildStats::of(&scene)),
        pipeline_executables: crate::stats::captured_pipelines(&ctx),
        ..PathStats::new(FrameStats::gpu(&out.stats))
    };
    drop(scene);
    ctx.check_validation()
        .map_err(|e| RenderError::Validation(e.into()))?;
    Ok((out.aov, out.rgba8, stats))
}

/// A recorded camera path on a full GPU build: one frame per camera through the viewer's
/// renderer (pipeline compiled once); the last frame is the output, every frame's time is in
/// `path_ms_per_frame`.
pub(crate) fn render_gpu_path(
    s: &RenderSettings,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    cams: &[CameraParams],
    backend: Backend,
    instance_lod: Option<&InstanceLod>,
    ctx: Option<motu_gpu::Context>,
) -> Result<Rendered, RenderError> {
    let (ctx, scene) = build_gpu_scene(s, pkg, view, backend, instance_lod, ctx)?;
    let opts = gpu_render_options(s, s.lod, backend, 1, scene_shading(s.shading, pkg, view));
    let mut live = motu_gpu::LiveRenderer::new(scene);
    let mut times = Vec::with_capacity(cams.len());
    let mut last = None;
    for (f, cam) in cams.iter().enumerate() {
        let out = live
            .render_frame(cam, &opts)
            .map_err(|source| RenderError::PathFrame { frame: f, source })?;
        times.push(out.stats.ms_per_frame);
        last = Some(out);
    }
    let out = last.ok_or(RenderError::EmptyCameraPath)?;
    let mut frame = FrameStats::gpu(&out.stats);
    // The first frame is a warm-up (pipeline first use): left out of the median.
    let timed = if times.len() > 1 {
        &times[1..]
    } else {
        &times[..]
    };
    let mut timed = timed.to_vec();
    timed.sort_by(f64::total_cmp);
    frame.ms_per_frame = timed[timed.len() / 2];
    frame.frames = cams.len() as u64;
    let stats = PathStats {
        full_build: Some(FullBuildStats::of(live.scene())),
        path_ms_per_frame: Some(times),
        pipeline_executables: crate::stats::captured_pipelines(&ctx),
        ..PathStats::new(frame)
    };
    drop(live);
    ctx.check_validation()
        .map_err(|e| RenderError::Validation(e.into()))?;
    Ok((out.aov, out.rgba8, stats))
}
