//! The CPU renderer: one primary ray per pixel centre (`CameraParams::primary_dir`, offset 0.5),
//! the AOV hit record, and the PNG views shared with the GPU backends.

use std::path::Path;
use std::time::Instant;

use motu_abi::aov::{Aov, AovRecord};
use motu_abi::camera::CameraParams;
use motu_abi::lod::RAY_PRIMARY;
use motu_abi::shade::{encode_rgb9e5, rand01, resolve_auto_exposure, tone_map};
use motu_abi::HierarchyView;
use rayon::prelude::*;

use crate::mesh::MeshSource;
use crate::ray::normalize;
use crate::shade::{shade_vertex, ShadeRays};
use crate::traverse::{RayQuery, Scratch, Tracer};
use crate::TraceError;

pub use crate::options::{RenderOptions, View};
pub use crate::ray::shadow_offset;

/// What a CPU render measured; key names follow the CLI's `--stats` contract where they
/// overlap (the JSON is `motu_render::stats::FrameStats`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RenderStats {
    pub width: u32,
    pub height: u32,
    pub backend: &'static str,
    pub view: View,
    /// Tracing only (after `prepare`).
    pub ms_per_frame: f64,
    pub prepare_ms: f64,
    /// Primary plus shadow rays.
    pub rays: u64,
    pub primary_rays: u64,
    pub shadow_rays: u64,
    pub hits: u64,
    /// TLAS walks in total.
    pub traces: u64,
    pub traces_per_ray: f64,
    pub rays_per_second: f64,
    /// Always 0: the CPU stack grows as needed (see `max_stack_depth`).
    pub stack_overflows: u64,
    /// Pixels whose primary or shadow ray was cut short at `max_traces_per_ray`.
    pub truncated_rays: u64,
    pub max_stack_depth: u32,
    /// The heatmap's red end: the most traces spent on one pixel.
    pub heatmap_max_traces: u32,
    /// The exposure the shaded image was tone-mapped with, in stops (auto exposure's choice).
    pub exposure_ev: f32,
    pub meshes_built: usize,
    pub threads: usize,
}

#[derive(Clone, Debug)]
pub struct RenderOutput {
    pub aov: Aov,
    /// `width × height × 4`, row 0 at the top.
    pub rgba8: Vec<u8>,
    pub stats: RenderStats,
}

/// Renders `view` as seen by `camera`.
pub fn render(
    view: HierarchyView<'_>,
    source: &dyn MeshSource,
    camera: &CameraParams,
    opts: &RenderOptions,
) -> Result<RenderOutput, TraceError> {
    let tracer = Tracer::new(view, source)?;
    render_with(&tracer, camera, opts)
}

#[derive(Default)]
struct RowStats {
    primary: u64,
    shadow: u64,
    hits: u64,
    traces: u64,
    max_stack: u32,
    truncated: u64,
}

impl RowStats {
    fn merge(mut self, o: Self) -> Self {
        self.primary += o.primary;
        self.shadow += o.shadow;
        self.hits += o.hits;
        self.traces += o.traces;
        self.max_stack = self.max_stack.max(o.max_stack);
        self.truncated += o.truncated;
        self
    }
}

