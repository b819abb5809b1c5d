//! The `--stats` schema: the JSON that `motu render --stats` and `motu view --stats` write
//! (and `motu devices --json`, and the GPU crate's parts of `motu report --json`), as typed
//! structs. These types own the keys (shared/CLI.md's contract: keys are added, never
//! renamed or removed); the libraries' statistics (`motu_gpu::RenderStats`,
//! `motu_gpu::FrameStreamStats`, `motu_alloc::AllocReport`, `motu_ascache::CacheStats`, …)
//! are not `Serialize` and are converted here, so renaming a library field cannot change a key.
//!
//! A struct that copies a library struct key for key is declared with `mirror!`
//! (`stats/mirror.rs`): its conversion names every field of the source, so a field added to
//! the library struct fails to compile until it has its key here. `stats/keys.txt` lists every
//! key path the schema writes; a unit test compares the two (`MOTU_UPDATE_STATS_KEYS=1`
//! rewrites the list after a deliberate addition).

mod devices;
mod mirror;
mod pipelines;
mod resources;
mod stream;
#[cfg(test)]
mod tests;

pub use devices::{Caps, DeviceList, DeviceReport, HeapReport, Limits};
pub(crate) use pipelines::captured as captured_pipelines;
pub use pipelines::{ExecutableStats, PipelineStats, RepresentationStats, StatisticStats};
pub use resources::{AllocReport, ClassStats, KindStats, ResourceReport};
pub use stream::{
    CacheStats, DiskStats, FrameStreamStats, FullBuildOverhead, HostStats, PassStats,
    PersistentEstimate, PoolStats, StreamFloor, StreamTotals, WarningCounts,
};

use mirror::mirror;
use serde::Serialize;

/// The keys CLI.md names for `motu render --stats` (checked against CLI.md by the
/// integration tests): each is a field of [`FrameStats`].
pub const CONTRACT_KEYS: [&str; 13] = [
    "width",
    "height",
    "backend",
    "ms_per_frame",
    "rays",
    "rays_per_second",
    "traces_per_ray",
    "stack_overflows",
    "vram_budget_bytes",
    "vram_peak_bytes",
    "allocation_count",
    "as_bytes",
    "passes",
];

/// `motu render --stats`: the frame written (CLI.md's keys), what the render path adds (a
/// full build's resources, a recorded path's frame times, the streaming run), and the
/// session's keys (denoise, LOD mode, BLAS build, subset, package).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RenderStats {
    #[serde(flatten)]
    pub frame: FrameStats,
    /// Rays of the frame written that were cut short (absent for a recorded camera path on
    /// the GPU, whose frames do not count them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truncated_rays: Option<u64>,
    /// A full GPU build's resources and instance-LOD passes.
    #[serde(flatten)]
    pub full_build: Option<FullBuildStats>,
    /// A recorded camera path on the GPU: every frame's time, the first (a warm-up) included.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub path_ms_per_frame: Option<Vec<f64>>,
    /// Streaming: the written frame's fallback pixels (not exact; 0 unless
    /// `--stream-fallback`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fallback_pixels: Option<u64>,
    /// The streaming run (`null` for other renders).
    pub stream: Option<StreamRunStats>,
    /// `--stream`'s test of whether the budget holds the whole scene (`null` for other renders
    /// and with `--stream-always`).
    pub stream_fit: Option<StreamFitStats>,
    /// `--denoise` on the shaded view (`null` otherwise).
    pub denoise: Option<DenoiseStats>,
    #[serde(flatten)]
    pub lod: LodStats,
    /// `--blas-build` as run (`fast-trace` or `small`).
    pub blas_build: &'static str,
    /// `--subset`'s element names.
    pub subset: Vec<String>,
    /// The package's path.
    pub package: String,
    /// `--pipeline-stats`: every pipeline the render made with the driver's statistics of its
    /// executables (absent without the flag).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pipeline_executables: Option<Vec<PipelineStats>>,
}

impl RenderStats {
    /// Median milliseconds per frame.
    pub fn ms_per_frame(&self) -> f64 {
        self.frame.ms_per_frame
    }

    pub fn rays_per_second(&self) -> f64 {
        self.frame.rays_per_second
    }

    pub fn traces_per_ray(&self) -> f64 {
        self.frame.traces_per_ray
    }
}

