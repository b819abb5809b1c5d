//! The GPU renderer: one primary ray per pixel centre through the traversal-shader emulation
//! (backend `pipeline` or `query`), an optional shadow ray, the AOV hit record and the views
//! of the CPU renderer (same hash, palettes, sky and sRGB encoding as motu-trace).
//!
//! Everything stays on the GPU until one final copy of the AOV, the colours and the counters;
//! frame times come from timestamps around each dispatch (median over `frames`, the first of
//! several being a warm-up left out).

use bytemuck::{Pod, Zeroable};
use motu_abi::aov::{Aov, AovRecord};
use motu_abi::camera::CameraParams;
use motu_abi::lod::LodParams;
use motu_abi::shade::{Shading, MAX_LIGHTS};
use motu_abi::LightRecord;
use motu_alloc::{AllocKind, MemoryClass};
use motu_vk::{
    BufferUsage, CommandRecorder, ComputePipeline, ComputePipelineDesc, Context, GpuHeap,
    HeapBuffer, RtPipeline, RtShaders, TimestampQueries, PUSH_CONSTANT_BYTES,
};

use crate::error::{GpuError, Result};
use crate::scene::{GpuScene, Slot, SLOT_COUNT};
use crate::shaders;

/// Which traversal backend traces.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    /// Ray-tracing pipeline: raygen owns the stack (every RT device; the only one on the H200).
    Pipeline,
    /// Compute shader with ray queries (the thesis's form).
    Query,
}

impl Backend {
    /// `query` where the device has ray queries, else `pipeline`.
    pub fn best(ctx: &Context) -> Option<Backend> {
        if ctx.caps().ray_query {
            Some(Backend::Query)
        } else if ctx.caps().ray_pipeline {
            Some(Backend::Pipeline)
        } else {
            None
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Backend::Pipeline => "pipeline",
            Backend::Query => "query",
        }
    }
}

impl std::str::FromStr for Backend {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "pipeline" => Ok(Backend::Pipeline),
            "query" => Ok(Backend::Query),
            _ => Err(format!(
                "unknown GPU backend {s:?} (expected pipeline or query)"
            )),
        }
    }
}

/// What the image shows (values match `VIEW_*` in `common.glsl`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum View {
    #[default]
    Shaded,
    Ids,
    Lod,
    /// Traces per pixel, blue (0) to red (the frame's maximum, `heatmap_max` in stats).
    Heatmap,
    /// The primary hit's textured base colour (sRGB-encoded; misses show the sky): the
    /// denoiser's material guide.
    Albedo,
}

