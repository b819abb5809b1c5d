//! How a [`StreamingRenderer`](super::StreamingRenderer) works ([`StreamOptions`]) and its enumerated choices.

use motu_alloc::MIB;

use super::persistent::TlasUpdate;

/// How a [`StreamingRenderer`](super::StreamingRenderer) works.
#[derive(Clone, Copy, Debug)]
pub struct StreamOptions {
    /// The VRAM budget (`--vram-budget`): blocks counted against it never exceed it.
    pub budget_bytes: u64,
    /// Cap on `VkDeviceMemory` allocations.
    pub max_allocations: u32,
    /// Build–traverse passes per frame before giving up on the remaining pixels; 0: sized
    /// from the structure count (see [`StreamingRenderer::max_passes`](super::StreamingRenderer::max_passes)).
    pub max_passes: u32,
    /// Scratch bytes one build batch may use (capped at an eighth of the budget).
    pub scratch_budget_bytes: u64,
    /// Host-visible staging ring (mesh data streams through it). Capped at an eighth of the
    /// budget: on unified-memory devices (lavapipe, integrated GPUs) it counts against it.
    pub staging_bytes: u64,
    /// Width in pixels of the guard band traced around the image in pass 1 (every other pixel
    /// of it) to prefetch what the camera is about to see; 0 disables prefetching.
    pub guard_band_px: u32,
    /// Compact acceleration structures after building.
    pub compact: bool,
    /// How triangle BLASes and proxy boxes are built: [`BlasBuild::Small`](motu_vk::BlasBuild::Small) by default (a
    /// fifth smaller on NVIDIA, faster to build; streamed frames are mostly building).
    pub blas_build: motu_vk::BlasBuild,
    /// Also build, in a pass's build step, what fits of the structures pixels will need
    /// after their nearest (fewer passes on a cold frame; off: they are only prefetched after
    /// the frame).
    pub build_open_early: bool,
    /// What a pixel whose structures are not resident yet shows when the frame stops before
    /// it is finished (`--stream-fallback`). Off: such pixels are unfinished (an error for
    /// the CLI); `Coarse`: the bounds of the nearest missing structure, counted as
    /// [`FrameStreamStats::fallback_pixels`].
    pub fallback: StreamFallback,
    /// After a frame, probe the next frame's camera when the caller names it
    /// ([`StreamingRenderer::set_next_camera`](super::StreamingRenderer::set_next_camera)): every ray of every `probe_stride`-th pixel
    /// (each axis) runs against what is resident and marks what it meets, and that is
    /// prefetched (see `probe.rs`); 0: no probe.
    pub probe_stride: u32,
    /// Most probe rounds after a frame (at least one when probing). A probe ray stops at the
    /// first structure that is not resident; once the prefetch built it, the ray may hit in
    /// it and send its shadow and AO rays to structures no round saw yet. So the pixels a
    /// round left open are probed again (only them) and what they need prefetched too, until
    /// none is open, the prefetch built none of what a round needed first, or this many rounds
    /// ran.
    /// Each round after the first costs a TLAS rebuild or update; two rounds took the passes
    /// a third did on the H200 (island 0.3 along shotCam: at half the full build 1.455 →
    /// 1.182 passes after the first at the same frame time; at a quarter 2.636 → 2.364, the
    /// image 13% sooner and the whole frame 19% longer; BENCHMARKS.md, session 22). One by
    /// default since session 40: with the bounce light, the rounds' TLAS rebuilds cost more
    /// than the passes they save (H100, island 0.3 along the default path, with the verifying
    /// rounds off too: at a quarter 1.86 → 2.57 passes after the first but 2.25–2.38 → 1.61–1.64 s
    /// a frame; at an eighth 5.85 → 4.40 s).
    pub probe_rounds: u32,
    /// Verifying probe rounds after those (`--stream-probe-verify`; 0: none): every pixel of
    /// the next camera probed again against what the prefetch left resident, and what its
    /// rays now find missing prefetched, until a round finds nothing missing, its prefetch
    /// builds nothing, or this many ran. The prefetch evicts for room what no probe ray met,
    /// and some of that the next frame's rays pass through on their way to their hits; a
    /// verifying round finds it before the frame does. A round's own prefetch may evict
    /// another such structure, so two are what fewer passes need: one round left the H200's
    /// third at 1.455 passes after the first, two at 1.000. None by default since session 40
    /// (see `probe_rounds`: frames are shorter without them). H200, island 0.3 along shotCam, two rounds
    /// against none (BENCHMARKS.md, session 28): primary visibility at a quarter of the full
    /// build 1.909 → 1.091 passes after the first at about the same frame time; shaded at half
    /// 1.182 → 1.000 (frames +12%), at a third 1.182 → 1.000 (+53%), at a quarter 2.364 →
    /// 2.182 (capacity-bound). Each round costs a probe trace and, when it finds something, a
    /// build step with its TLAS rebuilds.
    pub probe_verify_rounds: u32,
    /// What the rounds after the first do when the first round's prefetch evicted
    /// (`--stream-probe-later`, see [`ProbeLater`]).
    pub probe_later: ProbeLater,
    /// Where a probe round's paths end (`--stream-probe-paths`, see [`ProbePaths`]).
    pub probe_paths: ProbePaths,
    /// Pass marks of the probe (see [`PassMarks`]); [`PassMarks::Auto`] by default.
    pub pass_marks: PassMarks,
    /// Bytes (meshes plus acceleration structures) one frame may build; 0: unbounded. At least
    /// one structure is built per frame, so a frame may overshoot by one; when it is spent the
    /// frame stops (unfinished pixels, or fallback) and later frames go on refining.
    pub frame_build_bytes: u64,
    /// Milliseconds of building one frame may spend; 0: unbounded (same rules).
    pub frame_build_ms: f64,
    /// Milliseconds a whole frame aims at (`--stream-frame-ms`; 0: no clock): its trace, build
    /// step, stale TLAS piece rebuilds and readback share them. A frame builds BLAS groups,
    /// rebuilds stale pieces and probes the next camera only while what is left of them, less
    /// its tail by estimate, covers that work by estimate (`clock.rs`: averages measured on
    /// this renderer's device), and at least one BLAS when it built none yet, so a camera at
    /// rest still converges. Like `frame_build_ms` it makes stale TLAS pieces wait
    /// (`defer_stale_tlases`), and a camera at rest settles without it. What it cannot bound
    /// (a pass's trace, a must rebuild before it) may still overrun it.
    pub frame_ms: f64,
    /// Counts in place of [`Self::frame_ms`]'s time estimates (for tests: counts repeat, times
    /// do not): `Some` puts frames on the clock with these limits, whatever `frame_ms`.
    pub frame_caps: Option<FrameCaps>,
    /// How a frame on the clock probes the next camera, in place of `probe_stride`,
    /// `probe_rounds` and `probe_verify_rounds` (`None`: as those say). By default
    /// [`CLOCKED_PROBE`]: every 4th pixel of each axis, one round, no verifying round, so a
    /// complete frame while flying pays about a sixteenth of a full probe's trace (~100 ms on
    /// an H100 at ¼ of island 0.3: notes/flight.md D6). The CLI sets each of the three from
    /// `--stream-probe`, `--stream-probe-rounds` and `--stream-probe-verify` where given:
    /// explicit settings win.
    pub clocked_probe: Option<ProbeSettings>,
    /// With `frame_build_ms`, TLASes dirty only because BLASes under them were built are
    /// traced as they are and rebuilt while the frame's budget holds (`piece_order.rs`);
    /// `false`: every dirty TLAS is rebuilt at each build step's end, as without a budget
    /// (for comparisons). Default `true`; no effect without `frame_build_ms`.
    pub defer_stale_tlases: bool,
    /// Whether TLASes are persistent and updated as residency changes, or rebuilt over their
    /// resident instances (`--stream-tlas`; see `persistent.rs`).
    pub tlas_update: TlasUpdate,
    /// Before evicting for a TLAS rebuild's room or after a refused allocation, drain the
    /// emptiest memory blocks instead: their streamed BLASes, meshes and textures are copied
    /// into free space other blocks have and the emptied blocks return their bytes to the
    /// budget (`defrag.rs`; `defrag_*` per frame in `--stats`). Off by default: measured on
    /// lavapipe only (the default island along shotCam at a third of its full build, 64×36:
    /// 1.857 → 1.571 passes after the first, evictions on refusal 3.6 → 0 a frame; a quarter
    /// unchanged; every image equal to the full build's), not yet on a GPU. The prefetch after
    /// a frame drains on a refused allocation either way (`residency.rs`, `drains_on_refusal`).
    pub defrag: bool,
    /// The prefetch after a frame keeps what the frame's passes saw, beside what the probe of
    /// the next camera met, while the frame's working set fits its room next to its largest
    /// TLAS rebuild transient and the free space inside blocks: it prefetches into the rest
    /// and skips what does not fit, and the next frame's passes evict, least recently seen
    /// first, what that frame does not use (`--stream-prefetch-keeps-frame`). Off (the
    /// default), the prefetch keeps only what the probe met and may evict, for its room, what
    /// the frame used (one-sample bounce rays meet a different fringe of it each frame, which
    /// no probe sees; rays pass through structures without a hit). Opt-in until a GPU
    /// measures it (H100, island 0.3 at a quarter, default: frame 7 evicted 855 MB and
    /// brought back 662 MB while its working set fit). Lavapipe, the default island along
    /// shotCam at 64×36, frames after the first, off → on: a third of the 64×36 report's full
    /// build 1.000 passes either way, 186 → 188 evicted, 65 → 73 built back within their
    /// frame; a third of the default-size report's 1.143 → 1.000 passes, 139 → 131 evicted,
    /// 11 → 12 built back; a quarter (where the working set fits only now and then) 2.143
    /// passes either way, 479 → 348 evicted, 252 → 173 built back, 157 → 126 MB built.
    pub prefetch_keeps_frame: bool,
    /// Evictions take the least often used of the last 16 frames first, least recently seen
    /// first among equals, so that the part of the bounce rays' fringe met every few frames
    /// stays (`--stream-victims-by-frequency`; `residency.rs` `lru_victims` has the counts).
    /// Off (the default): least recently seen first, however often used.
    pub victims_by_frequency: bool,
    /// Where streamed meshes (positions, indices, primitive maps, shading attributes) live
    /// (`--stream-mesh-memory`; see [`MeshMemory`]).
    pub mesh_memory: MeshMemory,
    /// How evicted BLASes are kept in host memory when a structure cache is attached
    /// (`--stream-host-cache`; see [`HostCacheMode`](super::HostCacheMode)).
    pub host_cache_mode: super::HostCacheMode,
    /// Which built BLASes the serialised host tier stores (`--stream-host-cache-policy`; see
    /// [`HostStorePolicy`](super::HostStorePolicy)).
    pub host_store_policy: super::HostStorePolicy,
    /// Rates the restore and store rules decide from instead of measuring them
    /// (`--stream-rates`; `None`, the default: measured; see `restore_rule.rs`).
    pub fixed_rates: Option<motu_ascache::DeviceRates>,
    /// Where a streamed TLAS rebuild's instance records come from (`--stream-tlas-records`;
    /// see [`TlasRecordsMode`]).
    pub tlas_records: TlasRecordsMode,
    /// What rebuilt (not persistent) streamed TLASes are built for (`--stream-tlas-build`):
    /// fast trace (default) or fast build; their size queries use the same flags.
    pub tlas_build: motu_vk::TlasBuild,
    /// Compact rebuilt TLASes and their proxy and marks BLASes (`--stream-tlas-compact`): a
    /// compacted-size query, a second allocation and a copy per rebuild, for structures that
    /// live only until the next rebuild. Off (default: on an H100, island 0.3's frames 9–18%
    /// shorter, `tlas_gpu_ms` halved, for 26–30 MB more resident, BENCHMARKS.md session 41):
    /// built without compaction, larger by what `tlas_compact_saved_bytes` reports with it on.
    /// Triangle BLASes follow `compact`.
    pub tlas_compact: bool,
    /// Spare storage a rebuilt TLAS piece's fresh structure gets, as a fraction of its size
    /// (`--stream-tlas-headroom`; default 1/16, at most 1/9, 0: exact): a piece that grows by
    /// less is rebuilt into the same storage next time instead of a new allocation. Taken only
    /// where the budget has room for it, so it never refuses a rebuild.
    pub tlas_headroom: f64,
    /// Progressive frames at one camera left incomplete before the next ones there take
    /// passes until complete without the frame build budget (`render_progressive`; 0: never,
    /// for tests of the refinement itself). One pass a frame can churn at rest, each build
    /// step evicting what the next frame's pass needs: ¼ of the default island at 64×36 never
    /// completed in 8 still frames, flickering between 11 and 592 fallback pixels.
    pub settle_after_still_frames: u32,
    /// Counting mode (`MOTU_PROXY_TESTS=count`): each pass counts its proxy work by ray kind
    /// and outcome (`PassStats::proxy_calls_*`, `stream/proxy_count.rs`). For diagnosis and
    /// tests: its counters are atomics per ray and per proxy shader call, and its buffer's
    /// room shifts residency a little against a run without it.
    pub count_proxy_calls: bool,
    /// The pipeline backend's proxy intersection shader reads the current walk's nearest open
    /// entry so far (`STREAM_OPEN_BOUND`, `shaders/pipeline/open_bound.glsl`): proxy boxes
    /// behind it test no member, where before that shader, which cannot read the payload,
    /// tested the members of every box in front of the committed triangle (for an open ray,
    /// every box to the walk's far end). Images, walks, requests and residency are unchanged;
    /// only member tests go. `false` for comparisons (`MOTU_PROXY_TESTS=unbounded`).
    pub open_bound: bool,
}

