//! `render --stream` and `view`: the streaming options (the fallback, the acceleration-structure
//! cache, bounded work per frame, the expert knobs).

use crate::size::parse_size;
use clap::{Args, ValueEnum};
use std::path::PathBuf;

use super::{HEADING_STREAMING, HEADING_STREAMING_EXPERT};

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
    /// Streaming: milliseconds a whole frame aims at: its trace, building and readback share
    /// them. A frame builds, rebuilds waiting TLAS pieces and probes the next camera only
    /// while what is left covers that work by estimate (measured on this device as frames
    /// go), and builds at least one structure when it built none yet, so a camera at rest
    /// still converges; what is not built shows the fallback. While the camera moves it
    /// evicts nothing (it builds into free room; flying_no_room per frame). Default: none.
    ///
    /// Its probe takes every 4th pixel of each axis in one round with no verifying round,
    /// except for the probe settings given (--stream-probe, --stream-probe-rounds,
    /// --stream-probe-verify).
    #[arg(help_heading = HEADING_STREAMING, long, value_parser = parse_build_ms, value_name = "MS")]
    pub stream_frame_ms: Option<f64>,
    /// Streaming: after each frame whose next camera is known (a camera path, a flight; the
    /// viewer extrapolates it), trace every ray of every STRIDE-th pixel of the next camera
    /// against what is resident and prefetch what they meet, so the next frame mostly
    /// completes in one pass; its rays and ms are reported (probe_rays, probe_ms). 0: no
    /// probe. Default 1 (every pixel).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "STRIDE")]
    pub stream_probe: Option<u32>,
    /// Streaming: probe rounds after a frame, at most (default 1). A probe ray stops at the
    /// first structure that is not resident; once the prefetch built it, the ray may hit in
    /// it and its shadow and AO rays need structures no probe saw. Each later round probes
    /// only the pixels the round before left open and prefetches what they need, at the cost
    /// of a TLAS rebuild or update (probe_rounds per frame). 2 with --stream-probe-verify 2 for
    /// fewer passes; the default for shorter frames (H100, island 0.3 at a quarter: 2.57 passes
    /// after the first and 1.6 s a frame against 1.86 and 2.3 s with 2 and 2).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub stream_probe_rounds: Option<u32>,
    /// Streaming: verifying probe rounds after those, at most (default 0: none). The
    /// prefetch evicts for room what no probe ray met, and the next frame's rays may pass
    /// through some of it on their way to their hits; a verifying round probes every pixel
    /// again against what the prefetch left resident and prefetches what is now missing, so
    /// the next frame completes in one pass where its structures fit (H200, island 0.3 at a
    /// quarter of its full build, primary visibility: 1.909 → 1.091 passes after the first at
    /// about the same frame time; shaded at half 1.182 → 1.000, frames +12%; at a third
    /// 1.182 → 1.000, frames +53%). Each round costs a probe trace and, when it finds
    /// something, a build step (probe_verify_rounds per frame).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "N")]
    pub stream_probe_verify: Option<u32>,
    /// Streaming: what the probe rounds after the first do when the first round's prefetch
    /// evicted (verifying rounds then follow). `open` (default): probe the pixels it left open
    /// (--stream-probe-rounds), then the verifying rounds. `verify`: straight to the verifying
    /// rounds, which probe every pixel, the open ones among them, up to --stream-probe-rounds
    /// minus one more of them: a build step, and its TLAS rebuilds, fewer per frame where
    /// both kinds would have found something (probe_later_merged per frame).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, value_name = "WHAT")]
    pub stream_probe_later: Option<ProbeLaterArg>,
    /// Streaming: where a probe ray of the primary or a bounce ray goes when a structure that
    /// is not resident lies in front of its resident hit (it is requested either way).
    /// `through` (default): on from that hit, as if it were final. `stop`: the pixel's path
    /// ends there and the next probe round (--stream-probe-rounds) goes on from the
    /// structure's own hits once it is built, so no round prefetches what rays from a point
    /// the frame never reaches meet.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, value_name = "WHERE")]
    pub stream_probe_paths: Option<ProbePathsArg>,
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
    /// which is faster). 0: no split. Default: the cap the package was imported with
    /// (`import --stream-split-instances`, 1000000 unless given), whose stored split, proxy
    /// boxes and clusters then need not be made again.
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
    /// Streaming: the prefetch after a frame also keeps what the frame's own passes used
    /// while the frame's working set fits its room beside the TLAS rebuilds' transient
    /// (prefetch_kept_frame per frame in --stats), and prefetches for the next camera into the
    /// rest; the next frame's passes evict what it does not use. Off by default: the prefetch
    /// keeps only what the probe of the next camera met. returned_in_frame per frame in
    /// --stats counts what a frame evicted and built back. Measured on lavapipe only.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long)]
    pub stream_prefetch_keeps_frame: bool,
    /// Streaming: evictions take the structures used in the fewest of the last 16 frames
    /// first, least recently seen first among equals, so that what bounce rays meet every few
    /// frames stays (rebuilt_blases, restored_blases per frame in --stats count what comes
    /// back). Off by default: least recently seen first. Lavapipe (island 0.002, a third of
    /// its need): structures built back 443 → 239; H100 (island 0.3, a quarter, 8 frames):
    /// slower, 1,147 against 1,068 ms a frame, 2.86 against 2.57 passes (BENCHMARKS.md,
    /// session 48).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long)]
    pub stream_victims_by_frequency: bool,
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
    /// Streaming: how built BLASes are kept in host memory (`--host-cache` bytes) for their
    /// return. `serialize`: every BLAS built is serialised into host memory and the cache
    /// directory as it is built; `clone`: the device copies an evicted BLAS into host memory
    /// and back (no host work; the directory is written after the frames); `auto` (default):
    /// serialised, measured faster on an H100 (island 0.63 at 8 GiB, cold: 25.4 s to the PNG
    /// against 37.2 s; warm 19.7 against 25.0 s), but when a BLAS is evicted, and those
    /// resident after the last frame after the image is written (`serialize` where host
    /// memory counts against the budget). --stats: stream.totals.host_cache_mode, cloned_blases,
    /// restored_from_clone, persisted_blases, persisted_bytes, persist_ms.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, default_value = "auto")]
    pub stream_host_cache: HostCacheArg,
    /// Streaming: which built BLASes the serialised host tier (`--host-cache`) stores for
    /// their return. `measured` (default): a BLAS is stored only where its expected restores
    /// save more than its store costs, by this process's own rates (builds, restores and
    /// stores timed per batch, fixed cost per BLAS plus a rate; returns counted per BLAS
    /// built), starting from the H100's rates (restores ~2.7 GB/s, no faster than rebuilds at
    /// ~2.9 GB/s: nothing stored) until each has 3 batches; on lavapipe restores are far
    /// cheaper than builds and everything pays. A cache directory (`--as-cache`) takes a BLAS
    /// where the next process would restore it faster than it builds it, and a cached BLAS is
    /// restored only where that beats building it, by this device's rates (recorded in the
    /// directory for the next process; unknown rates: restore and write). `always`: every BLAS
    /// built is stored and written, every cached one restored (the behaviour before). Same
    /// images either way. --stats: per frame host_cache_skipped_stores,
    /// host_cache_skipped_store_bytes, disk_restore_declined, disk_store_skipped;
    /// stream.totals.store_policy (the estimates, rates_file), store_gb_per_s.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, default_value = "measured")]
    pub stream_host_cache_policy: HostCachePolicyArg,
    /// Streaming: the rates the restore and store decisions above are made from. `measured`
    /// (default): this process's own, else those the cache directory recorded for this
    /// device, so what is restored or built, stored and written may differ between two runs
    /// of the same command. A list `OP=GB/S` or `OP=GB/S+MS` (OP: build, restore, disk_read,
    /// store; GB of structure a second, `inf` for none, plus a fixed milliseconds per
    /// structure), e.g. `build=0.5,restore=4+0.1,disk_read=8`: decisions from these alone,
    /// the same on every run and machine (tests, comparisons); the directory's rates file is
    /// neither read nor written (rates_file `fixed`). An operation not named is unknown
    /// (cached structures restored and written; the host tier's store rule takes the H100's
    /// rates); `unmeasured`: every one unknown.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "RATES", value_parser = parse_stream_rates, default_value = "measured")]
    pub stream_rates: StreamRatesArg,
    /// Streaming: where a rebuilt TLAS's instance records come from. `gpu` (opt-in): every
    /// instance's record is kept on the GPU (encoded once, at the TLAS's second rebuild) and a
    /// compute pass writes a rebuild's records from it with the resident BLASes' addresses; the
    /// host writes only the proxy and marks records. The kept records take free budget only (64
    /// bytes an instance) and are released before any structure is evicted, so the passes are
    /// mostly `host`'s; a TLAS without them is written from the host. `host` (default): the
    /// host encodes every resident instance's record per rebuild and uploads it (H100, island
    /// 0.3 at a quarter, before records yielded: `gpu` raised TLAS time 217 → 398 ms a frame).
    /// Both give the same image. --stats: stream.totals.tlas_records_mode,
    /// tlas_records_released, per frame tlas_instances_written (the host's),
    /// tlas_records_compacted, tlas_compact_ms, tlas_records_kept_bytes,
    /// tlas_records_host_fallbacks, tlas_records_released.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, default_value = "host")]
    pub stream_tlas_records: TlasRecordsArg,
    /// Streaming: what rebuilt TLASes (those `--stream-tlas` does not update in place) are
    /// built for. A streamed TLAS is rebuilt whenever its resident instances change (island
    /// 0.3 at a quarter on an H100: 40 rebuilds and 27.5M records a frame, ~1.1 s of a 2.3 s
    /// frame) and traced by a frame's few passes. `fast-trace` (default): the full build's
    /// choice; `fast-build`: the driver builds faster, traces may be slower. Same image either
    /// way. --stats: stream.totals.tlas_build, per frame tlas_gpu_ms.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, default_value = "fast-trace")]
    pub stream_tlas_build: TlasBuildArg,
    /// Streaming: compact rebuilt TLASes and their proxy and marks BLASes (`on`) or build them
    /// without compaction (`off`, default: on an H100 frames 9–18% shorter for ~30 MB more
    /// resident): no compacted-size query, second allocation and
    /// copy per rebuild, for structures that live until the next rebuild, at the cost of their
    /// uncompacted size in VRAM. Same image either way. --stats: stream.totals.tlas_compact,
    /// per frame tlas_compactions, tlas_compact_saved_bytes (summed over the rebuilds) and
    /// tlas_compact_resident_saved_bytes (the room `off` would take more).
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_enum, default_value = "off")]
    pub stream_tlas_compact: OnOffArg,
    /// Streaming: spare storage a rebuilt TLAS piece's new structure gets, as a fraction of
    /// its size (default 0.0625, at most 1/9; 0: exact size), taken only where the budget has
    /// room: a piece that grows by less between rebuilds is rebuilt into the same storage
    /// instead of a new allocation (island 0.3 at a quarter on an H100: 100 of 117 new
    /// allocations were grown pieces). Same image either way. --stats: per frame
    /// tlas_storage_reused, tlas_storage_allocated, tlas_storage_grew.
    #[arg(help_heading = HEADING_STREAMING_EXPERT, hide_short_help = true, long, value_name = "FRACTION", value_parser = parse_tlas_headroom)]
    pub stream_tlas_headroom: Option<f64>,
}