/// Renders with an existing tracer (its built structures are reused across frames).
pub fn render_with(
    tracer: &Tracer<'_>,
    camera: &CameraParams,
    opts: &RenderOptions,
) -> Result<RenderOutput, TraceError> {
    let (w, h) = (camera.width, camera.height);
    if w == 0 || h == 0 || (w as u64) * (h as u64) > (1 << 28) {
        return Err(TraceError::Camera(format!("image size {w}×{h} is invalid")));
    }
    let _span = tracing::info_span!("render", backend = "cpu", width = w, height = h).entered();
    let t0 = Instant::now();
    if opts.prepare {
        tracer.prepare()?;
    }
    let prepare_ms = t0.elapsed().as_secs_f64() * 1e3;

    let t1 = Instant::now();
    let mut aov = Aov::new(w, h);
    let mut rgba8 = vec![0u8; w as usize * h as usize * 4];
    let exposure = opts.shading.exposure_scale();
    let auto_exposure = opts.shading.auto_exposure && opts.view == View::Shaded;
    let spp = opts.shading.spp.max(1);
    let totals = aov
        .records
        .par_chunks_mut(w as usize)
        .zip(rgba8.par_chunks_mut(w as usize * 4))
        .enumerate()
        .map_init(Scratch::default, |scratch, (y, (rec_row, px_row))| {
            let mut st = RowStats::default();
            for x in 0..w {
                let pixel = y as u32 * w + x;
                let dir = camera.primary_dir(x, y as u32, 0.5, 0.5).to_array();
                let q = RayQuery {
                    kind: RAY_PRIMARY,
                    lod: opts.lod,
                    pixels_per_unit_at_1: camera.pixels_per_unit_at_1,
                    lod_u: pixel_dither(x, y as u32),
                    max_traces: opts.max_traces_per_ray,
                    ..RayQuery::default()
                };
                let hit = tracer.trace(camera.world_eye, dir, &q, scratch);
                let mut truncated = hit.truncated;
                st.primary += 1;
                st.traces += hit.traces as u64;
                st.max_stack = st.max_stack.max(hit.max_stack);
                let mut traces = hit.traces;
                if hit.is_hit() {
                    st.hits += 1;
                }
                let colour = match opts.view {
                    View::Shaded => {
                        let mut sum = [0.0f32; 3];
                        for local in 0..spp {
                            // The sequence's sample 0 is the pixel centre (the hit record's
                            // ray); a progressive frame starts at `first_sample`.
                            let sample = opts.shading.first_sample + local;
                            let (h, d) = if sample == 0 {
                                (hit, dir)
                            } else {
                                let d = camera
                                    .primary_dir(
                                        x,
                                        y as u32,
                                        rand01(pixel, sample, 0),
                                        rand01(pixel, sample, 1),
                                    )
                                    .to_array();
                                let h = tracer.trace(camera.world_eye, d, &q, scratch);
                                truncated |= h.truncated;
                                st.primary += 1;
                                st.traces += h.traces as u64;
                                traces += h.traces;
                                (h, normalize(d))
                            };
                            let c = if h.is_hit() {
                                let mut rays = ShadeRays::default();
                                let c = shade_path(
                                    tracer,
                                    camera,
                                    opts,
                                    &h,
                                    normalize(d),
                                    pixel,
                                    sample,
                                    scratch,
                                    &mut rays,
                                );
                                st.shadow += rays.rays;
                                st.traces += rays.traces as u64;
                                st.max_stack = st.max_stack.max(rays.max_stack);
                                traces += rays.traces;
                                truncated |= rays.truncated;
                                c
                            } else {
                                background(opts, d)
                            };
                            for (s, v) in sum.iter_mut().zip(c) {
                                *s += v / spp as f32;
                            }
                        }
                        sum
                    }
                    _ if !hit.is_hit() => sky(dir),
                    View::Ids => id_colour(hit.source_mesh, hit.primitive),
                    View::Lod => lod_colour(hit.lod),
                    View::Albedo => crate::shade::hit_albedo(
                        tracer,
                        camera,
                        &hit,
                        camera.world_eye,
                        normalize(dir),
                    ),
                    // Filled in once the frame's maximum is known.
                    View::Heatmap => [0.0; 3],
                };
                rec_row[x as usize] = if hit.is_hit() {
                    AovRecord {
                        mesh: hit.source_mesh,
                        primitive: hit.primitive,
                        t: hit.t,
                        lod: hit.lod.min(255) as u8,
                        _pad: 0,
                        traces: traces.min(u16::MAX as u32) as u16,
                    }
                } else {
                    AovRecord {
                        traces: traces.min(u16::MAX as u32) as u16,
                        ..AovRecord::MISS
                    }
                };
                st.truncated += u64::from(truncated);
                let px = &mut px_row[x as usize * 4..x as usize * 4 + 4];
                if auto_exposure {
                    // Linear until the whole image's exposure is known (as the GPU writes it).
                    px.copy_from_slice(&encode_rgb9e5(colour).to_le_bytes());
                } else {
                    px[..3].copy_from_slice(&if opts.view == View::Shaded {
                        tone_map(colour, exposure)
                    } else {
                        encode_srgb(colour)
                    });
                    px[3] = 255;
                }
            }
            st
        })
        .reduce(RowStats::default, RowStats::merge);
    let heatmap_max = aov
        .records
        .iter()
        .map(|r| r.traces as u32)
        .max()
        .unwrap_or(0);
    if opts.view == View::Heatmap {
        for (r, px) in aov.records.iter().zip(rgba8.chunks_exact_mut(4)) {
            let c = heat_colour(r.traces as f32 / heatmap_max.max(1) as f32);
            px[..3].copy_from_slice(&c.map(|v| (v * 255.0 + 0.5) as u8));
        }
    }
    let exposure_ev = if auto_exposure {
        resolve_auto_exposure(&mut rgba8)
    } else {
        opts.shading.exposure_ev
    };
    let secs = t1.elapsed().as_secs_f64();
    tracer.first_error()?;
    let rays = totals.primary + totals.shadow;
    let stats = RenderStats {
        width: w,
        height: h,
        backend: "cpu",
        view: opts.view,
        ms_per_frame: secs * 1e3,
        prepare_ms,
        rays,
        primary_rays: totals.primary,
        shadow_rays: totals.shadow,
        hits: totals.hits,
        traces: totals.traces,
        traces_per_ray: totals.traces as f64 / rays.max(1) as f64,
        rays_per_second: rays as f64 / secs.max(1e-9),
        stack_overflows: 0,
        truncated_rays: totals.truncated,
        max_stack_depth: totals.max_stack,
        heatmap_max_traces: heatmap_max,
        exposure_ev,
        meshes_built: tracer.meshes_built(),
        threads: rayon::current_num_threads(),
    };
    tracing::info!(
        rays = stats.rays,
        ms = stats.ms_per_frame,
        rays_per_second = stats.rays_per_second,
        "cpu render done"
    );
    Ok(RenderOutput { aov, rgba8, stats })
}