/// One frame's counts: CLI.md's keys first, then what every tracer reports, then the GPU's
/// or the CPU's own detail ([`TracerStats`]).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FrameStats {
    pub width: u32,
    pub height: u32,
    /// `pipeline`, `query` or `cpu`.
    pub backend: &'static str,
    /// Median time of one frame's trace (GPU timestamps; wall clock on the CPU).
    pub ms_per_frame: f64,
    /// Primary plus shadow rays of one frame.
    pub rays: u64,
    pub rays_per_second: f64,
    pub traces_per_ray: f64,
    pub stack_overflows: u64,
    /// The VRAM budget (0: none; the CPU reports `--vram-budget` as given).
    pub vram_budget_bytes: u64,
    /// Highest bytes of memory blocks counted against the budget (0 on the CPU).
    pub vram_peak_bytes: u64,
    /// Most `VkDeviceMemory` allocations at once (0 on the CPU).
    pub allocation_count: u32,
    /// Acceleration-structure bytes resident (0 on the CPU).
    pub as_bytes: u64,
    /// Build–trace passes of the frame (1 but for streaming).
    pub passes: u32,
    /// `shaded`, `ids`, `lod` or `heatmap`.
    pub view: &'static str,
    /// Frames rendered (timed, or shown by the viewer).
    pub frames: u64,
    pub primary_rays: u64,
    pub shadow_rays: u64,
    /// TLAS walks of one frame.
    pub traces: u64,
    /// The exposure the shaded image was tone-mapped with, in stops.
    pub exposure_ev: f32,
    #[serde(flatten)]
    pub tracer: TracerStats,
}

/// What only one kind of tracer reports.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum TracerStats {
    /// The GPU backends (`motu_gpu::RenderStats`).
    Gpu {
        stack_size: u32,
        pi_list_overflows: u64,
        /// The heatmap's red end: the most traces spent on one pixel.
        heatmap_max: u32,
    },
    /// The CPU reference (`motu_trace::RenderStats`).
    Cpu {
        prepare_ms: f64,
        hits: u64,
        max_stack_depth: u32,
        /// The heatmap's red end (as the GPU's `heatmap_max`).
        heatmap_max_traces: u32,
        meshes_built: usize,
        threads: usize,
    },
}

impl FrameStats {
    /// A GPU frame's stats.
    pub fn gpu(s: &motu_gpu::RenderStats) -> Self {
        let motu_gpu::RenderStats {
            width,
            height,
            backend,
            view,
            frames,
            ms_per_frame,
            rays,
            primary_rays,
            shadow_rays,
            rays_per_second,
            traces,
            traces_per_ray,
            stack_size,
            stack_overflows,
            pi_list_overflows,
            heatmap_max,
            exposure_ev,
            as_bytes,
            vram_budget_bytes,
            vram_peak_bytes,
            allocation_count,
            passes,
        } = *s;
        Self {
            width,
            height,
            backend,
            ms_per_frame,
            rays,
            rays_per_second,
            traces_per_ray,
            stack_overflows,
            vram_budget_bytes,
            vram_peak_bytes,
            allocation_count,
            as_bytes,
            passes,
            view: view.name(),
            frames: u64::from(frames),
            primary_rays,
            shadow_rays,
            traces,
            exposure_ev,
            tracer: TracerStats::Gpu {
                stack_size,
                pi_list_overflows,
                heatmap_max,
            },
        }
    }

    /// A CPU frame's stats, with the frame count and the budget the CPU does not know, and its
    /// truncated rays (a key of [`RenderStats`]).
    pub fn cpu(s: &motu_trace::RenderStats, frames: u64, vram_budget_bytes: u64) -> (Self, u64) {
        let motu_trace::RenderStats {
            width,
            height,
            backend,
            view,
            ms_per_frame,
            prepare_ms,
            rays,
            primary_rays,
            shadow_rays,
            hits,
            traces,
            traces_per_ray,
            rays_per_second,
            stack_overflows,
            truncated_rays,
            max_stack_depth,
            heatmap_max_traces,
            exposure_ev,
            meshes_built,
            threads,
        } = *s;
        let frame = Self {
            width,
            height,
            backend,
            ms_per_frame,
            rays,
            rays_per_second,
            traces_per_ray,
            stack_overflows,
            vram_budget_bytes,
            vram_peak_bytes: 0,
            allocation_count: 0,
            as_bytes: 0,
            passes: 1,
            view: view.name(),
            frames,
            primary_rays,
            shadow_rays,
            traces,
            exposure_ev,
            tracer: TracerStats::Cpu {
                prepare_ms,
                hits,
                max_stack_depth,
                heatmap_max_traces,
                meshes_built,
                threads,
            },
        };
        (frame, truncated_rays)
    }
}