impl View {
    /// The view's name (`--view`, `view` in `--stats`).
    pub fn name(self) -> &'static str {
        match self {
            View::Shaded => "shaded",
            View::Ids => "ids",
            View::Lod => "lod",
            View::Heatmap => "heatmap",
            View::Albedo => "albedo",
        }
    }

    fn code(self) -> u32 {
        match self {
            View::Shaded => 0,
            View::Ids => 1,
            View::Lod => 2,
            View::Heatmap => 3,
            View::Albedo => 4,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    pub backend: Backend,
    pub view: View,
    pub lod: LodParams,
    /// Traversal stack entries (a specialisation constant), 1..=[`MAX_STACK_SIZE`].
    pub stack_size: u32,
    /// TLAS walks a ray may make before it is cut short (a specialisation constant).
    pub max_traces_per_ray: u32,
    /// Frames traced (for timing); the outputs are the last frame's.
    pub frames: u32,
    /// World direction towards the sun (normalised here).
    pub sun_dir_world: [f32; 3],
    pub sun_intensity: f32,
    pub ambient: f32,
    pub shadows: bool,
    /// Shadow rays use the primary hit's LOD (prevents LOD self-shadowing).
    pub shadow_lod_from_primary: bool,
    /// Scene lights, sky, ambient occlusion, samples per pixel and exposure (shaded view).
    pub shading: Shading,
}

impl Default for RenderOptions {
    fn default() -> Self {
        Self {
            backend: Backend::Pipeline,
            view: View::Shaded,
            lod: LodParams::default(),
            stack_size: 16,
            max_traces_per_ray: motu_abi::DEFAULT_MAX_TRACES_PER_RAY,
            frames: 1,
            sun_dir_world: [0.4, 0.8, 0.45],
            sun_intensity: 0.8,
            ambient: 0.25,
            shadows: true,
            shadow_lod_from_primary: true,
            shading: Shading::default(),
        }
    }
}

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
        let shadow = u64::from(m.counters[2]);
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

/// `FrameParams` of `common.glsl` (std430, 560 bytes).
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
#[repr(C)]
pub(crate) struct FrameParams {
    camera: CameraParams,
    lod: LodParams,
    sun_dir_intensity: [f32; 4],
    view: u32,
    shadows: u32,
    shadow_lod_from_primary: u32,
    ambient: f32,
    root_tlas: u32,
    light_count: u32,
    /// Address of the scene's shading tables (`shade.glsl`'s `ShadingRef`), 0 for none.
    pub(crate) shading: u64,
    sky: [f32; 4],
    ao_samples: u32,
    spp: u32,
    ao_distance: f32,
    exposure_scale: f32,
    lights: [LightRecord; MAX_LIGHTS],
    /// 1: an environment map's tables ([`motu_abi::env::Environment::gpu_words`]) follow the
    /// parameters, [`ENV_OFFSET_BYTES`] into their buffer (`shade.glsl` `env_base`).
    environment: u32,
    /// 1: shaded pixels are written as linear RGB9E5 and tone-mapped on the host
    /// ([`frame_outputs`], `motu_abi::shade::resolve_auto_exposure`).
    auto_exposure: u32,
    /// Diffuse bounces after each primary hit (`shade.glsl`).
    bounces: u32,
    /// The frame's first sample in the pixel's sequence (`Shading::first_sample`).
    first_sample: u32,
}

/// Where an environment map's tables start in the frame-parameter buffer (`shade.glsl`
/// `ENV_OFFSET_BYTES`): they are written with the parameters, so every renderer's frame
/// carries them without a table of its own.
pub(crate) const ENV_OFFSET_BYTES: u64 = 1024;

/// Bytes of the frame-parameter buffer for a frame shaded with `shading`.
pub(crate) fn params_bytes(shading: &Shading) -> u64 {
    let base = std::mem::size_of::<FrameParams>() as u64;
    match shading.environment {
        Some(e) => ENV_OFFSET_BYTES + 4 * e.gpu_words().len() as u64,
        None => base,
    }
}

/// Writes the frame's parameters (and its environment map's tables) into `buf`.
pub(crate) fn write_params(
    buf: &HeapBuffer,
    params: &FrameParams,
    shading: &Shading,
) -> Result<()> {
    buf.write(0, std::slice::from_ref(params))?;
    if let Some(e) = shading.environment {
        let words = e.gpu_words();
        if ENV_OFFSET_BYTES + 4 * words.len() as u64 > buf.size_bytes() {
            return Err(GpuError::InvalidRequest(
                "the frame's parameter buffer has no room for the environment map".into(),
            ));
        }
        buf.write(ENV_OFFSET_BYTES, &words)?;
    }
    Ok(())
}

impl FrameParams {
    /// What instance-level LOD's levels depend on: the camera and the LOD parameters.
    pub(crate) fn camera_and_lod(&self) -> (&CameraParams, &LodParams) {
        (&self.camera, &self.lod)
    }
}

/// Stats words of every renderer's buffers (full builds, streaming, the viewer), indexed by
/// the `STAT_*` of `common.glsl`.
pub(crate) const STAT_WORDS: usize = 6;
const RENDER_STAT_WORDS: usize = STAT_WORDS;
/// Rays cut short by a stack overflow or the trace cap.
pub(crate) const STAT_TRUNCATED_RAYS: usize = 4;
/// Texture reads that found a streamed texture not resident.
pub(crate) const STAT_MISSING_TEXTURES: usize = 5;

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

/// The largest traversal stack: entries are 64 bytes of private memory per ray, and beyond a
/// few hundred shader compilers spill, stall or fail (2^16 hangs lavapipe's compiler).
pub const MAX_STACK_SIZE: u32 = 256;

/// Counts of one render beyond [`RenderStats`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    /// Rays whose traversal was cut short: a stack overflow dropped an entry, or the ray
    /// reached `max_traces_per_ray`. Their hit may be wrong.
    pub truncated_rays: u64,
}