/// Whether `MOTU_PROXY_TESTS` (comma-separated words) has `word`.
pub(super) fn proxy_tests_env_has(word: &str) -> bool {
    std::env::var("MOTU_PROXY_TESTS")
        .unwrap_or_default()
        .split(',')
        .any(|w| w.trim() == word)
}

/// What a frame on the clock may do, as counts ([`StreamOptions::frame_caps`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameCaps {
    /// BLASes a frame builds (at least one when it built none yet).
    pub blases: u32,
    /// Stale TLAS pieces a frame rebuilds (at least one group in a frame that built nothing,
    /// or whose pixels wait on stale pieces and rebuilt none yet).
    pub pieces: u32,
    /// Whether a complete frame probes the next camera.
    pub probe: bool,
}

/// How the probe of the next camera runs ([`StreamOptions::clocked_probe`]): the stride of
/// its pixels on each axis (0: no probe), its most rounds, its most verifying rounds (as
/// `probe_stride`, `probe_rounds`, `probe_verify_rounds`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProbeSettings {
    pub stride: u32,
    pub rounds: u32,
    pub verify_rounds: u32,
}

/// [`StreamOptions::clocked_probe`]'s default: a sixteenth of the pixels, one round, none
/// verifying. The next frame's first pass opens what the skipped pixels' rays need (on the
/// counted fallback while flying), which costs less than probing it when a frame has ~50 ms.
pub const CLOCKED_PROBE: ProbeSettings = ProbeSettings {
    stride: 4,
    rounds: 1,
    verify_rounds: 0,
};