/// A full GPU build's keys: its resources and instance-level LOD's per-frame pass.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FullBuildStats {
    pub resources: ResourceReport,
    /// Frames that ran the pass (levels picked, slot TLASes rebuilt), frames that did not
    /// (their camera was the one the levels were built for).
    pub lod_passes: u64,
    pub lod_passes_skipped: u64,
    /// Of the passes that ran: slot TLASes updated in place (a moving camera), and a held
    /// camera's refittable tree rebuilt at full quality.
    pub lod_refits: u64,
    pub lod_settles: u64,
    /// Mean GPU time of the passes that ran (inside the frames' times).
    pub lod_pass_ms: f64,
}

impl FullBuildStats {
    /// `scene`'s resources and LOD passes.
    pub fn of(scene: &motu_gpu::GpuScene) -> Self {
        let [lod_passes, lod_passes_skipped] = scene.lod_instance_passes();
        let [lod_refits, lod_settles] = scene.lod_instance_refits();
        Self {
            resources: scene.report().into(),
            lod_passes,
            lod_passes_skipped,
            lod_refits,
            lod_settles,
            lod_pass_ms: scene.lod_instance_pass_ms(),
        }
    }
}

/// The LOD mode that ran and its instance/selector counts.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct LodStats {
    /// `instance`, `traversal` or `none`.
    pub lod_mode: &'static str,
    pub lod_mode_reason: &'static str,
    /// LOD instances rewritten (instance mode), else 0.
    pub lod_instances: usize,
    /// LOD selectors the traversal shader evaluates.
    pub lod_traversal_selectors: u32,
}

/// `stream_fit` in `--stats`: whether a `--stream` render's budget holds the whole scene,
/// by an upper bound of the full build's peak (`motu_gpu::full_build_fits`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StreamFitStats {
    /// The budget the full build would get.
    pub budget_bytes: u64,
    /// The bound (uncompacted structures, every mesh and texel, transients, overhead).
    pub full_build_upper_bytes: u64,
    /// The budget held it and the full build rendered (`stream` is then `null`).
    pub full_build: bool,
    /// The test's time (the device's size queries for every structure).
    pub check_ms: f64,
}

/// `stream` in `--stats`: every frame, the run's totals, the floor the budget was checked
/// against, the pass cap, the start's phases and the structure cache.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StreamRunStats {
    pub frames: Vec<FrameStreamStats>,
    pub totals: StreamTotals,
    pub floor: StreamFloor,
    pub max_passes: u32,
    pub startup: StreamStartup,
    /// The structure cache's counters (`null` without one).
    pub cache: Option<CacheStats>,
    /// Mean passes of the frames after the first (`null` with one frame).
    pub mean_passes_after_first: Option<f64>,
}

