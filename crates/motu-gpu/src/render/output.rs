//! What a frame yields: its image and AOV ([`RenderOutput`]), the measured [`RenderStats`]
//! and [`RayCounts`], and the stats words every renderer reads back from the GPU.

use motu_abi::aov::{Aov, AovRecord};

use super::{RenderOptions, View};
use crate::error::Result;

/// What one frame measured: the CLI contract's `--stats` keys and detail (the JSON is
/// `motu_render::stats::FrameStats`).
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderStats {
    pub width: u32,
    pub height: u32,
    pub backend: &'static str,
    pub view: View,
    pub frames: u32,
    /// Median GPU time of one frame's dispatch (timestamps).
    pub ms_per_frame: f64,
    /// Primary plus shadow rays of one frame.
    pub rays: u64,
    pub primary_rays: u64,
    pub shadow_rays: u64,
    pub rays_per_second: f64,
    /// TLAS walks (traceRayEXT / ray queries) of one frame.
    pub traces: u64,
    pub traces_per_ray: f64,
    pub stack_size: u32,
    pub stack_overflows: u64,
    /// TLAS walks whose candidate list was full (re-walked for the rest, never dropped).
    pub pi_list_overflows: u64,
    /// The heatmap's red end: the most traces spent on one pixel.
    pub heatmap_max: u32,
    /// The exposure the shaded image was tone-mapped with, in stops (auto exposure's choice).
    pub exposure_ev: f32,
    pub as_bytes: u64,
    pub vram_budget_bytes: u64,
    pub vram_peak_bytes: u64,
    pub allocation_count: u32,
    pub passes: u32,
}

/// What one rendered frame measured (every renderer: full builds, the viewer's live renderer,
/// streaming), turned into [`RenderStats`] in one place.
pub(crate) struct FrameMeasure<'a> {
    pub width: u32,
    pub height: u32,
    pub frames: u32,
    pub ms_per_frame: f64,
    /// Pixels traced (streaming adds the re-shot ones).
    pub primary_rays: u64,
    pub aov: &'a Aov,
    /// The frame's stats words (`STAT_WORDS`).
    pub counters: &'a [u32],
    pub heatmap_max: u32,
    pub exposure_ev: f32,
    pub as_bytes: u64,
    pub alloc: motu_alloc::AllocReport,
    pub passes: u32,
}

impl RenderStats {
    pub(crate) fn measured(opts: &RenderOptions, m: FrameMeasure<'_>) -> Self {
        let shadow = u64::from(m.counters[STAT_SHADOW_RAYS]);
        let rays = m.primary_rays + shadow;
        let traces: u64 = m.aov.records.iter().map(|r| u64::from(r.traces)).sum();
        let ms = m.ms_per_frame;
        Self {
            width: m.width,
            height: m.height,
            backend: opts.backend.name(),
            view: opts.view,
            frames: m.frames,
            ms_per_frame: ms,
            rays,
            primary_rays: m.primary_rays,
            shadow_rays: shadow,
            rays_per_second: if ms > 0.0 {
                rays as f64 / (ms / 1e3)
            } else {
                0.0
            },
            traces,
            traces_per_ray: traces as f64 / rays.max(1) as f64,
            stack_size: opts.stack_size,
            stack_overflows: u64::from(m.counters[0]),
            pi_list_overflows: u64::from(m.counters[1]),
            heatmap_max: m.heatmap_max,
            exposure_ev: m.exposure_ev,
            as_bytes: m.as_bytes,
            vram_budget_bytes: m.alloc.budget_bytes,
            vram_peak_bytes: m.alloc.peak_block_bytes,
            allocation_count: m.alloc.peak_allocation_count,
            passes: m.passes,
        }
    }
}

#[derive(Clone, Debug)]
pub struct RenderOutput {
    pub aov: Aov,
    /// `width × height × 4`, row 0 at the top.
    pub rgba8: Vec<u8>,
    pub stats: RenderStats,
}

/// Stats words of every renderer's buffers (full builds, streaming, the viewer), indexed by
/// the `STAT_*` of `common.glsl`.
pub(crate) const STAT_WORDS: usize = 11;
pub(super) const RENDER_STAT_WORDS: usize = STAT_WORDS;
/// Secondary rays traced (shadow, AO, bounce).
pub(crate) const STAT_SHADOW_RAYS: usize = 2;
/// Rays cut short by a stack overflow or the trace cap.
pub(crate) const STAT_TRUNCATED_RAYS: usize = 4;
/// Texture reads that found a streamed texture not resident.
pub(crate) const STAT_MISSING_TEXTURES: usize = 5;
/// Streamed passes only: TLAS walks of the rays' walks, mark walks, and the TLAS walks of
/// those mark walks (`stream::PassStats`).
pub(crate) const STAT_TLAS_WALKS: usize = 6;
pub(crate) const STAT_MARK_WALKS: usize = 7;
pub(crate) const STAT_MARK_TLAS_WALKS: usize = 8;
/// Streamed passes of the query backend only: proxy member boxes tested (quantised), and the
/// exact member tests among them (`stream::PassStats`).
pub(crate) const STAT_PROXY_MEMBER_TESTS: usize = 9;
pub(crate) const STAT_PROXY_EXACT_TESTS: usize = 10;

