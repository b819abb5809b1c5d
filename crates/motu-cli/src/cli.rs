//! The argument grammar (clap derive), one struct per subcommand.

use crate::size::parse_budget;
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

mod gen;
mod import;
mod stream;

pub use gen::{GenArgs, GenFormatArg, GenKindArg};
pub use import::{CurvesArg, ImportArgs, LevelsArg};
pub use stream::{
    AsCacheArgs, FallbackArg, HostCacheArg, HostCachePolicyArg, MeshMemoryArg, OnOffArg,
    StreamBoundArgs, StreamRatesArg, StreamTlasArg, TlasBuildArg, TlasRecordsArg,
};

// `render`/`view` flags under help headings (issue 46: 38 flags in one list were not a CLI a
// person can hold in their head). The expert streaming knobs show in `--help`, not in `-h`.
const HEADING_OUTPUT: &str = "Output";
const HEADING_CAMERA: &str = "Camera";
const HEADING_SHADING: &str = "Shading";
const HEADING_SCENE: &str = "Scene subset and level of detail";
const HEADING_DEVICE: &str = "Device and budget";
const HEADING_STREAMING: &str = "Streaming";
const HEADING_STREAMING_EXPERT: &str = "Streaming, expert (--help only)";
const HEADING_DEBUG: &str = "Debugging";

#[derive(Parser, Debug)]
#[command(name = "motu", version, about = "Make Moana-scale instanced scenes usable on one GPU", long_about = None)]
pub struct Cli {
    /// More logging (-v info, -vv debug, -vvv trace); MOTU_LOG overrides.
    #[arg(short, long, action = clap::ArgAction::Count, global = true)]
    pub verbose: u8,
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// List Vulkan devices, their ray-tracing support, limits and heap budgets.
    Devices(DevicesArgs),
    /// Write a procedural pbrt scene (DIR/scene.pbrt + PLY files).
    Gen(GenArgs),
    /// Import a pbrt-v3/v4 or OBJ scene into a compiled, chunked scene package.
    Import(ImportArgs),
    /// Show a package's structure and sizes.
    Info(InfoArgs),
    /// Check every checksum, offset and padding byte of a package.
    Verify(VerifyArgs),
    /// VRAM-budget report: what a scene costs on a GPU and what fits.
    Report(ReportArgs),
    /// Render a package headless to PNG (and AOV/stats).
    Render(RenderArgs),
    /// Fly through a package in a window (needs a display; `motu render` is the headless path).
    View(ViewArgs),
    /// Compare two AOV files pixel by pixel.
    Compare(CompareArgs),
    /// Repeatable measurements.
    Bench(BenchArgs),
    /// Generate the default scene, import it and render demo.png, showing where time and memory went.
    Demo(DemoArgs),
}

#[derive(Args, Debug)]
pub struct DevicesArgs {
    /// One JSON object on stdout.
    #[arg(long)]
    pub json: bool,
}

/// `render --lod-mode`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum LodModeArg {
    Instance,
    Traversal,
}

/// `--depth-epsilon`: a finite relative tolerance ≥ 0.
fn parse_depth_epsilon(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|_| format!("'{s}' is not a number"))?;
    if v.is_finite() && v >= 0.0 {
        Ok(v)
    } else {
        Err(format!(
            "{s} is not a relative depth tolerance: it must be a finite number ≥ 0 (e.g. 0.001)"
        ))
    }
}

fn parse_threshold(s: &str) -> Result<f64, String> {
    let v: f64 = s.parse().map_err(|_| format!("'{s}' is not a number"))?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is not a fraction in [0, 1]"))
    }
}

#[derive(Args, Debug)]
pub struct InfoArgs {
    pub package: PathBuf,
    #[arg(long)]
    pub json: bool,
    /// List the scene's elements with instance and triangle counts.
    #[arg(long)]
    pub elements: bool,
}

#[derive(Args, Debug)]
pub struct VerifyArgs {
    pub package: PathBuf,
}

