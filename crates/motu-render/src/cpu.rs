//! The CPU reference render with instance-level LOD (what `motu render --backend cpu` runs when
//! the LOD mode is `instance`).

use crate::RenderError;
use motu_abi::camera::CameraParams;
use motu_abi::lod_instance::InstanceLod;
use motu_abi::HierarchyView;
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