/// [`StreamOptions::tlas_headroom`]'s default: pieces at a quarter of island 0.3 grow by a few
/// percent between rebuilds (a frame's new BLASes add instances to nearly every piece).
pub const DEFAULT_TLAS_HEADROOM: f64 = 1.0 / 16.0;

/// The most [`StreamOptions::tlas_headroom`] may be: with more, a piece rebuilt at its old
/// size would leave more than an eighth of its storage spare, which the rebuild releases
/// (`tlas_build/storage.rs`).
pub const MAX_TLAS_HEADROOM: f64 = 1.0 / 9.0;

/// Where a rebuilt streamed TLAS's instance records come from ([`StreamOptions::tlas_records`],
/// `--stream-tlas-records`; `tlas_compact.rs`). A split root's pieces are rebuilt several times
/// a frame as the probe's prefetches bring BLASes in (island 0.3 at a quarter on an H100: 43
/// rebuilds writing 29.8M records, ~1.1 s of a 2.5 s frame), and the host path's cost is per
/// record: encoding into the staging ring, the copy, the build.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TlasRecordsMode {
    /// Every instance's record is kept on the GPU (encoded once, the BLAS id where the address
    /// goes) and a compute pass writes a rebuild's records from it with the resident BLASes'
    /// addresses; the host writes only the proxy and marks records. A piece whose kept
    /// records do not fit the budget is written from the host (`tlas_records_host_fallbacks`
    /// per frame). The kept records yield to structures (released before any is evicted); on
    /// lavapipe (session 37) 7 of 8 paths took `Host`'s passes frame by frame, but a split
    /// root's path at a quarter took one pass more in one of 5 frames, so it stays opt-in.
    Gpu,
    /// The host encodes every resident instance's record into the staging ring per rebuild.
    #[default]
    Host,
}

