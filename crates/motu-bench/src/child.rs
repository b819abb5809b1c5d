//! The hidden `--child-render PKG` mode: one timed render in its own process.

use crate::error::{gpu_err, io, BenchError};
use crate::plan::Backend;
use crate::report::RenderMetrics;
use motu_abi::camera::CameraParams;
use motu_abi::HierarchyView;
use motu_import::peak_rss_bytes;
use std::path::PathBuf;
use std::time::Instant;

/// The hidden `--child-render PKG` mode's options.
#[derive(Clone, Debug)]
pub struct ChildRender {
    pub backend: Option<Backend>,
    pub frames: Option<u32>,
    pub warmup: Option<u32>,
    /// Where the [`RenderMetrics`] JSON goes (`--child-stats`).
    pub stats_path: PathBuf,
    pub png: Option<PathBuf>,
    /// When the child started (before opening the package), for `wall_s`.
    pub started: Instant,
}

/// `--child-render PKG`: build, warm up, time `frames` frames, write [`RenderMetrics`] as JSON.
/// The caller opens the package and picks the camera (`view`, `camera`, `meshes`).
pub fn child_render<M>(
    a: &ChildRender,
    view: HierarchyView<'_>,
    camera: &CameraParams,
    meshes: &M,
) -> Result<(), BenchError>
where
    M: motu_trace::MeshSource + motu_gpu::MeshBlobSource,
{
    let t0 = a.started;
    let stats_path = &a.stats_path;
    let frames = a.frames.unwrap_or(21).max(1);
    let warmup = a.warmup.unwrap_or(1);
    let camera = *camera;
    let backend = a.backend.unwrap_or(Backend::Query);
    let mut m = RenderMetrics {
        backend: backend.name().into(),
        width: camera.width,
        height: camera.height,
        warmup_frames: warmup,
        frames,
        ..Default::default()
    };
    let rgba8 = match backend {
        Backend::Cpu => {
            let tracer =
                motu_trace::Tracer::new(view, meshes).map_err(|source| BenchError::Trace {
                    what: "preparing the CPU tracer",
                    source,
                })?;
            let opts = motu_trace::RenderOptions::default();
            // The first frame builds every reachable BVH (`prepare`): that is the build time.
            let first = motu_trace::render_with(&tracer, &camera, &opts).map_err(|source| {
                BenchError::Trace {
                    what: "rendering on the CPU",
                    source,
                }
            })?;
            m.as_build_ms = first.stats.prepare_ms;
            let timed = motu_trace::RenderOptions {
                prepare: false,
                ..opts
            };
            for _ in 1..warmup {
                motu_trace::render_with(&tracer, &camera, &timed)
                    .map_err(BenchError::TraceFrame)?;
            }
            let mut times = Vec::with_capacity(frames as usize);
            let mut last = first;
            for _ in 0..frames {
                let t = Instant::now();
                let o = motu_trace::render_with(&tracer, &camera, &timed)
                    .map_err(BenchError::TraceFrame)?;
                times.push(t.elapsed().as_secs_f64() * 1e3);
                last = o;
            }
            m.ms_per_frame = median(&mut times);
            m.device = format!("CPU ({} threads)", last.stats.threads);
            m.rays = last.stats.rays;
            m.traces_per_ray = last.stats.traces_per_ray;
            m.stack_overflows = last.stats.stack_overflows;
            last.rgba8
        }
        Backend::Pipeline | Backend::Query => {
            use motu_gpu::{Context as GpuContext, ContextOptions, Requirement};
            let ctx = GpuContext::new(&ContextOptions {
                require: if backend == Backend::Query {
                    Requirement::RayQuery
                } else {
                    Requirement::RayPipeline
                },
                ..Default::default()
            })
            .map_err(gpu_err(
                "opening a Vulkan device for ray tracing (`motu devices` lists them)",
            ))?;
            m.device = ctx.device_name().to_string();
            let scene =
                motu_gpu::GpuScene::build(&ctx, &view, meshes, &motu_gpu::BuildOptions::default())
                    .map_err(gpu_err("building acceleration structures"))?;
            let res = scene.report();
            m.as_build_ms = res.build_ms;
            m.blas_bytes = res.blas_bytes;
            m.blas_compacted_bytes = res.blas_compacted_bytes;
            m.tlas_bytes = res.tlas_bytes;
            m.tlas_compacted_bytes = res.tlas_compacted_bytes;
            m.geometry_bytes = res.geometry_bytes;
            m.scratch_peak_bytes = res.scratch_peak_bytes;
            let opts = motu_gpu::RenderOptions {
                backend: if backend == Backend::Query {
                    motu_gpu::Backend::Query
                } else {
                    motu_gpu::Backend::Pipeline
                },
                frames: warmup.max(1),
                ..Default::default()
            };
            // Warm-up in its own submission: its frames never enter the timed median.
            if warmup > 0 {
                motu_gpu::render(&ctx, &scene, &camera, &opts)
                    .map_err(gpu_err("warm-up frames"))?;
            }
            let out = motu_gpu::render(
                &ctx,
                &scene,
                &camera,
                &motu_gpu::RenderOptions { frames, ..opts },
            )
            .map_err(gpu_err("timed frames"))?;
            let st = &out.stats;
            m.ms_per_frame = st.ms_per_frame;
            m.rays = st.rays;
            m.traces_per_ray = st.traces_per_ray;
            m.stack_overflows = st.stack_overflows;
            m.as_bytes = st.as_bytes;
            m.vram_peak_bytes = st.vram_peak_bytes;
            m.allocation_count = st.allocation_count;
            drop(scene);
            ctx.check_validation()
                .map_err(gpu_err("Vulkan validation reported errors"))?;
            out.rgba8
        }
    };
    m.fps = if m.ms_per_frame > 0.0 {
        1e3 / m.ms_per_frame
    } else {
        0.0
    };
    m.rays_per_second = if m.ms_per_frame > 0.0 {
        m.rays as f64 / (m.ms_per_frame / 1e3)
    } else {
        0.0
    };
    if let Some(png) = &a.png {
        if let Some(dir) = png.parent() {
            std::fs::create_dir_all(dir).map_err(io(format!("creating {}", dir.display())))?;
        }
        motu_trace::write_png(png, camera.width, camera.height, &rgba8).map_err(|source| {
            BenchError::PngWrite {
                what: format!("writing {}", png.display()),
                source,
            }
        })?;
    }
    m.peak_rss_bytes = peak_rss_bytes().unwrap_or(0);
    m.wall_s = t0.elapsed().as_secs_f64();
    std::fs::write(stats_path, serde_json::to_string_pretty(&m)?)
        .map_err(io(format!("writing {}", stats_path.display())))?;
    Ok(())
}

pub(crate) fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(0.0)
}