pub(crate) struct Frame {
    pub(crate) params: HeapBuffer,
    aov: HeapBuffer,
    rgba: HeapBuffer,
    stats: HeapBuffer,
    readback: HeapBuffer,
}

impl Frame {
    pub(crate) fn release(self, heap: &mut GpuHeap) {
        for b in [self.params, self.aov, self.rgba, self.stats, self.readback] {
            heap.free(b);
        }
    }
}

/// Sizes of the buffers [`alloc_frame`] allocates for `pixels`: parameters, AOV (16 B a
/// pixel), colour (4), counters, readback (20 a pixel and the counters). One list for the
/// allocation and for [`frame_bytes`].
fn frame_buffer_sizes(pixels: u64, params_size: u64) -> [u64; 5] {
    let stats = (RENDER_STAT_WORDS * 4) as u64;
    [
        params_size,
        pixels * 16,
        pixels * 4,
        stats,
        pixels * 20 + stats,
    ]
}

/// What [`alloc_frame`] allocates for `pixels` (each buffer rounded to 16 bytes).
pub(crate) fn frame_bytes(pixels: u64) -> u64 {
    frame_buffer_sizes(pixels, std::mem::size_of::<FrameParams>() as u64)
        .iter()
        .map(|v| v.max(&16).div_ceil(16) * 16)
        .sum()
}

pub(crate) fn alloc_frame(
    heap: &mut GpuHeap,
    pixels: u64,
    params: &FrameParams,
    shading: &Shading,
) -> Result<Frame> {
    let out = BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS | BufferUsage::TRANSFER_SRC;
    let [params_size, aov_size, rgba_size, stats_size, readback_size] =
        frame_buffer_sizes(pixels, params_bytes(shading));
    let p = heap.alloc_buffer(
        "frame-params",
        params_size,
        BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
        AllocKind::Other,
        MemoryClass::HostVisible,
        16,
    )?;
    if let Err(e) = write_params(&p, params, shading) {
        heap.free(p);
        return Err(e);
    }
    let mut bufs = vec![p];
    let sizes = [aov_size, rgba_size, stats_size];
    for (i, size) in sizes.into_iter().enumerate() {
        let usage = if i == 2 {
            out | BufferUsage::TRANSFER_DST
        } else {
            out
        };
        match heap.alloc_buffer(
            ["aov", "rgba", "stats"][i],
            size,
            usage,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
            16,
        ) {
            Ok(b) => bufs.push(b),
            Err(e) => {
                bufs.into_iter().for_each(|b| heap.free(b));
                return Err(e.into());
            }
        }
    }
    let readback = match heap.alloc_buffer(
        "readback",
        readback_size,
        BufferUsage::TRANSFER_DST,
        AllocKind::Staging,
        MemoryClass::HostVisible,
        16,
    ) {
        Ok(b) => b,
        Err(e) => {
            bufs.into_iter().for_each(|b| heap.free(b));
            return Err(e.into());
        }
    };
    let mut it = bufs.into_iter();
    let (Some(params), Some(aov), Some(rgba), Some(stats)) =
        (it.next(), it.next(), it.next(), it.next())
    else {
        return Err(GpuError::InvalidRequest("frame buffers".into()));
    };
    Ok(Frame {
        params,
        aov,
        rgba,
        stats,
        readback,
    })
}

pub(crate) enum Tracer {
    Pipeline(Box<RtPipeline>),
    Query(ComputePipeline),
}