/// A sample's path from the camera's hit `hit` (direction `dir`): each vertex shaded with its
/// lights and environment rays, then `opts.shading.bounces` diffuse bounces
/// (`render_pixel.glsl`'s states 4 and 5). A bounce that escapes ends the path: the
/// environment's light reached every vertex through its sampled rays already. Vertex `b`
/// draws its numbers from sample `sample | b << 20`.
#[allow(clippy::too_many_arguments)]
fn shade_path(
    tracer: &Tracer<'_>,
    camera: &CameraParams,
    opts: &RenderOptions,
    hit: &crate::traverse::Hit,
    dir: [f32; 3],
    pixel: u32,
    sample: u32,
    scratch: &mut Scratch,
    rays: &mut ShadeRays,
) -> [f32; 3] {
    let (mut colour, mut from) = shade_vertex(
        tracer,
        camera,
        opts,
        hit,
        camera.world_eye,
        dir,
        pixel,
        sample,
        true,
        scratch,
        rays,
    );
    let mut thru = [1.0f32; 3];
    for b in 1..=opts.shading.bounces {
        let next = sample | (b << 20);
        let Some(d) = from.direction(pixel, next) else {
            break;
        };
        thru = std::array::from_fn(|i| thru[i] * from.diffuse[i]);
        let q = RayQuery {
            kind: motu_abi::lod::RAY_SHADOW,
            lod: motu_abi::lod::LodParams {
                forced_lod: if opts.shadow_lod_from_primary {
                    from.lod as i32
                } else {
                    opts.lod.forced_lod
                },
                ..opts.lod
            },
            pixels_per_unit_at_1: camera.pixels_per_unit_at_1,
            max_traces: opts.max_traces_per_ray,
            ..RayQuery::default()
        };
        let h = tracer.trace(from.start, d, &q, scratch);
        rays.truncated |= h.truncated;
        rays.rays += 1;
        rays.traces += h.traces;
        rays.max_stack = rays.max_stack.max(h.max_stack);
        if !h.is_hit() {
            break;
        }
        let (c, f) = shade_vertex(
            tracer, camera, opts, &h, from.start, d, pixel, next, false, scratch, rays,
        );
        colour = std::array::from_fn(|i| colour[i] + thru[i] * c[i]);
        from = f;
    }
    colour
}

/// What a primary ray that hits nothing shows in the shaded view: the scene's sky colour, else
/// the gradient sky.
fn background(opts: &RenderOptions, dir: [f32; 3]) -> [f32; 3] {
    if let Some(env) = opts.shading.environment {
        return env.radiance_towards(dir);
    }
    opts.shading.sky.unwrap_or_else(|| sky(dir))
}