/// Fails a frame whose shading read a texture that was not resident: the pixel would show the
/// material's constant colour, a wrong image. A resident mesh holds its textures, so this is a
/// broken residency invariant, never a budget matter.
pub(crate) fn check_texture_residency(counters: &[u32]) -> Result<()> {
    match counters.get(STAT_MISSING_TEXTURES).copied().unwrap_or(0) {
        0 => Ok(()),
        n => Err(crate::error::GpuError::InvalidRequest(format!(
            "{n} texture reads found their texture not resident (a streaming residency bug): \
             the frame would show constant material colours, so it is refused"
        ))),
    }
}

/// Counts of one render beyond [`RenderStats`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    /// Rays whose traversal was cut short: a stack overflow dropped an entry, or the ray
    /// reached `max_traces_per_ray`. Their hit may be wrong.
    pub truncated_rays: u64,
}

/// The frame's AOV and image from the read-back records and colours; the heatmap view is
/// coloured here, against the frame's most traces (returned).
pub(crate) fn frame_outputs(
    w: u32,
    h: u32,
    records: Vec<AovRecord>,
    rgba_words: &[u32],
    opts: &RenderOptions,
) -> (Aov, Vec<u8>, u32, f32) {
    let view = opts.view;
    let mut aov = Aov::new(w, h);
    aov.records = records;
    let heatmap_max = aov
        .records
        .iter()
        .map(|r| u32::from(r.traces))
        .max()
        .unwrap_or(0);
    let mut rgba8: Vec<u8> = bytemuck::cast_slice(rgba_words).to_vec();
    if view == View::Heatmap {
        for (r, px) in aov.records.iter().zip(rgba8.chunks_exact_mut(4)) {
            let c = heat_colour(f32::from(r.traces) / heatmap_max.max(1) as f32);
            px[..3].copy_from_slice(&c.map(|v| (v * 255.0 + 0.5) as u8));
            px[3] = 255;
        }
    }
    // Auto exposure: the shader wrote linear RGB9E5; tone-map with the whole image's exposure.
    let exposure_ev = if view == View::Shaded && opts.shading.auto_exposure {
        resolve_auto_exposure_parallel(&mut rgba8)
    } else {
        opts.shading.exposure_ev
    };
    (aov, rgba8, heatmap_max, exposure_ev)
}

/// [`motu_abi::shade::resolve_auto_exposure`] on rayon threads, to the bit: the log terms are
/// summed in pixel order, each pixel is tone-mapped alone. Sequentially it took 15–20 ms of a
/// 640×360 frame on the host after the GPU was done (three `powf` and a `ln` a pixel), a
/// quarter of a 20 frames/s budget.
pub(crate) fn resolve_auto_exposure_parallel(rgba8: &mut [u8]) -> f32 {
    use motu_abi::shade::{decode_rgb9e5, exposure_ev_of_logs, log_luminance, tone_map};
    use rayon::prelude::*;
    const PIXELS_PER_TASK: usize = 4096;
    let word = |p: &[u8]| u32::from_le_bytes([p[0], p[1], p[2], p[3]]);
    let logs: Vec<Option<f64>> = rgba8
        .par_chunks_exact(4)
        .map(|p| log_luminance(decode_rgb9e5(word(p))))
        .collect();
    let ev = exposure_ev_of_logs(logs.into_iter().flatten());
    let scale = ev.exp2();
    let whole = rgba8.len() / 4 * 4;
    rgba8[..whole]
        .par_chunks_mut(PIXELS_PER_TASK * 4)
        .for_each(|task| {
            for p in task.chunks_exact_mut(4) {
                let c = tone_map(decode_rgb9e5(word(p)), scale);
                p[..3].copy_from_slice(&c);
                p[3] = 255;
            }
        });
    ev
}

/// Blue → cyan → green → yellow → red for `v` in [0, 1] (motu-trace's heat colours).
pub fn heat_colour(v: f32) -> [f32; 3] {
    let v = v.clamp(0.0, 1.0) * 4.0;
    let f = v.fract();
    match v as u32 {
        0 => [0.0, f, 1.0],
        1 => [0.0, 1.0, 1.0 - f],
        2 => [f, 1.0, 0.0],
        3 => [1.0, 1.0 - f, 0.0],
        _ => [1.0, 0.0, 0.0],
    }
}

#[cfg(test)]
mod tests;