impl Tracer {
    /// The pipeline of `opts.backend` (its SBT, if any, from `heap`).
    /// `pi_capacity`: the payload's candidate slots ([`crate::scene::pi_capacity`]).
    /// `streamed`: the trace shaders' streamed variant (`trace_stream.rgen` /
    /// `trace_stream.comp`, MOTU_STREAMED: a sample's secondary rays traced in windows, so its
    /// shadow and AO rays wait on their structures' builds together rather than one after
    /// another; H200, a quarter of the island's full build at 160×90: 5.05 → 4.38 passes a
    /// frame); full builds keep the sequential loop, which costs their rays less.
    pub(crate) fn new(
        ctx: &Context,
        heap: &mut GpuHeap,
        opts: &RenderOptions,
        pi_capacity: u32,
        streamed: bool,
    ) -> Result<Tracer> {
        if !(1..=MAX_STACK_SIZE).contains(&opts.stack_size) || opts.max_traces_per_ray == 0 {
            return Err(GpuError::InvalidRequest(format!(
                "stack size {} is outside 1..={MAX_STACK_SIZE}, or the trace cap {} is 0",
                opts.stack_size, opts.max_traces_per_ray
            )));
        }
        let spec = [
            (0, opts.stack_size),
            (1, opts.max_traces_per_ray),
            (2, pi_capacity.clamp(1, crate::scene::MAX_PI_CAPACITY)),
        ];
        Ok(match opts.backend {
            Backend::Pipeline => {
                // The streamed variants of the raygen and the PI any-hit
                // (`pipeline/trace_stream.rgen`, `pipeline/pi_stream.rahit`).
                let shaders = RtShaders {
                    raygen: if streamed {
                        shaders::PIPELINE_TRACE_STREAM_RGEN
                    } else {
                        shaders::PIPELINE_TRACE_RGEN
                    },
                    miss: shaders::PIPELINE_MISS_RMISS,
                    triangle_closest_hit: shaders::PIPELINE_TRIANGLE_RCHIT,
                    triangle_any_hit: shaders::PIPELINE_TRIANGLE_RAHIT,
                    pi_intersection: shaders::PIPELINE_PI_RINT,
                    pi_any_hit: if streamed {
                        shaders::PIPELINE_PI_STREAM_RAHIT
                    } else {
                        shaders::PIPELINE_PI_RAHIT
                    },
                };
                Tracer::Pipeline(Box::new(RtPipeline::new(ctx, heap, &spec, &shaders)?))
            }
            Backend::Query => {
                if !ctx.caps().ray_query {
                    return Err(GpuError::MissingFeature {
                        what: "ray queries (VK_KHR_ray_query) for backend `query`; use `pipeline`"
                            .into(),
                        details: ctx.device_name().to_string(),
                    });
                }
                Tracer::Query(ComputePipeline::new(
                    ctx,
                    &ComputePipelineDesc {
                        label: "traversal query",
                        spirv: if streamed {
                            shaders::QUERY_TRACE_STREAM_COMP
                        } else {
                            shaders::QUERY_TRACE_COMP
                        },
                        storage_buffer_count: 0,
                        push_constant_size_bytes: PUSH_CONSTANT_BYTES,
                        specialization: &spec,
                    },
                )?)
            }
        })
    }

    pub(crate) fn release(self, heap: &mut GpuHeap) {
        if let Tracer::Pipeline(p) = self {
            p.release(heap);
        }
    }

    /// Records one trace of `dims` invocations (pipeline: a launch of `dims`; query: 8 × 8
    /// groups covering `dims`, or `groups` verbatim when given).
    pub(crate) fn record<'a>(
        &'a self,
        rec: &mut CommandRecorder<'a>,
        push_bytes: &[u8],
        dims: [u32; 2],
        groups: Option<[u32; 2]>,
    ) -> Result<()> {
        match self {
            // The pipeline, its SBT, and every buffer behind the pushed addresses live until
            // the fenced submission returns.
            Tracer::Pipeline(p) => Ok(rec.trace_rays(p, push_bytes, dims)?),
            Tracer::Query(q) => {
                let g = groups.unwrap_or([dims[0].div_ceil(8), dims[1].div_ceil(8)]);
                Ok(rec.dispatch(q, None, push_bytes, [g[0], g[1], 1])?)
            }
        }
    }
}

