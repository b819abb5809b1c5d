//! The argument grammar (clap derive), one struct per subcommand.

use crate::size::{parse_budget, parse_size};
use clap::{Args, Parser, Subcommand, ValueEnum};
use std::path::PathBuf;

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

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum GenKindArg {
    Forest,
    Sphereflake,
    LodGrid,
    Island,
    /// A lighting test: a courtyard lit by a sky map and a sun through a roof opening.
    Courtyard,
}

#[derive(Args, Debug)]
pub struct GenArgs {
    pub kind: GenKindArg,
    /// Output directory: written into a temp directory beside it and renamed into place when
    /// complete. An existing non-empty directory is refused unless --force.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Replace an existing non-empty output directory (as a whole, once the new scene is
    /// complete).
    #[arg(long)]
    pub force: bool,
    /// forest: grid levels above the tree; trees = (W·H)^N (the thesis layout is 3).
    #[arg(long)]
    pub levels: Option<u32>,
    /// forest: copies per level as a WxH grid (the thesis layout is 4x3); lod-grid: W across,
    /// H rows going away from the camera.
    #[arg(long)]
    pub grid: Option<String>,
    /// forest: leaf instances per tree.
    #[arg(long)]
    pub leaves: Option<u32>,
    /// forest: trunk detail (3..=512).
    #[arg(long)]
    pub trunk_segments: Option<u32>,
    /// sphereflake: recursion depth (spheres = 1 + 9 + … + 9^N).
    #[arg(long)]
    pub depth: Option<u32>,
    /// sphereflake: sphere tessellation.
    #[arg(long)]
    pub sphere_segments: Option<u32>,
    /// island: 1 approximates Moana's counts (~28M instances, ~36 GB of pbrt).
    #[arg(long)]
    pub scale: Option<f64>,
    /// island: number of elements (1–20, Moana's names).
    #[arg(long)]
    pub elements: Option<u32>,
    /// lod-grid: target triangles of the dense mesh.
    #[arg(long)]
    pub triangles: Option<u32>,
    /// lod-grid: distance between copies.
    #[arg(long)]
    pub spacing: Option<f64>,
    /// forest, sphereflake: write standard single-level pbrt (no nested ObjectInstance).
    #[arg(long)]
    pub flat: bool,
    /// Random seed (generation is deterministic for a seed).
    #[arg(long)]
    pub seed: Option<u64>,
    /// Image width written to the Film.
    #[arg(long)]
    pub width: Option<u32>,
    /// Image height written to the Film.
    #[arg(long)]
    pub height: Option<u32>,
    /// island: writer threads.
    #[arg(long)]
    pub threads: Option<usize>,
    /// island: triangles per terrain patch / trunk section before it is split (64..=2^30;
    /// default 1000000).
    #[arg(long)]
    pub max_mesh_triangles: Option<u32>,
    /// island: wrap each terrain geometry file in its own object instanced once, so every
    /// patch gets its own BLAS (the unit `--stream` builds and evicts).
    #[arg(long)]
    pub terrain_objects: bool,
    /// island: the file layout: `pbrt` (Moana's pbrt-v3 release) or `json` (Moana's JSON+OBJ
    /// base package: `DIR/json/island.json`, element JSON, OBJ).
    #[arg(long, value_enum, default_value = "pbrt")]
    pub format: GenFormatArg,
    /// One JSON object on stdout describing what was written.
    #[arg(long)]
    pub json: bool,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum GenFormatArg {
    Pbrt,
    Json,
}

#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum CurvesArg {
    Skip,
    Ribbons,
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub enum LevelsArg {
    Ml,
    Auto,
    Sl,
    N(u32),
}

fn parse_levels(s: &str) -> Result<LevelsArg, String> {
    match s {
        "ml" => Ok(LevelsArg::Ml),
        "auto" => Ok(LevelsArg::Auto),
        "sl" => Ok(LevelsArg::Sl),
        n => match n.parse::<u32>() {
            Ok(v) if v >= 1 => Ok(LevelsArg::N(v)),
            _ => Err(format!(
                "'{s}': expected ml, auto, sl or a number of levels ≥ 1"
            )),
        },
    }
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
pub struct ImportArgs {
    /// The entry .pbrt (or .pbrt.gz) file, an .obj file, or Moana's JSON+OBJ base package: its
    /// `json/` folder (or the island folder above it), one element's folder or JSON file, or a
    /// list `{"elements": [...], "cameras": [...], "lights": [...]}` (`motu gen island --format
    /// json` writes `json/island.json`).
    pub scene: PathBuf,
    /// Output package path.
    #[arg(short, long)]
    pub output: PathBuf,
    /// ml: keep the instancing graph; auto: ml with cheap grouping levels inlined, small
    /// instanced prototypes (at most 2^17 triangles with their copies) baked into triangle BLASes
    /// and levels whose inlining costs at most 2^16 instances inlined (fewer traces per ray, big
    /// geometry still shared); sl: flatten to one level; N: at most N levels.
    #[arg(long, default_value = "ml", value_parser = parse_levels)]
    pub levels: LevelsArg,
    /// Instances per TLAS before it is split (default: the spec's 2^24−1).
    #[arg(long, default_value_t = (1 << 24) - 1)]
    pub max_instances: u32,
    /// Also split a TLAS whose estimated build scratch would exceed this (128 B per instance).
    #[arg(long, value_parser = parse_size)]
    pub max_tlas_scratch: Option<u64>,
    /// Triangles per triangle BLAS (the partitioner's bound): a mesh over it is split into
    /// spatial clusters, small meshes are grouped by location under it. Default: chosen from
    /// the scene's size: 2^16 (every BLAS around 6.5 MiB, ≤ 12 MiB with build scratch and
    /// geometry), or about a 256th of the whole build on scenes under ~8.4M triangles (at
    /// least 4,096; heavily instanced meshes are not split), so a streaming budget far below
    /// the full build still holds the largest one and a frame's working set is not padded out
    /// by whole coarse units.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..))]
    pub max_blas_triangles: Option<u32>,
    /// Build N LOD levels for heavy meshes.
    #[arg(long)]
    pub lod: Option<u32>,
    /// With --lod: meshes with more triangles than this get a LOD chain.
    #[arg(long, default_value_t = 10_000)]
    pub lod_min_triangles: u32,
    /// Compress chunks with zstd at this level (1–22).
    #[arg(long)]
    pub zstd: Option<i32>,
    /// `curve` shapes: `ribbons` tessellates them into flat ribbons (motu traces triangles),
    /// `skip` counts and drops them.
    #[arg(long, value_enum, default_value = "ribbons")]
    pub curves: CurvesArg,
    /// Warn about missing referenced files and skip their shapes instead of failing.
    #[arg(long)]
    pub allow_missing: bool,
    /// Do not store the boxes inside triangle BLASes (the `proxy_boxes` section): a faster
    /// import whose streamed renders make them from every mesh at start instead.
    #[arg(long)]
    pub no_proxy_boxes: bool,
    /// Do not store the proxy clusters of the TLASes (the `proxy_clusters` section): a faster
    /// import whose streamed renders and `motu report` run the binned SAH over every instance
    /// instead.
    #[arg(long)]
    pub no_proxy_clusters: bool,
    /// Worker threads (default: all cores).
    #[arg(long)]
    pub threads: Option<usize>,
    /// Keep only these elements (comma-separated names).
    #[arg(long, value_delimiter = ',')]
    pub subset: Vec<String>,
    /// Force the pbrt version instead of detecting it (3 or 4).
    #[arg(long, value_parser = clap::value_parser!(u32).range(3..=4))]
    pub pbrt_version: Option<u32>,
    /// Chunk target size.
    #[arg(long, value_parser = parse_size, default_value = "64MiB")]
    pub chunk_size: u64,
    /// Image textures are stored as mip chains whose finest level has at most this many
    /// texels per side (larger images are halved until they fit).
    #[arg(long, default_value_t = 1024, value_parser = clap::value_parser!(u32).range(1..=16384))]
    pub texture_max: u32,
    /// Ptex faces keep at most this many texels per face edge (larger faces are halved with a
    /// box filter until they fit).
    #[arg(long, default_value_t = motu_import::DEFAULT_PTEX_MAX, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub ptex_max: u32,
    /// One JSON object on stdout describing the import.
    #[arg(long)]
    pub json: bool,
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

/// `--stream-fallback`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum FallbackArg {
    /// Unfinished pixels stay unfinished (an error unless --allow-incomplete).
    #[default]
    Off,
    /// A structure not resident yet shows as its bounds (a box; LOD 254 in the AOV, a hatched
    /// colour); counted per frame, never silent.
    Coarse,
}

/// Built structures kept for reuse while streaming (`render --stream`): a BLAS evicted or left
/// by an earlier process is restored by copy instead of rebuilt; images are the same.
#[derive(Args, Debug, Clone)]
pub struct AsCacheArgs {
    /// Streaming: bytes of built acceleration structures (serialised) kept in host memory,
    /// least recently used dropped first. Default: a quarter of the memory available at start;
    /// 0: none.
    #[arg(help_heading = HEADING_STREAMING, long, value_parser = parse_size)]
    pub host_cache: Option<u64>,
    /// Streaming: the directory where built structures are kept between runs (per device and
    /// driver; bad or foreign entries are rebuilt with a warning; a read-only or full
    /// directory is a warning). Default: $MOTU_AS_CACHE, else $XDG_CACHE_HOME/motu/as-cache,
    /// else ~/.cache/motu/as-cache.
    #[arg(help_heading = HEADING_STREAMING, long, conflicts_with = "no_as_cache")]
    pub as_cache: Option<PathBuf>,
    /// Streaming: keep no built structures on disk.
    #[arg(help_heading = HEADING_STREAMING, long)]
    pub no_as_cache: bool,
}

/// Bounded streaming work per frame (`render --stream`, `view`): how long a frame may build
/// and what the pixels still waiting show.
#[derive(Args, Debug, Clone, Copy)]
pub struct StreamBoundArgs {
    /// Streaming: what a structure that is not resident yet shows when a frame stops before
    /// building it (opt-in: such a frame is not exact; its fallback pixels are counted in
    /// --stats and on stderr). Later frames of a camera path refine it.
    #[arg(help_heading = HEADING_STREAMING, long, value_enum, default_value = "off")]
    pub stream_fallback: FallbackArg,
    /// Streaming: bytes (meshes plus acceleration structures) one frame may build; a frame
    /// stops when it is spent (at least one structure is built per frame) and later frames go
    /// on. Default: unbounded.
    #[arg(help_heading = HEADING_STREAMING, long, value_parser = parse_size)]
    pub stream_build_budget: Option<u64>,
    /// Streaming: milliseconds of building one frame may spend (same rules). Default: unbounded.
    #[arg(help_heading = HEADING_STREAMING, long, value_parser = parse_build_ms)]
    pub stream_build_ms: Option<f64>,
    /// Streaming: after each frame whose next camera is known (a camera path, a flight; the
    /// viewer extrapolates it), trace every ray of every STRIDE-th pixel of the next camera
    /// against what is resident and prefetch what they meet, so the next frame mostly
    /// completes in one pass; its rays and ms are reported (probe_rays, probe_ms). 0: no
    /// probe. Default 1 (every pixel).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "STRIDE")]
    pub stream_probe: Option<u32>,
    /// Streaming: probe rounds after a frame, at most (default 2). A probe ray stops at the
    /// first structure that is not resident; once the prefetch built it, the ray may hit in
    /// it and its shadow and AO rays need structures no probe saw. Each later round probes
    /// only the pixels the round before left open and prefetches what they need, at the cost
    /// of a TLAS rebuild or update (probe_rounds per frame). 1: one probe.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub stream_probe_rounds: Option<u32>,
    /// Streaming: verifying probe rounds after those, at most (default 2; 0: none). The
    /// prefetch evicts for room what no probe ray met, and the next frame's rays may pass
    /// through some of it on their way to their hits; a verifying round probes every pixel
    /// again against what the prefetch left resident and prefetches what is now missing, so
    /// the next frame completes in one pass where its structures fit (H200, island 0.3 at a
    /// quarter of its full build, primary visibility: 1.909 → 1.091 passes after the first at
    /// about the same frame time; shaded at half 1.182 → 1.000, frames +12%; at a third
    /// 1.182 → 1.000, frames +53%). Each round costs a probe trace and, when it finds
    /// something, a build step (probe_verify_rounds per frame); 0 for throughput.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "N")]
    pub stream_probe_verify: Option<u32>,
    /// Streaming: the probe's pixels of every N-th row also mark the resident structures their
    /// rays pass through without hitting, so the prefetch evicts those last (it never skips a
    /// build to keep them). Fewer second passes where the prefetch evicts for room (a third
    /// of the full build on the H200: 1.727 → 1.182 passes after the first), at the cost of
    /// the probe's time (at half: frames +20–40% for 1.182 → 1.000). `auto` (default): every
    /// 2nd row for the probes within 4 frames of one whose builds evicted for room while its
    /// prefetch skipped nothing, else none (H200: a third 1.727 → 1.182 at the same frame
    /// time; half and a quarter never mark, unchanged). --stats has the stride and the count
    /// per frame (probe_pass_rows, probe_pass_marks). 0: off.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "N|auto", value_parser = parse_pass_marks)]
    pub stream_probe_pass_rows: Option<motu_gpu::PassMarks>,
    /// Streaming: how TLASes follow what is resident. `update`: each TLAS is built once over
    /// all its instances (a non-resident one points at a placeholder no ray meets) and
    /// updated in place as BLASes come and go: no rebuild transient, at the cost of the TLAS
    /// at full residency kept resident. `rebuild`: rebuilt over its resident instances
    /// whenever they change (smallest resident TLAS). `auto` (default): update when the
    /// persistent TLASes take at most a fifth of the budget. `--stats` reports the choice
    /// (stream.tlas_mode).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, default_value = "auto")]
    pub stream_tlas: StreamTlasArg,
    /// Streaming: TLASes over N instances (a large root) are split into spatial pieces when
    /// the package is loaded, as `import --max-instances N` would split them, and the pieces
    /// are rebuilt one at a time as residency changes, so a rebuild takes one piece's room
    /// from resident BLASes. The package is unchanged (full builds trace the unsplit TLAS,
    /// which is faster). 0: no split. Default 1000000.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "N", value_parser = parse_split_instances)]
    pub stream_split_instances: Option<u32>,
    /// Streaming: before evicting structures for a TLAS rebuild's room or after a refused
    /// allocation, drain the emptiest memory blocks instead: their BLASes, meshes and textures
    /// are copied into free space other blocks have, and the emptied blocks go back to the
    /// budget (defrag_moves, defrag_freed_bytes per frame in --stats). Off by default: measured on
    /// lavapipe only (default island along shotCam at a third of its full build: 1.86 → 1.57
    /// passes after the first, the same image), not yet on a GPU.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long)]
    pub stream_defrag: bool,
    /// Streaming: where streamed meshes (positions, indices, shading attributes) live. `host`:
    /// host memory the GPU reads over the bus (only hits and BLAS builds read meshes), outside
    /// the VRAM budget, which then holds acceleration structures and textures alone; `device`:
    /// VRAM, counted against the budget. `auto` (default): host on a discrete GPU, device
    /// where host memory is the same memory and counts against the budget (lavapipe,
    /// integrated GPUs). H200, island 0.3 along shotCam, shaded, device → host: a quarter of
    /// the full build 2.18 → 1.00 passes a frame after the first (frames 1.76 → 1.00 s, 2.4 GB
    /// of host memory); a third 1.33 → 0.71 s a frame; half +2–11%. --stats reports the choice
    /// (stream.totals.mesh_memory) and the host bytes (host_mesh_peak_bytes,
    /// resident_host_mesh_bytes per frame); `motu report` the most they take
    /// (streaming.mesh_bytes).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, default_value = "auto")]
    pub stream_mesh_memory: MeshMemoryArg,
    /// Streaming: how evicted BLASes are kept in host memory (`--host-cache` bytes) when they
    /// return. `clone`: the device copies an evicted BLAS into host memory and back (no host
    /// work; the cache directory is written after the frames); `serialize`: every BLAS built
    /// is serialised into host memory and the directory as it is built; `auto` (default):
    /// clone on a discrete GPU, serialize where host memory counts against the budget
    /// (lavapipe, integrated GPUs). --stats: stream.totals.host_cache_mode, cloned_blases,
    /// restored_from_clone, persisted_blases, persist_ms.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, default_value = "auto")]
    pub stream_host_cache: HostCacheArg,
}

#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HostCacheArg {
    #[default]
    Auto,
    Clone,
    Serialize,
}

impl From<HostCacheArg> for motu_gpu::HostCacheMode {
    fn from(a: HostCacheArg) -> Self {
        match a {
            HostCacheArg::Auto => motu_gpu::HostCacheMode::Auto,
            HostCacheArg::Clone => motu_gpu::HostCacheMode::Clone,
            HostCacheArg::Serialize => motu_gpu::HostCacheMode::Serialize,
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MeshMemoryArg {
    #[default]
    Auto,
    Device,
    Host,
}

impl From<MeshMemoryArg> for motu_gpu::MeshMemory {
    fn from(a: MeshMemoryArg) -> Self {
        match a {
            MeshMemoryArg::Auto => motu_gpu::MeshMemory::Auto,
            MeshMemoryArg::Device => motu_gpu::MeshMemory::Device,
            MeshMemoryArg::Host => motu_gpu::MeshMemory::Host,
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StreamTlasArg {
    #[default]
    Auto,
    Update,
    Rebuild,
}

impl From<StreamTlasArg> for motu_gpu::TlasUpdate {
    fn from(a: StreamTlasArg) -> Self {
        match a {
            StreamTlasArg::Auto => motu_gpu::TlasUpdate::Auto,
            StreamTlasArg::Update => motu_gpu::TlasUpdate::Update,
            StreamTlasArg::Rebuild => motu_gpu::TlasUpdate::Rebuild,
        }
    }
}

fn parse_split_instances(s: &str) -> Result<u32, String> {
    match s.parse::<u32>() {
        Ok(1) => {
            Err("1 is too small: a split TLAS holds at least 2 instances (0: no split)".into())
        }
        Ok(n) => Ok(n),
        Err(_) => Err(format!("{s:?} is not a count of instances (0: no split)")),
    }
}

fn parse_pass_marks(s: &str) -> Result<motu_gpu::PassMarks, String> {
    match s {
        "auto" => Ok(motu_gpu::PassMarks::Auto),
        "0" => Ok(motu_gpu::PassMarks::Off),
        _ => s
            .parse::<u32>()
            .map(motu_gpu::PassMarks::Rows)
            .map_err(|_| format!("{s:?} is not a row stride (N ≥ 1, 0: off) or auto")),
    }
}

fn parse_build_ms(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{s:?} is not a positive number of milliseconds")),
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
    /// Samples per pixel of the shaded view (the first, at the pixel centre, gives the AOV).
    #[arg(help_heading = HEADING_SHADING, long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=4096))]
    pub spp: u32,
    /// Ambient-occlusion rays per sample for the sky term (0: unoccluded sky light).
    #[arg(help_heading = HEADING_SHADING, long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(0..=256))]
    pub ao_samples: u32,
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
