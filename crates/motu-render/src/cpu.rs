//! The CPU reference render (`motu render --backend cpu`), with instance-level LOD when the LOD
//! mode is `instance`.

use crate::gpu::{PathStats, Rendered};
use crate::settings::RenderSettings;
use crate::stats::FrameStats;
use crate::{scene_shading, PackageMeshes, RenderError};
use motu_abi::camera::CameraParams;
use motu_abi::lod::LodParams;
use motu_abi::lod_instance::InstanceLod;
use motu_abi::HierarchyView;
use motu_pack::ScenePackage;
use motu_trace::{MeshSource, RenderOptions, RenderOutput};

/// Per camera, each slot's level from the same rule as the GPU's compute pass (`opts.lod`),
/// then a trace of the rewritten hierarchy. Returns the last frame and the median of the
/// frames' times in milliseconds.
pub fn render_cpu_instance_lod(
    view: &HierarchyView<'_>,
    meshes: &dyn MeshSource,
    il: &InstanceLod,
    opts: &RenderOptions,
    cameras: &[CameraParams],
) -> Result<(RenderOutput, f64), RenderError> {
    let cpu = |what| move |source| RenderError::Cpu { what, source };
    let mut times = Vec::with_capacity(cameras.len());
    let mut last = None;
    for cam in cameras {
        let mut frame = il.clone();
        let levels = frame.levels(view, &opts.lod, cam.pixels_per_unit_at_1, cam.world_eye);
        frame.apply_levels(view, &levels);
        let v = frame.view(view);
        let tracer = motu_trace::Tracer::new(v, meshes).map_err(cpu("preparing the CPU tracer"))?;
        let out =
            motu_trace::render_with(&tracer, cam, opts).map_err(cpu("rendering on the CPU"))?;
        times.push(out.stats.ms_per_frame);
        last = Some(out);
    }
    let out = last.ok_or(RenderError::NoFrame)?;
    times.sort_by(f64::total_cmp);
    Ok((out, times[times.len() / 2]))
}

/// The CPU reference render of `cameras` (timed over them; the first prepares the tracer):
/// the last frame, its stats with `ms_per_frame` the median and `frames` the count; with
/// instance LOD (`il`), levels per camera as [`render_cpu_instance_lod`].
pub(crate) fn render_cpu(
    s: &RenderSettings,
    pkg: &ScenePackage,
    view: &HierarchyView<'_>,
    lod: LodParams,
    il: Option<&InstanceLod>,
    cameras: &[CameraParams],
) -> Result<Rendered, RenderError> {
    let meshes = PackageMeshes(pkg);
    let opts = RenderOptions {
        view: trace_view(s.view),
        lod,
        max_traces_per_ray: s.limits.max_traces_per_ray,
        shading: scene_shading(s.shading, pkg, view),
        ..Default::default()
    };
    let (out, median) = match il {
        Some(il) => render_cpu_instance_lod(view, &meshes, il, &opts, cameras)?,
        None => {
            let cpu = |what| move |source| RenderError::Cpu { what, source };
            let tracer =
                motu_trace::Tracer::new(*view, &meshes).map_err(cpu("preparing the CPU tracer"))?;
            let mut out = motu_trace::render_with(&tracer, &cameras[0], &opts)
                .map_err(cpu("rendering on the CPU"))?;
            let mut times = vec![out.stats.ms_per_frame];
            for cam in &cameras[1..] {
                let o = motu_trace::render_with(
                    &tracer,
                    cam,
                    &RenderOptions {
                        prepare: false,
                        ..opts
                    },
                )?;
                times.push(o.stats.ms_per_frame);
                out = o;
            }
            times.sort_by(f64::total_cmp);
            (out, times[times.len() / 2])
        }
    };
    let (mut frame, truncated_rays) = FrameStats::cpu(
        &out.stats,
        cameras.len() as u64,
        s.device.vram_budget_bytes.unwrap_or(0),
    );
    frame.ms_per_frame = median;
    let stats = PathStats {
        truncated_rays: Some(truncated_rays),
        ..PathStats::new(frame)
    };
    Ok((out.aov, out.rgba8, stats))
}

/// The CPU tracer's view of the GPU's (the two crates' enums name the same views).
fn trace_view(v: motu_gpu::View) -> motu_trace::View {
    match v {
        motu_gpu::View::Shaded => motu_trace::View::Shaded,
        motu_gpu::View::Ids => motu_trace::View::Ids,
        motu_gpu::View::Lod => motu_trace::View::Lod,
        motu_gpu::View::Heatmap => motu_trace::View::Heatmap,
        motu_gpu::View::Albedo => motu_trace::View::Albedo,
    }
}