impl TlasRecordsMode {
    /// The name `--stats` reports (`stream.totals.tlas_records_mode`).
    pub fn name(self) -> &'static str {
        match self {
            TlasRecordsMode::Gpu => "gpu",
            TlasRecordsMode::Host => "host",
        }
    }
}

/// Where the streaming renderer keeps its meshes ([`StreamOptions::mesh_memory`]). After a
/// BLAS is built only the hits on it read its meshes (the closest-hit shading: a few
/// vertices a pixel) and its rebuilds read them once, so on a discrete GPU they can live in
/// host memory the GPU reads over the bus, as production GPU renderers keep out-of-core
/// geometry, and the VRAM budget holds acceleration structures and textures alone.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum MeshMemory {
    /// [`MeshMemory::Host`] where host-visible memory is not counted against the VRAM budget
    /// (a discrete GPU), else [`MeshMemory::Device`] (unified memory: lavapipe, integrated
    /// GPUs, where both are the same memory).
    #[default]
    Auto,
    /// Device-local memory, counted against the budget.
    Device,
    /// Host-visible memory, written in place; counted against the budget only where
    /// host-visible memory is (unified memory).
    Host,
}

/// Pass marks of the probe ([`StreamOptions::pass_marks`], `--stream-probe-pass-rows`): the
/// pixels of every N-th row of the next camera also walk, when their rays' hits are final, the
/// boxes of the resident BLASes in front of those hits (the mark walk, over the marks BLASes),
/// and the BLASes they pass without hitting (the hardware reports no such pass) become the
/// most recently used after what the probe met: the prefetch evicts them after everything else
/// it may evict and never skips a build to keep them (see `probe.rs`). On the H200 (island
/// 0.3, shotCam, 640×360, BENCHMARKS.md session 25): at a third of the full build every 2nd
/// row took passes after the first 1.727 → 1.182 at 784 ms a frame (775–856 ms without, in
/// other calls); at half 1.182 → 1.000 passes but frames 264 → 350 ms (the walk's cost; every
/// 4th row: 318 ms); at a quarter no change (what the probe met does not fit either).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum PassMarks {
    /// No pass marks.
    Off,
    /// Every N-th row (N ≥ 1) of every probe.
    Rows(u32),
    /// Every [`AUTO_PASS_ROWS`]-th row of the probes within [`AUTO_PASS_FRAMES`] frames of one
    /// whose build steps evicted for room while its prefetch skipped nothing (a window, since
    /// marking removes the evictions it reads: a frame at a time it marked every other
    /// probe and missed more than without). The marks only reorder what the prefetch
    /// evicts, so they help when it evicts and stops before running out of what it may evict
    /// (a third of island 0.3's build), and are not worth their walk when it evicts nothing
    /// for room (half: the misses there follow refusals) or everything (a quarter: it skips
    /// builds). The default: on the H200 (island 0.3, shotCam, 640×360, 12 frames,
    /// BENCHMARKS.md session 26) it marked from the third frame on at a third of the full
    /// build, 1.727 → 1.182 passes after the first at 811–835 ms a frame against 846–892 ms
    /// off (alternated), and never at half or a quarter (counts identical to off).
    #[default]
    Auto,
}