/// Where a streamed render's time went up to its first frame (`stream.startup` in `--stats`):
/// the time to first pixel and its phases, in milliseconds. Each phase is also a `tracing`
/// span (`MOTU_LOG=motu_render=info` prints them).
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct StreamStartup {
    /// From the command's start to the render: opening and checking the package, the subset,
    /// the camera and the LOD mode (0 when the caller gave no start).
    pub before_render_ms: f64,
    /// Opening the Vulkan device.
    pub device_ms: f64,
    /// Splitting large TLASes for streaming ([`crate::stream_split`]).
    pub split_ms: f64,
    /// The cap the TLASes were split at (`--stream-split-instances`; 0: no split).
    pub split_instances: u32,
    /// Where that cap came from: "flag" (`--stream-split-instances`), "package" (recorded by
    /// `motu import --stream-split-instances`, the cap its stored split, proxy boxes and
    /// clusters were made for) or "default" (a package that recorded none: 1,000,000).
    pub split_instances_source: &'static str,
    /// TLASes split at that cap, and the pieces they were split into (0 and 0: none over it).
    pub split_tlases: u64,
    pub split_pieces: u64,
    /// The proxy clusters of every TLAS (`motu_gpu::StreamPlan`), which the floor and the
    /// renderer share.
    pub clusters_ms: f64,
    /// Whether the clusters were read from the structure cache (kept by an earlier process).
    pub clusters_cached: bool,
    /// Where the clusters came from: "package" (the package's `proxy_clusters` section,
    /// stored at import), "cache" (the structure cache) or "computed" (binned SAH here, for
    /// every TLAS or the ones whose stored entry was stale).
    pub clusters_source: &'static str,
    /// TLASes whose entry in the package's table did not match (changed since import; made
    /// again, with a warning).
    pub clusters_stale_tlases: u64,
    /// The streaming floor (`motu_gpu::streaming_floor`): refusing budgets below it.
    pub floor_ms: f64,
    /// The streaming renderer's start: derived tables, proxy clusters and boxes, the resident
    /// skeleton's upload and builds.
    pub init_ms: f64,
    /// Of `init_ms`: the derived tables (parents, proxy clusters, GPU records), choosing
    /// persistent TLASes, the boxes inside streamable BLASes (read from every mesh), and the
    /// resident skeleton (tables uploaded, PI BLASes and TLASes built).
    pub derived_ms: f64,
    pub persistent_choice_ms: f64,
    pub proxy_boxes_ms: f64,
    /// Where the boxes inside streamable BLASes came from: "package" (the package's
    /// `proxy_boxes` section, stored at import), "cache" (the structure cache) or "computed"
    /// (read from every mesh).
    pub proxy_boxes_source: &'static str,
    pub skeleton_ms: f64,
    /// The first frame (all its passes, builds and its next-camera probe).
    pub first_frame_ms: f64,
    /// From the command's start to the end of the first frame (0 when the caller gave no
    /// start).
    pub to_first_pixel_ms: f64,
    /// Writing the PNG and AOV after the render (`motu render` adds it).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub write_ms: Option<f64>,
}

mirror! {
    /// `motu_render::denoise::DenoiseStats` as JSON.
    DenoiseStats from crate::denoise::DenoiseStats {
        filter: &'static str,
        iterations: u32,
        filtered_pixels: u64,
        denoise_ms: f64,
    }
}

/// `motu view --stats`: the last frame (as `motu render`'s, `frames` counting the frames
/// shown), the window's timing, residency and accumulation, and the renderer's detail.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ViewStats {
    #[serde(flatten)]
    pub frame: FrameStats,
    /// Wall time per frame shown (median, and every frame).
    pub wall_ms_per_frame_median: f64,
    pub wall_ms_per_frame: Vec<f64>,
    pub window: WindowStats,
    pub vram_used_bytes: u64,
    pub resident_structures: u64,
    pub total_structures: u64,
    /// Whether the viewer streamed.
    pub streaming: bool,
    /// Frames shown with unfinished pixels, and the unfinished pixels of each frame.
    pub incomplete_frames: u64,
    pub incomplete_pixels_per_frame: Vec<u64>,
    pub lod_mode: &'static str,
    pub accumulated_samples: u32,
    pub denoised: bool,
    /// `--stream`/`--vram-budget`: whether the budget held the whole scene, so the full build
    /// drew it (`streaming` is then false), as `motu render --stream`'s `stream_fit`; `null`
    /// without streaming and with `--stream-always`.
    pub stream_fit: Option<StreamFitStats>,
    /// The last frame's renderer detail (absent when the renderer gave none).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail: Option<ViewDetail>,
    pub package: String,
}

/// `window` in `motu view --stats`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct WindowStats {
    pub width: u32,
    pub height: u32,
    /// How frames reached the screen (`swapchain`).
    pub presented_via: &'static str,
    /// Frames presented with the panel drawn over them, and the last frame's pixels the panel
    /// changed on the window (0 without a panel or a screenshot).
    pub panel_frames: u64,
    pub panel_pixels: u64,
}

/// `detail` in `motu view --stats`: a full build's resources or the streamed frame's stats.
#[derive(Clone, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum ViewDetail {
    Resources(Box<ResourceReport>),
    Stream(Box<FrameStreamStats>),
}