#[derive(Args, Debug)]
pub struct ReportArgs {
    pub package: PathBuf,
    /// VRAM budget to fit the scene into.
    #[arg(long, value_parser = parse_budget)]
    pub budget: Option<u64>,
    /// Vulkan device index.
    #[arg(long, env = "MOTU_DEVICE")]
    pub device: Option<usize>,
    #[arg(long)]
    pub json: bool,
    /// Write a self-contained HTML report.
    #[arg(long)]
    pub html: Option<PathBuf>,
    /// Build the structures to measure real (compacted) sizes.
    #[arg(long)]
    pub measure: bool,
    /// Image width the streaming floor is computed for (default: the first camera's).
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height the streaming floor is computed for (default: the first camera's).
    #[arg(long)]
    pub height: Option<u32>,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlasBuildArg {
    FastTrace,
    Small,
}

impl From<BlasBuildArg> for motu_gpu::BlasBuild {
    fn from(b: BlasBuildArg) -> Self {
        match b {
            BlasBuildArg::FastTrace => motu_gpu::BlasBuild::FastTrace,
            BlasBuildArg::Small => motu_gpu::BlasBuild::Small,
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum BackendArg {
    Pipeline,
    Query,
    Cpu,
}

impl From<BackendArg> for motu_render::Backend {
    fn from(b: BackendArg) -> Self {
        match b {
            BackendArg::Pipeline => motu_render::Backend::Pipeline,
            BackendArg::Query => motu_render::Backend::Query,
            BackendArg::Cpu => motu_render::Backend::Cpu,
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ViewArg {
    Shaded,
    Heatmap,
    Lod,
    Ids,
    /// The primary hit's textured base colour (the denoiser's material guide).
    Albedo,
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    pub package: PathBuf,
    /// Output PNG.
    #[arg(help_heading = HEADING_OUTPUT, short, long)]
    pub output: PathBuf,
    /// Camera name (default: the scene's active camera).
    #[arg(help_heading = HEADING_CAMERA, long)]
    pub camera: Option<String>,
    /// Image width in pixels (default: the camera's film; with only one of --width and --height,
    /// the other keeps the film's aspect).
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub width: Option<u32>,
    /// Image height in pixels (see --width).
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub height: Option<u32>,
    /// Default: query where available, else pipeline.
    #[arg(help_heading = HEADING_DEVICE, long, value_enum)]
    pub backend: Option<BackendArg>,
    /// What the image shows: shaded, a traversal heatmap, LOD levels or ids.
    #[arg(help_heading = HEADING_SHADING, long, value_enum, default_value = "shaded")]
    pub view: ViewArg,
    /// Write the per-pixel hit record (FORMAT.md, "AOV file").
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub aov: Option<PathBuf>,
    /// VRAM the render may use (a size: 512MiB, 8GiB); default: the device's budget.
    #[arg(help_heading = HEADING_DEVICE, long, value_parser = parse_budget)]
    pub vram_budget: Option<u64>,
    /// Cap on VkDeviceMemory allocations (lower than the device's, for testing).
    #[arg(help_heading = HEADING_DEBUG, long)]
    pub max_allocations: Option<u32>,
    /// How BLASes are built. Default: fast-trace for a full build, small with --stream
    /// (fast build and low memory: a fifth smaller on NVIDIA, faster to build).
    #[arg(help_heading = HEADING_DEVICE, long, value_enum)]
    pub blas_build: Option<BlasBuildArg>,
    /// Build only what rays touch and evict under the budget.
    #[arg(help_heading = HEADING_STREAMING, long)]
    pub stream: bool,
    /// With --stream: write the image even when a frame ends with unfinished pixels (they are
    /// magenta misses; a loud, counted warning). Without it such a frame is an error.
    #[arg(help_heading = HEADING_STREAMING, long)]
    pub allow_incomplete: bool,
    /// With --stream: build–traverse passes per frame before a frame gives up (testing; by
    /// default sized from the scene's structure count).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, hide = true)]
    pub stream_max_passes: Option<u32>,
    /// With --stream: stream even when the budget holds the whole scene (by default the full
    /// build renders it then, being never slower; for testing the streamer).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long)]
    pub stream_always: bool,
    #[command(flatten)]
    pub stream_bounds: StreamBoundArgs,
    #[command(flatten)]
    pub as_cache: AsCacheArgs,
    /// Frames to render (timing; with --stream, along the camera path).
    #[arg(help_heading = HEADING_CAMERA, long, default_value_t = 1)]
    pub frames: u32,
    /// Write statistics JSON.
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub stats: Option<PathBuf>,
    /// Render only these elements (comma-separated).
    #[arg(help_heading = HEADING_SCENE, long, value_delimiter = ',')]
    pub subset: Vec<String>,
    /// Force every LOD selector to this level.
    #[arg(help_heading = HEADING_SCENE, long)]
    pub lod: Option<u32>,
    /// LOD rule: projected radius (pixels) at and above which the finest level is used; one
    /// level coarser per halving.
    #[arg(help_heading = HEADING_SCENE, long, default_value_t = 256.0)]
    pub lod_r_max: f32,
    /// Levels added for shadow rays (when they do not take the primary hit's level).
    #[arg(help_heading = HEADING_SCENE, long, default_value_t = 1.0)]
    pub shadow_lod_bias: f32,
    /// Dither between the two nearest LOD levels (hashed per pixel) instead of rounding down.
    #[arg(help_heading = HEADING_SCENE, long)]
    pub lod_stochastic: bool,
    /// How LOD selectors are resolved: `instance` picks each LOD instance's level per frame
    /// from the camera (a compute pass rewrites the TLAS: one trace, no traversal-shader hop;
    /// every ray sees an instance at one level, so --shadow-lod-bias does not apply), where the
    /// rule allows (not with --lod-stochastic or --stream, which use `traversal`: a level per
    /// ray, chosen in the traversal shader). The mode that ran is `lod_mode` in --stats.
    #[arg(help_heading = HEADING_SCENE, long, value_enum, default_value_t = LodModeArg::Instance)]
    pub lod_mode: LodModeArg,
    /// Traversal stack entries per ray (1–256: 64 bytes of private shader memory each).
    #[arg(help_heading = HEADING_DEBUG, long, default_value_t = 16,
          value_parser = clap::value_parser!(u32).range(1..=i64::from(motu_gpu::MAX_STACK_SIZE)))]
    pub stack_size: u32,
    /// TLAS walks one ray may make before it is cut short (bounds a frame's work on
    /// exponentially deep instancing); cut rays are counted as `truncated_rays`.
    #[arg(help_heading = HEADING_DEBUG, long, default_value_t = motu_abi::DEFAULT_MAX_TRACES_PER_RAY,
          value_parser = clap::value_parser!(u32).range(1..))]
    pub max_traces_per_ray: u32,
    /// Write the image even when rays were truncated (stack overflow or --max-traces-per-ray):
    /// a counted warning instead of an error.
    #[arg(help_heading = HEADING_DEBUG, long)]
    pub allow_truncated: bool,
    /// Capture the driver's statistics of every pipeline made (registers, spills, instruction
    /// counts: VK_KHR_pipeline_executable_properties), logged at info and written as
    /// `pipeline_executables` in --stats. A device without the extension warns (no statistics).
    #[arg(help_heading = HEADING_DEBUG, long)]
    pub pipeline_stats: bool,
    /// Samples per pixel of the shaded view (the first, at the pixel centre, gives the AOV).
    #[arg(help_heading = HEADING_SHADING, long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub spp: u32,
    /// Ambient-occlusion rays per sample for the sky term (0: unoccluded sky light).
    #[arg(help_heading = HEADING_SHADING, long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(0..=256))]
    pub ao_samples: u32,
    /// How far ambient-occlusion rays reach, as a fraction of the scene's diagonal (default
    /// 0.2). A shorter reach changes the image (less distant occlusion) and, streamed, keeps
    /// AO rays from requesting far structures: a smaller working set under a small budget.
    /// Compare a streamed render against a full build with the same value.
    #[arg(help_heading = HEADING_SHADING, long, value_name = "FRACTION", default_value_t = motu_render::AO_DISTANCE_OF_DIAGONAL, value_parser = parse_ao_reach)]
    pub ao_reach: f32,
    /// Diffuse bounces of the shaded view after each camera hit, each lit by the scene's lights
    /// and environment (0: direct light only).
    #[arg(help_heading = HEADING_SHADING, long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(0..=8))]
    pub bounces: u32,
    /// Exposure of the shaded view: `auto` (the image's log-average luminance becomes middle
    /// grey; the chosen value is `exposure_ev` in --stats) or a number of stops EV (the image is
    /// scaled by 2^EV before the sRGB transfer).
    #[arg(help_heading = HEADING_SHADING, long, default_value = "auto", allow_hyphen_values = true, value_parser = parse_exposure)]
    pub exposure: ExposureArg,
    /// Filter the shaded image's sampling noise with an edge-aware à-trous filter guided by the
    /// AOV's depth, the normals it implies and the materials' base colours (never the AOV;
    /// `denoise` in --stats). Only the shaded view.
    #[arg(help_heading = HEADING_SHADING, long)]
    pub denoise: bool,
    /// Vulkan device index.
    #[arg(help_heading = HEADING_DEVICE, long, env = "MOTU_DEVICE")]
    pub device: Option<usize>,
    /// Replay a recorded camera path (`motu view --record`) over `--frames` frames (default:
    /// one per recorded pose); writes the last frame.
    #[arg(help_heading = HEADING_CAMERA, long)]
    pub camera_path: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct ViewArgs {
    pub package: PathBuf,
    /// Start at this scene camera (default: the scene's active camera); 1–9 switch cameras.
    #[arg(help_heading = HEADING_CAMERA, long)]
    pub camera: Option<String>,
    /// Window size (default: the camera's image size).
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub width: Option<u32>,
    /// Image height in pixels (see --width).
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub height: Option<u32>,
    /// Default: query where available, else pipeline.
    #[arg(help_heading = HEADING_DEVICE, long, value_enum)]
    pub backend: Option<BackendArg>,
    #[arg(help_heading = HEADING_SHADING, long, value_enum, default_value = "shaded")]
    pub view: ViewArg,
    /// How far ambient-occlusion rays reach, as a fraction of the scene's diagonal, as `motu
    /// render --ao-reach` (default 0.2; a shorter reach: a smaller streamed working set).
    #[arg(help_heading = HEADING_SHADING, long, value_name = "FRACTION", default_value_t = motu_render::AO_DISTANCE_OF_DIAGONAL, value_parser = parse_ao_reach)]
    pub ao_reach: f32,
    /// Diffuse bounces at the start, as `motu render --bounces` (the panel changes it live).
    #[arg(help_heading = HEADING_SHADING, long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(0..=8))]
    pub bounces: u32,
    /// Stream structures under this VRAM budget (implies --stream).
    #[arg(help_heading = HEADING_DEVICE, long, value_parser = parse_budget)]
    pub vram_budget: Option<u64>,
    /// Build only what rays touch and evict under the budget.
    #[arg(help_heading = HEADING_STREAMING, long)]
    pub stream: bool,
    /// Streaming: build–trace passes per frame. 1 (the default while flying): trace with what
    /// is resident (the rest unfinished, or the --stream-fallback), then build toward the next
    /// frame within the frame's build budget (--stream-build-budget/--stream-build-ms; 30 ms
    /// while flying if neither is given), so the window stays responsive and later frames
    /// refine. With --frames the default is the full pass cap (each frame exact).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long)]
    pub stream_passes: Option<u32>,
    /// With --stream or --vram-budget: stream even when the budget holds the whole scene (by
    /// default the full build draws it then, being never slower; for testing the streamer).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long)]
    pub stream_always: bool,
    #[command(flatten)]
    pub stream_bounds: StreamBoundArgs,
    #[command(flatten)]
    pub as_cache: AsCacheArgs,
    #[arg(help_heading = HEADING_DEBUG, long)]
    pub max_allocations: Option<u32>,
    /// Elements shown at the start (comma-separated; Shift+1–9 toggle them live).
    #[arg(help_heading = HEADING_SCENE, long, value_delimiter = ',')]
    pub subset: Vec<String>,
    /// Force every LOD selector to this level (L cycles live).
    #[arg(help_heading = HEADING_SCENE, long)]
    pub lod: Option<u32>,
    #[arg(help_heading = HEADING_SCENE, long, default_value_t = 256.0)]
    pub lod_r_max: f32,
    #[arg(help_heading = HEADING_SCENE, long)]
    pub lod_stochastic: bool,
    /// How LOD selectors are resolved at the start, as in `motu render --lod-mode` (M toggles
    /// live): `instance` where the rule allows (not with --lod-stochastic/K or streaming),
    /// else the traversal shader. The panel and --stats (`lod_mode`) say which ran.
    #[arg(help_heading = HEADING_SCENE, long, value_enum, default_value_t = LodModeArg::Instance)]
    pub lod_mode: LodModeArg,
    #[arg(help_heading = HEADING_DEBUG, long, default_value_t = 16)]
    pub stack_size: u32,
    #[arg(help_heading = HEADING_DEVICE, long, env = "MOTU_DEVICE")]
    pub device: Option<usize>,
    /// Render N frames through the window and swapchain, write the last (--screenshot, --aov,
    /// --stats) and exit.
    #[arg(help_heading = HEADING_CAMERA, long)]
    pub frames: Option<u32>,
    /// With --frames: the last frame as read back from the swapchain image (PNG).
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub screenshot: Option<PathBuf>,
    /// With --frames: the last frame's hit records (FORMAT.md, "AOV file").
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub aov: Option<PathBuf>,
    /// With --frames: statistics JSON of the last frame.
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub stats: Option<PathBuf>,
    /// Write the camera of every frame shown as a camera path (JSON) on exit.
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub record: Option<PathBuf>,
    /// Fly along a recorded camera path instead of the fly camera (frames: one per pose, or
    /// --frames spread over it).
    #[arg(help_heading = HEADING_CAMERA, long)]
    pub camera_path: Option<PathBuf>,
    /// Show the panel in --frames runs too (drawn on the window after the screenshot is read:
    /// never in --screenshot or --aov).
    #[arg(help_heading = HEADING_OUTPUT, long, conflicts_with = "no_panel")]
    pub overlay: bool,
    /// Start with the panel hidden (Tab shows it).
    #[arg(help_heading = HEADING_OUTPUT, long)]
    pub no_panel: bool,
    /// Present as fast as possible (MAILBOX/IMMEDIATE) instead of at the display's rate.
    #[arg(help_heading = HEADING_DEVICE, long)]
    pub no_vsync: bool,
    /// Accumulate samples while the camera rests in --frames runs too (a window always does
    /// until P turns it off): each frame adds the next samples of every pixel's sequence and
    /// the image converges; anything that changes starts again. Without it a scripted frame
    /// equals `motu render`'s per pixel.
    #[arg(help_heading = HEADING_SHADING, long)]
    pub accumulate: bool,
    /// Start with the denoiser on (N toggles it): the shown image is filtered as `motu render
    /// --denoise` filters, never the AOV.
    #[arg(help_heading = HEADING_SHADING, long)]
    pub denoise: bool,
    /// Fly speed in world units per second (default: a quarter of the scene's radius).
    #[arg(help_heading = HEADING_CAMERA, long)]
    pub speed: Option<f32>,
    /// For scripts and tests: click the panel's widget labelled LABEL (an element, a view, a
    /// checkbox, a camera button) through egui's input, as a user would, starting at frame
    /// FRAME (≥ 2: egui lays the panel out in frames 0 and 1; hover, press, release: the change
    /// renders from frame FRAME+3). Repeatable; needs the panel shown (--overlay with
    /// --frames); a label not visible is an error.
    #[arg(help_heading = HEADING_DEBUG, long, value_name = "FRAME:LABEL")]
    pub panel_click: Vec<motu_view::PanelClick>,
}

#[derive(Args, Debug)]
pub struct CompareArgs {
    pub a: PathBuf,
    pub b: PathBuf,
    /// Exit non-zero above this fraction of mismatched pixels.
    #[arg(long, default_value = "0.001", value_parser = parse_threshold)]
    pub max_mismatch: f64,
    /// Relative depth tolerance (finite, ≥ 0).
    #[arg(long, default_value = "0.001", value_parser = parse_depth_epsilon, allow_hyphen_values = true)]
    pub depth_epsilon: f32,
    /// Write a difference image.
    #[arg(long)]
    pub diff: Option<PathBuf>,
    #[arg(long)]
    pub json: bool,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    /// Suite: `gpu` (the full device suite, 1920×1080), `quick` (tiny versions of the same, minutes
    /// on lavapipe), `cpu` (import/compile/pack and the CPU renderer).
    #[arg(default_value = "quick")]
    pub suite: String,
    /// One JSON object on stdout (the whole report).
    #[arg(long)]
    pub json: bool,
    /// Where to keep generated scenes, packages, logs and renders (default: ./motu-bench).
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Tiny versions of the suite's scenes (`motu bench gpu --quick` is the `quick` suite).
    #[arg(long)]
    pub quick: bool,
    /// Also write the results as a Markdown table (for BENCHMARKS.md).
    #[arg(long)]
    pub markdown: Option<PathBuf>,
    /// Run only these scenes (comma-separated: forest, sphereflake, lod-grid, island, buddha-fractal).
    #[arg(long, value_delimiter = ',')]
    pub only: Vec<String>,
    /// Timed frames per render (default: 21 for gpu, fewer for quick/cpu).
    #[arg(long)]
    pub frames: Option<u32>,
    /// Untimed warm-up frames, submitted before the timed ones.
    #[arg(long)]
    pub warmup: Option<u32>,
    #[arg(long)]
    pub width: Option<u32>,
    #[arg(long)]
    pub height: Option<u32>,
    /// Render backend (default: the best the device has; `cpu` for the cpu suite).
    #[arg(long, value_enum)]
    pub backend: Option<BackendArg>,
    /// `motu gen island --scale` for the island scene (default: just over 2^24 flattened instances
    /// in the gpu suite).
    #[arg(long)]
    pub island_scale: Option<f64>,
    /// Directory holding `buddha-fractal/` (default: shared/scenes beside or above the working
    /// directory or the binary).
    #[arg(long)]
    pub scenes: Option<PathBuf>,
    /// Run only these configurations (comma-separated labels: sl, ml, levels2, sl+lod, ml+lod).
    #[arg(long, value_delimiter = ',')]
    pub configs: Vec<String>,
    /// Start no step after this many seconds: the rest is recorded as skipped, so a time-limited
    /// machine still returns every result measured so far.
    #[arg(long)]
    pub deadline_s: Option<u64>,
    /// Kill a step (gen, import, render) that runs longer than this and record it as failed.
    #[arg(long)]
    pub step_timeout_s: Option<u64>,
    /// Keep packages after rendering them (default: deleted, to bound disk use).
    #[arg(long)]
    pub keep: bool,
    /// Print the plan (scenes, configurations, commands) and exit.
    #[arg(long)]
    pub dry_run: bool,
    /// One line per step on stderr even when stderr is not a terminal.
    #[arg(long)]
    pub progress: bool,
    /// Replay this recorded camera path (`motu view --record`) on `--package` as a benchmark
    /// (frame times along the flight) instead of running a suite.
    #[arg(long, requires = "package")]
    pub camera_path: Option<PathBuf>,
    /// The package a `--camera-path` flight is flown through.
    #[arg(long, requires = "camera_path")]
    pub package: Option<PathBuf>,
    /// With --camera-path: fly through the streaming renderer (structures built as rays need
    /// them, evicted under --vram-budget): per-frame passes, bytes built and build/trace ms.
    #[arg(long, requires = "camera_path")]
    pub stream: bool,
    /// With --camera-path --stream: the VRAM budget (default: unlimited).
    #[arg(long, value_parser = parse_budget, requires = "camera_path")]
    pub vram_budget: Option<u64>,
    /// With --camera-path: ambient-occlusion reach as a fraction of the scene's diagonal, as
    /// `motu render --ao-reach` (default 0.2).
    #[arg(long, value_name = "FRACTION", value_parser = parse_ao_reach, requires = "camera_path")]
    pub ao_reach: Option<f32>,
    /// With --camera-path: diffuse bounces, as `motu render --bounces` (default 1).
    #[arg(long, value_parser = clap::value_parser!(u32).range(0..=8), requires = "camera_path")]
    pub bounces: Option<u32>,
    /// With --camera-path --stream: build–trace passes per frame, as `motu view
    /// --stream-passes`. 1: the viewer's flying mode (one trace with what is resident, then one
    /// build step toward the next frame; 30 ms of building unless --stream-build-ms or
    /// --stream-build-budget says otherwise). Default: passes until the frame is complete or its
    /// build budget is spent (then one more pass).
    #[arg(long, value_name = "N", requires = "camera_path")]
    pub stream_passes: Option<u32>,
    /// With --camera-path --stream: the camera each frame probes and prefetches for. `path`
    /// (default): the path's next pose; `extrapolated`: the viewer's guess, one more step along
    /// the motion from the previous frame (none on the first frame, itself while still).
    #[arg(long, value_enum, value_name = "WHICH", requires = "camera_path")]
    pub next_camera: Option<NextCameraArg>,
    /// With --camera-path --stream: render the path's last pose K more times (a camera come to
    /// rest); the report says after how many of them a frame was complete
    /// (still_frames_to_complete).
    #[arg(long, value_name = "K", requires = "camera_path")]
    pub still_frames: Option<u32>,
    #[command(flatten)]
    pub stream_bounds: StreamBoundArgs,
    /// Internal: render one package and write its measurements (the child process of a render step).
    #[arg(long, hide = true)]
    pub child_render: Option<PathBuf>,
    /// Internal: where the child writes its measurements (JSON).
    #[arg(long, hide = true)]
    pub child_stats: Option<PathBuf>,
    /// Internal: where the child writes the last frame (PNG).
    #[arg(long, hide = true)]
    pub child_png: Option<PathBuf>,
}

/// `motu bench --next-camera`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum NextCameraArg {
    Path,
    Extrapolated,
}

impl From<NextCameraArg> for motu_bench::NextCamera {
    fn from(a: NextCameraArg) -> Self {
        match a {
            NextCameraArg::Path => motu_bench::NextCamera::Path,
            NextCameraArg::Extrapolated => motu_bench::NextCamera::Extrapolated,
        }
    }
}

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Working directory for the generated scene and package.
    #[arg(long, default_value = "demo-out")]
    pub work_dir: PathBuf,
    /// The image to write.
    #[arg(short, long, default_value = "demo.png")]
    pub output: PathBuf,
}

/// `--exposure`: `auto` or a finite number of stops.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ExposureArg {
    Auto,
    Ev(f32),
}

fn parse_exposure(s: &str) -> Result<ExposureArg, String> {
    if s.eq_ignore_ascii_case("auto") {
        return Ok(ExposureArg::Auto);
    }
    match s.parse::<f32>() {
        Ok(v) if v.is_finite() => Ok(ExposureArg::Ev(v)),
        _ => Err(format!(
            "--exposure {s:?} is neither `auto` nor a finite number of stops"
        )),
    }
}

/// `--ao-reach`: a finite fraction of the scene's diagonal in (0, 1000].
fn parse_ao_reach(s: &str) -> Result<f32, String> {
    let v: f32 = s.parse().map_err(|_| {
        format!("`{s}` is not a number (a fraction of the scene's diagonal, e.g. 0.05)")
    })?;
    if !(v.is_finite() && v > 0.0 && v <= 1000.0) {
        return Err(format!(
            "{s} is outside (0, 1000] (a fraction of the scene's diagonal)"
        ));
    }
    Ok(v)
}