/// The row stride of [`PassMarks::Auto`] when it marks (every 2nd row measured best at a
/// third of island 0.3's build: BENCHMARKS.md session 25).
pub const AUTO_PASS_ROWS: u32 = 2;

/// How many frames [`PassMarks::Auto`] keeps marking after its condition last held.
pub const AUTO_PASS_FRAMES: u64 = 4;

impl PassMarks {
    /// The row stride a probe marks with (0: none), `wanted` being [`PassMarks::Auto`]'s
    /// reading of the frames before ([`PassMarks::auto_window`]).
    pub fn rows(self, wanted: bool) -> u32 {
        match self {
            Self::Off => 0,
            Self::Rows(n) => n,
            Self::Auto if wanted => AUTO_PASS_ROWS,
            Self::Auto => 0,
        }
    }

    /// Whether [`PassMarks::Auto`] marks the next probe after a frame that evicted
    /// `build_room_evictions` structures to make room for builds and whose prefetch left
    /// `prefetch_skipped` structures unbuilt.
    pub fn auto_wanted(build_room_evictions: u32, prefetch_skipped: u32) -> bool {
        build_room_evictions > 0 && prefetch_skipped == 0
    }

    /// Whether [`PassMarks::Auto`] marks the probe after frame `frame`, its condition having
    /// last held after frame `held` (0: never).
    pub fn auto_window(frame: u64, held: u64) -> bool {
        held > 0 && frame.saturating_sub(held) <= AUTO_PASS_FRAMES
    }
}