/// The frame parameters of `common.glsl` for `camera` and `opts`.
pub(crate) fn frame_params(
    camera: &CameraParams,
    opts: &RenderOptions,
    root_tlas: u32,
) -> FrameParams {
    let sun = {
        let s = opts.sun_dir_world;
        let l = (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]).sqrt().max(1e-20);
        [s[0] / l, s[1] / l, s[2] / l, opts.sun_intensity]
    };
    let sh = &opts.shading;
    let (lights, light_count) = sh.frame_lights(opts.sun_dir_world, opts.sun_intensity);
    let sky = sh.sky_radiance(opts.ambient);
    FrameParams {
        camera: *camera,
        lod: opts.lod,
        sun_dir_intensity: sun,
        view: opts.view.code(),
        shadows: u32::from(opts.shadows),
        shadow_lod_from_primary: u32::from(opts.shadow_lod_from_primary),
        ambient: opts.ambient,
        root_tlas,
        light_count,
        shading: 0,
        sky: [
            sky[0],
            sky[1],
            sky[2],
            if sh.sky.is_some() { 1.0 } else { 0.0 },
        ],
        ao_samples: sh.ao_samples,
        spp: sh.spp.max(1),
        // GLSL has no infinity literal here: T_INFINITY (3e38) stands for it.
        ao_distance: sh.ao_distance.min(3.0e38),
        exposure_scale: sh.exposure_scale(),
        lights,
        environment: u32::from(sh.environment.is_some()),
        auto_exposure: u32::from(sh.auto_exposure && opts.view == View::Shaded),
        bounces: sh.bounces,
        first_sample: sh.first_sample,
    }
}

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
    let mut params = frame_params(camera, opts, scene.root_tlas);
    params.shading = scene.shading_address;
    let pixels = u64::from(w) * u64::from(h);
    let frames = opts.frames.max(1);
    let mut heap = scene.heap();
    let tracer = Tracer::new(ctx, &mut heap, opts, scene.pi_capacity, false)?;
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
    let (records, rgba_words, counters, frame_ns) = result?;

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

pub(crate) type FrameResult = (Vec<AovRecord>, Vec<u32>, Vec<u32>, Vec<f64>);