#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OnOffArg {
    #[default]
    On,
    Off,
}

#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TlasBuildArg {
    #[default]
    FastTrace,
    FastBuild,
}

impl From<TlasBuildArg> for motu_gpu::TlasBuild {
    fn from(a: TlasBuildArg) -> Self {
        match a {
            TlasBuildArg::FastTrace => motu_gpu::TlasBuild::FastTrace,
            TlasBuildArg::FastBuild => motu_gpu::TlasBuild::FastBuild,
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TlasRecordsArg {
    Gpu,
    #[default]
    Host,
}

impl From<TlasRecordsArg> for motu_gpu::TlasRecordsMode {
    fn from(a: TlasRecordsArg) -> Self {
        match a {
            TlasRecordsArg::Gpu => motu_gpu::TlasRecordsMode::Gpu,
            TlasRecordsArg::Host => motu_gpu::TlasRecordsMode::Host,
        }
    }
}

#[derive(ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum HostCachePolicyArg {
    #[default]
    Measured,
    Always,
}

impl From<HostCachePolicyArg> for motu_gpu::HostStorePolicy {
    fn from(a: HostCachePolicyArg) -> Self {
        match a {
            HostCachePolicyArg::Measured => motu_gpu::HostStorePolicy::Measured,
            HostCachePolicyArg::Always => motu_gpu::HostStorePolicy::Always,
        }
    }
}

/// `--stream-rates`: fixed rates (`None`: measured, the default).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StreamRatesArg(pub Option<motu_gpu::DeviceRates>);

fn parse_stream_rates(s: &str) -> Result<StreamRatesArg, String> {
    match s {
        "measured" => Ok(StreamRatesArg(None)),
        "unmeasured" => Ok(StreamRatesArg(Some(motu_gpu::DeviceRates::default()))),
        _ => motu_gpu::parse_rates(s)
            .map(|r| StreamRatesArg(Some(r)))
            .map_err(|e| format!("{e} (or measured, unmeasured)")),
    }
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

/// `--stream-probe-later`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProbeLaterArg {
    Open,
    Verify,
}

impl From<ProbeLaterArg> for motu_gpu::ProbeLater {
    fn from(a: ProbeLaterArg) -> Self {
        match a {
            ProbeLaterArg::Open => motu_gpu::ProbeLater::Open,
            ProbeLaterArg::Verify => motu_gpu::ProbeLater::Verify,
        }
    }
}

/// `--stream-probe-paths`.
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ProbePathsArg {
    Through,
    Stop,
}

impl From<ProbePathsArg> for motu_gpu::ProbePaths {
    fn from(a: ProbePathsArg) -> Self {
        match a {
            ProbePathsArg::Through => motu_gpu::ProbePaths::Through,
            ProbePathsArg::Stop => motu_gpu::ProbePaths::Stop,
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

/// `--stream-split-instances` of `motu render`, `view`, `bench` and `import`.
pub(crate) fn parse_split_instances(s: &str) -> Result<u32, String> {
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

fn parse_tlas_headroom(s: &str) -> Result<f64, String> {
    let most = motu_gpu::MAX_TLAS_HEADROOM;
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && (0.0..=most).contains(&v) => Ok(v),
        _ => Err(format!(
            "{s:?} is not a fraction from 0 to {most:.4} (more would leave a piece rebuilt at \
             its old size over an eighth of its storage spare)"
        )),
    }
}

fn parse_build_ms(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("{s:?} is not a positive number of milliseconds")),
    }
}
