//! The GPU renderer: one primary ray per pixel centre through the traversal-shader emulation
//! (backend `pipeline` or `query`), an optional shadow ray, the AOV hit record and the views
//! of the CPU renderer (same hash, palettes, sky and sRGB encoding as motu-trace).
//!
//! Everything stays on the GPU until one final copy of the AOV, the colours and the counters;
//! frame times come from timestamps around each dispatch (median over `frames`, the first of
//! several being a warm-up left out).

mod frame;
mod options;
mod output;
mod params;
mod tracer;

use motu_abi::camera::CameraParams;
use motu_vk::Context;

use crate::error::{GpuError, Result};
use crate::scene::GpuScene;

pub(crate) use frame::{alloc_frame, frame_bytes, run_frames, Frame, FrameResult};
pub use options::{Backend, RenderOptions, View};
use output::RENDER_STAT_WORDS;
pub(crate) use output::{
    check_texture_residency, frame_outputs, FrameMeasure, STAT_MARK_TLAS_WALKS, STAT_MARK_WALKS,
    STAT_PROXY_EXACT_TESTS, STAT_PROXY_MEMBER_TESTS, STAT_SHADOW_RAYS, STAT_TLAS_WALKS,
    STAT_TRUNCATED_RAYS, STAT_WORDS,
};
pub use output::{heat_colour, RayCounts, RenderOutput, RenderStats};
pub(crate) use params::{frame_params, params_bytes, write_params, FrameParams};
pub(crate) use tracer::Tracer;
pub use tracer::MAX_STACK_SIZE;

/// Renders `scene` as seen by `camera`.
pub fn render(
    ctx: &Context,
    scene: &GpuScene,
    camera: &CameraParams,
    opts: &RenderOptions,
) -> Result<RenderOutput> {
    render_counted(ctx, scene, camera, opts).map(|(out, _)| out)
}

/// [`render`], also returning the [`RayCounts`] of the last frame.
pub fn render_counted(
    ctx: &Context,
    scene: &GpuScene,
    camera: &CameraParams,
    opts: &RenderOptions,
) -> Result<(RenderOutput, RayCounts)> {
    let (w, h) = (camera.width, camera.height);
    if w == 0 || h == 0 || u64::from(w) * u64::from(h) > (1 << 28) {
        return Err(GpuError::InvalidRequest(format!(
            "image size {w}×{h} is invalid"
        )));
    }
    let span = tracing::info_span!(
        "render",
        backend = opts.backend.name(),
        width = w,
        height = h
    );
    let _g = span.enter();
    let params = frame_params(camera, opts, scene.root_tlas, scene.shading_address);
    let pixels = u64::from(w) * u64::from(h);
    let frames = opts.frames.max(1);
    let mut heap = scene.heap();
    let tracer = Tracer::new(ctx, &mut heap, opts, scene.pi_capacity, false, false)?;
    let frame = match alloc_frame(&mut heap, pixels, &params, &opts.shading) {
        Ok(f) => f,
        Err(e) => {
            if let Tracer::Pipeline(p) = tracer {
                p.release(&mut heap);
            }
            return Err(e);
        }
    };
    let result = run_frames(ctx, scene, &tracer, &frame, w, h, frames);
    let alloc = heap.report();
    frame.release(&mut heap);
    if let Tracer::Pipeline(p) = tracer {
        p.release(&mut heap);
    }
    drop(heap);
    let FrameResult {
        records,
        rgba_words,
        counters,
        frame_ns,
    } = result?;

    let (aov, rgba8, heatmap_max, exposure_ev) = frame_outputs(w, h, records, &rgba_words, opts);
    // The first of several frames is a warm-up (caches, pipeline first use): not in the median.
    let mut sorted = if frame_ns.len() > 1 {
        frame_ns[1..].to_vec()
    } else {
        frame_ns.clone()
    };
    sorted.sort_by(f64::total_cmp);
    let ms = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0) / 1e6;
    let stats = RenderStats::measured(
        opts,
        FrameMeasure {
            width: w,
            height: h,
            frames,
            ms_per_frame: ms,
            primary_rays: pixels,
            aov: &aov,
            counters: &counters,
            heatmap_max,
            exposure_ev,
            as_bytes: scene.report().as_bytes,
            alloc,
            passes: 1,
        },
    );
    tracing::info!(
        ms = stats.ms_per_frame,
        rays = stats.rays,
        overflows = stats.stack_overflows,
        "gpu render done"
    );
    let counts = RayCounts {
        truncated_rays: u64::from(counters[STAT_TRUNCATED_RAYS]),
    };
    Ok((RenderOutput { aov, rgba8, stats }, counts))
}

#[cfg(test)]
mod tests;