/// A per-pixel uniform number in [0, 1) for stochastic LOD (a PCG hash of the pixel).
pub fn pixel_dither(x: u32, y: u32) -> f32 {
    (hash_u32(x.wrapping_mul(0x8da6_b343) ^ y.wrapping_mul(0xd816_3841)) >> 8) as f32
        / (1u32 << 24) as f32
}

/// PCG-style integer hash (also used for id colours).
pub fn hash_u32(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

/// A stable colour per (mesh, primitive), linear RGB.
pub fn id_colour(mesh: u32, primitive: u32) -> [f32; 3] {
    let h = hash_u32(hash_u32(mesh) ^ primitive);
    [
        0.15 + 0.85 * (h & 0xff) as f32 / 255.0,
        0.15 + 0.85 * ((h >> 8) & 0xff) as f32 / 255.0,
        0.15 + 0.85 * ((h >> 16) & 0xff) as f32 / 255.0,
    ]
}

/// A colour per LOD level (linear RGB), repeating after 8.
pub fn lod_colour(level: u32) -> [f32; 3] {
    const PALETTE: [[f32; 3]; 8] = [
        [0.1, 0.8, 0.1],
        [0.1, 0.4, 0.9],
        [0.9, 0.8, 0.1],
        [0.9, 0.4, 0.1],
        [0.8, 0.1, 0.1],
        [0.7, 0.1, 0.8],
        [0.1, 0.8, 0.8],
        [0.6, 0.6, 0.6],
    ];
    PALETTE[level as usize % PALETTE.len()]
}

/// Blue → cyan → green → yellow → red for `v` in [0, 1] (display values, not linear).
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

fn sky(dir: [f32; 3]) -> [f32; 3] {
    let t = 0.5 * (dir[1].clamp(-1.0, 1.0) + 1.0);
    [0.55 + 0.25 * t, 0.65 + 0.2 * t, 0.8 + 0.15 * t].map(|c| c * 0.8)
}

fn encode_srgb(c: [f32; 3]) -> [u8; 3] {
    c.map(|v| {
        let v = v.clamp(0.0, 1.0);
        let s = if v <= 0.003_130_8 {
            12.92 * v
        } else {
            1.055 * v.powf(1.0 / 2.4) - 0.055
        };
        (s * 255.0 + 0.5) as u8
    })
}

/// Writes an 8-bit RGBA PNG.
pub fn write_png(path: &Path, width: u32, height: u32, rgba8: &[u8]) -> Result<(), TraceError> {
    let shown = || path.display().to_string();
    let bytes = encode_png(width, height, rgba8).map_err(|e| match e {
        TraceError::Png { reason, .. } => TraceError::Png {
            path: shown(),
            reason,
        },
        TraceError::PngEncode { source, .. } => TraceError::PngEncode {
            path: shown(),
            source,
        },
        other => other,
    })?;
    std::fs::write(path, bytes).map_err(|source| TraceError::PngWrite {
        path: shown(),
        source,
    })
}

/// Encodes an RGBA8 image as PNG in memory (callers write it atomically); a 0-pixel image or
/// a buffer of the wrong size is an error.
pub fn encode_png(width: u32, height: u32, rgba8: &[u8]) -> Result<Vec<u8>, TraceError> {
    let err = |reason: String| TraceError::Png {
        path: "<memory>".into(),
        reason,
    };
    if width == 0 || height == 0 {
        return Err(err(format!("a {width}×{height} image has no pixels")));
    }
    if rgba8.len() != width as usize * height as usize * 4 {
        return Err(err(format!(
            "{} bytes for {width}×{height} RGBA",
            rgba8.len()
        )));
    }
    let mut out = Vec::new();
    let mut enc = png::Encoder::new(&mut out, width, height);
    enc.set_color(png::ColorType::Rgba);
    enc.set_depth(png::BitDepth::Eight);
    let encode_err = |source| TraceError::PngEncode {
        path: "<memory>".into(),
        source,
    };
    let mut w = enc.write_header().map_err(encode_err)?;
    w.write_image_data(rgba8).map_err(encode_err)?;
    w.finish().map_err(encode_err)?;
    Ok(out)
}

#[cfg(test)]
mod tests;