pub(crate) fn run_frames(
    ctx: &Context,
    scene: &GpuScene,
    tracer: &Tracer,
    frame: &Frame,
    w: u32,
    h: u32,
    frames: u32,
) -> Result<FrameResult> {
    let mut addresses = scene.addresses;
    addresses[Slot::Frame as usize] = frame.params.device_address()?.0;
    addresses[Slot::Aov as usize] = frame.aov.device_address()?.0;
    addresses[Slot::Rgba as usize] = frame.rgba.device_address()?.0;
    addresses[Slot::Stats as usize] = frame.stats.device_address()?.0;
    let push: [u64; SLOT_COUNT] = addresses;
    let push_bytes: &[u8] = bytemuck::cast_slice(&push);
    let pixels = u64::from(w) * u64::from(h);
    // Two per frame, then one at the end of the instance-LOD pass (when a frame runs it).
    let timestamps = TimestampQueries::new(ctx, 2 * frames + 1)?;
    let mut rec: CommandRecorder<'_> = ctx.record(match tracer {
        Tracer::Pipeline(_) => "trace (pipeline)",
        Tracer::Query(_) => "trace (query)",
    })?;
    rec.reset_queries(&timestamps);
    // Instance-level LOD: every frame of this call has the same camera, so the levels are
    // picked on the host and applied (the slot TLASes rebuilt) in the first frame at most,
    // and not at all when the slot TLASes already hold exactly those levels (lod_instances.rs).
    let lod_levels = match &scene.instance_lod {
        Some(lod) => {
            let params: Vec<FrameParams> = frame.params.read_vec(0, 1)?;
            let (camera, lod_params) = params[0].camera_and_lod();
            Some(lod.levels(camera, lod_params))
        }
        None => None,
    };
    let lod_pass = match (&scene.instance_lod, &lod_levels) {
        (Some(lod), Some(levels)) => lod.needs_pass(levels, frames),
        _ => None,
    };
    for f in 0..frames {
        rec.fill_buffer(&frame.stats, 0, (RENDER_STAT_WORDS * 4) as u64, 0)?;
        rec.barrier();
        rec.write_timestamp(&timestamps, 2 * f)?;
        // In the first frame (`frames` ≥ 1), counted in its time.
        if let (0, Some(kind), Some(lod), Some(levels)) =
            (f, lod_pass, &scene.instance_lod, &lod_levels)
        {
            lod.record(&mut rec, levels, kind)?;
            rec.write_timestamp(&timestamps, 2 * frames)?;
        }
        tracer.record(&mut rec, push_bytes, [w, h], None)?;
        rec.write_timestamp(&timestamps, 2 * f + 1)?;
        rec.barrier();
    }
    if lod_pass.is_none() {
        // Every query is read back: the LOD one too, unused without a pass.
        rec.write_timestamp(&timestamps, 2 * frames)?;
    }
    let rgba_off = pixels * 16;
    let stats_off = pixels * 20;
    rec.copy_buffer(&frame.aov, 0, &frame.readback, 0, pixels * 16)?;
    rec.copy_buffer(&frame.rgba, 0, &frame.readback, rgba_off, pixels * 4)?;
    rec.copy_buffer(
        &frame.stats,
        0,
        &frame.readback,
        stats_off,
        (RENDER_STAT_WORDS * 4) as u64,
    )?;
    rec.submit_and_wait()?;
    let ticks = timestamps.read_ticks()?;
    if let (Some(lod), Some(levels), Some(kind)) = (&scene.instance_lod, lod_levels, lod_pass) {
        let pass_ms = timestamps.elapsed_ns(&ticks, 0, 2 * frames)? / 1e6;
        lod.built(levels, kind, pass_ms);
    }
    let records: Vec<AovRecord> = frame.readback.read_vec(0, pixels as usize)?;
    let rgba: Vec<u32> = frame.readback.read_vec(rgba_off, pixels as usize)?;
    let counters: Vec<u32> = frame.readback.read_vec(stats_off, RENDER_STAT_WORDS)?;
    check_texture_residency(&counters)?;
    let frame_ns = (0..frames)
        .map(|f| timestamps.elapsed_ns(&ticks, 2 * f, 2 * f + 1))
        .collect::<motu_vk::Result<Vec<f64>>>()?;
    Ok((records, rgba, counters, frame_ns))
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
        motu_abi::shade::resolve_auto_exposure(&mut rgba8)
    } else {
        opts.shading.exposure_ev
    };
    (aov, rgba8, heatmap_max, exposure_ev)
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
mod stat_word_tests {
    use super::*;

    /// The stats-word indices are written twice (Rust here, `#define STAT_*` in common.glsl):
    /// this keeps them equal, and every GLSL index inside the buffer.
    #[test]
    fn stat_words_match_common_glsl() {
        let glsl = include_str!("../../../shaders/common.glsl");
        let defines: Vec<(&str, usize)> = glsl
            .lines()
            .filter_map(|l| {
                let mut it = l.strip_prefix("#define STAT_")?.split_whitespace();
                Some((it.next()?, it.next()?.parse().ok()?))
            })
            .collect();
        let index = |name: &str| {
            defines
                .iter()
                .find(|(n, _)| *n == name)
                .unwrap_or_else(|| panic!("common.glsl has no STAT_{name}"))
                .1
        };
        assert_eq!(index("TRUNCATED_RAYS"), STAT_TRUNCATED_RAYS);
        assert_eq!(index("MISSING_TEXTURES"), STAT_MISSING_TEXTURES);
        assert_eq!(defines.len(), STAT_WORDS, "{defines:?}");
        assert!(defines.iter().all(|&(_, i)| i < STAT_WORDS), "{defines:?}");
    }

    #[test]
    fn a_missing_texture_read_fails_the_frame() {
        let mut counters = vec![0u32; STAT_WORDS];
        assert!(check_texture_residency(&counters).is_ok());
        counters[STAT_MISSING_TEXTURES] = 3;
        let e = check_texture_residency(&counters).unwrap_err().to_string();
        assert!(e.contains("3 texture reads"), "{e}");
    }
}