/// What the probe rounds after the first do ([`StreamOptions::probe_later`],
/// `--stream-probe-later`) when the first round's prefetch evicted, so that verifying rounds
/// (every pixel again) follow whatever the open-pixel rounds do. Each round that finds
/// something costs a build step, and each step rebuilds every TLAS piece holding an instance
/// of what it built or evicted: with a split root and popular BLASes, every piece.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ProbeLater {
    /// The open-pixel rounds ([`StreamOptions::probe_rounds`]), then the verifying rounds.
    #[default]
    Open,
    /// Straight to the verifying rounds: they probe every pixel, the open ones among them, so
    /// the open-pixel rounds' build steps (and their TLAS rebuilds) are saved; the verifying
    /// rounds may run up to `probe_rounds - 1` more to reach as deep (each still stops when
    /// its prefetch builds nothing). Without an eviction the open-pixel rounds run as with
    /// `Open` (no verifying round follows them once they settle).
    Verify,
}

/// Where a probe ray of a closest-hit link (the primary ray, a bounce ray) goes on when a
/// structure that is not resident lies in front of its resident hit
/// ([`StreamOptions::probe_paths`], `--stream-probe-paths`). Either way the structure is
/// requested and its pixel listed for the next round, which goes on from the structure's own
/// hits once the prefetch built it; the image never depends on it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ProbePaths {
    /// The path goes on as if the resident hit were final: that hit's secondary rays and its
    /// bounce leave from a point the frame's rays may never leave from, and what they meet
    /// is prefetched too.
    #[default]
    Through,
    /// The pixel's path ends there (`STREAM_PROBE_STOP`): a round prefetches only what paths
    /// that are right so far meet, and the later rounds go one link deeper each.
    Stop,
}

/// See [`StreamOptions::fallback`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum StreamFallback {
    /// Unfinished pixels stay unfinished (misses, magenta).
    #[default]
    Off,
    /// A not-yet-resident structure is shown by its bounds (a box hit at the box's entry
    /// distance, LOD `AOV_LOD_FALLBACK`, a hatched colour).
    Coarse,
}

impl Default for StreamOptions {
    fn default() -> Self {
        Self {
            budget_bytes: 512 * MIB,
            max_allocations: 4096,
            max_passes: 0,
            // Both are capped by the budget (scratch an eighth, staging a 32nd), so these only
            // matter for budgets above 256 MiB, where fewer, larger build batches and ring
            // flushes cut the per-step cost (a ring flush and a batch are a fenced submission
            // each).
            scratch_budget_bytes: 256 * MIB,
            staging_bytes: 64 * MIB,
            guard_band_px: 8,
            compact: true,
            blas_build: motu_vk::BlasBuild::Small,
            build_open_early: true,
            probe_stride: 1,
            probe_rounds: 1,
            probe_verify_rounds: 0,
            probe_paths: ProbePaths::Through,
            probe_later: ProbeLater::Open,
            pass_marks: PassMarks::Auto,
            fallback: StreamFallback::Off,
            frame_build_bytes: 0,
            frame_build_ms: 0.0,
            frame_ms: 0.0,
            frame_caps: None,
            clocked_probe: Some(CLOCKED_PROBE),
            defer_stale_tlases: true,
            tlas_update: TlasUpdate::Auto,
            defrag: false,
            prefetch_keeps_frame: false,
            victims_by_frequency: false,
            mesh_memory: MeshMemory::Auto,
            host_cache_mode: super::HostCacheMode::Auto,
            host_store_policy: super::HostStorePolicy::Measured,
            fixed_rates: None,
            tlas_records: TlasRecordsMode::Host,
            tlas_build: motu_vk::TlasBuild::FastTrace,
            tlas_compact: false,
            tlas_headroom: DEFAULT_TLAS_HEADROOM,
            settle_after_still_frames: 2,
            count_proxy_calls: proxy_tests_env_has("count"),
            open_bound: !proxy_tests_env_has("unbounded"),
        }
    }
}
