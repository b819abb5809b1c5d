//! Out-of-core rendering: lazy, visibility-driven acceleration-structure builds and eviction
//! under a VRAM budget (Lee & Liktor 2020, "multi-pass lazy build", adapted to motu's
//! multi-level hierarchy).
//!
//! # Empty instances
//! Every triangle BLAS starts non-resident. PI (AABB) BLASes, every TLAS and the node tables
//! form the resident *skeleton* (TLASes are the instance skeleton: never evicted, so every ray
//! reaches every BLAS box and only BLASes stream). In the GPU's copy of the tables each TLAS
//! with triangle instances gets one extra instance: a *proxy* AABB BLAS with one box per
//! non-resident *cluster* (up to 16 neighbouring instances of one BLAS, grouped by the
//! compiler's SAH over instance bounds; the union of their BLAS bounds in TLAS space, padded),
//! whose PI record has kind `PI_EMPTY_BLAS` and names the BLAS. A ray that enters such a box
//! tests the cluster's member instances (their BLAS bounds under their own transforms, read
//! from the resident instance table through a member table; the PI record's unused transform
//! words carry the range): only a ray that enters a member's box, in front of its best hit,
//! opens the BLAS (at that member's entry), so rays passing between the instances of a
//! cluster demand nothing (guard probes alike), and only if it also enters one of the boxes
//! around the BLAS's triangles (`proxy_boxes.rs`), so rays through a BLAS's empty space do not
//! either. A built TLAS holds only the
//! instances of resident BLASes (and PI instances) plus the proxy: each carries its index in
//! the TLAS's record range as its custom index, which the shaders read, so records never move
//! and the resident skeleton does not grow with the instance count (only the instance table
//! does, 64 bytes an instance). A *persistent* TLAS (`persistent.rs`, `--stream-tlas`: large
//! TLASes when the budget has room) instead holds every instance, the non-resident ones on
//! placeholders no ray meets, and is updated in place rather than rebuilt.
//!
//! # Carried hits (both backends, `traverse.glsl`, `render_pixel.glsl`)
//! Each pixel keeps its state across the passes of a frame (`Carry`, 128 bytes):
//! the current sample's primary best hit so far, *resolved* (source mesh, primitive, LOD,
//! material, geometric and shading normals, textured base colour) while its BLAS was resident,
//! sample 0's AOV record, the colour summed so far, and which ray is open (the primary, or the
//! n-th secondary ray: lights' shadow rays, then AO rays) since which pass. A pass
//! walks what is resident now against that best hit (it only culls with the carried t, never
//! with an empty instance's box). A ray that was traced in every pass since it started has
//! walked every BLAS resident in any of those passes, so a non-resident BLAS is *open* for it
//! only when it was not resident in any pass since the ray started (`walked[b]` < the ray's
//! start stamp) and its box lies in front of the best hit; the nearest open one is the pixel's
//! request (needed, counted), the rest are marked open by a second walk of the ray over PI and
//! proxy boxes only, up to the pass's hit (the *mark walk*, `traverse.glsl`: marked during the
//! first walk, against the closest hit *so far* in the hardware's order, most lay behind the
//! hit and were built ahead for nothing). The closest hit over BLASes processed
//! in different passes is the minimum over the passes, so the image equals the full build's,
//! and a pixel never needs two BLASes resident at once: anything may be evicted between
//! passes. Secondary rays start when their sample's primary hit is final, in windows of 8
//! traced together each pass (the streamed shaders' `MOTU_STREAMED`), each ray stopping at its
//! first occluder; the colour is the full build's (docs/shading.md). While the primary ray is
//! open with a hit so far, its windows are traced *ahead* from that hit in each pass after it
//! (dropped if a closer hit comes): a wide view whose rays need more than the room otherwise
//! took one more pass for shadow and AO rays whose structures the primary's build evicted.
//!
//! # Build–traverse loop ([`StreamingRenderer::render_frame`])
//! Pass 1 traces every pixel plus a sparse *guard band* of primary rays around the image.
//! After each pass the host reads the stamps, the request counts and the open-pixel list and
//! builds the needed structures most requested first (meshes stream through the staging ring;
//! BLASes build in groups that halve when the budget refuses them; single builds evict least
//! recently visible BLASes for room), then what fits of the open ones; each TLAS whose
//! instance set changed is rebuilt with its proxy (a persistent one, built over every
//! instance, is updated in place instead: `persistent.rs`), and only open pixels are traced
//! again.
//! Each pass builds at least one needed BLAS, so a budget at or above the floor
//! ([`streaming_floor`]) completes; the pass cap ([`StreamingRenderer::max_passes`]) is a
//! safety net sized from the BLAS count, and a frame that reaches it reports its unfinished
//! pixels ([`FrameStreamStats::complete`], `incomplete_pixels`; the CLI exits non-zero).
//! Structures the guard band (or pass 1's open marks) saw are built after the frame as a
//! prefetch, evicting only what this frame did not see, so later frames of a camera path
//! mostly need one pass. When the caller names the next frame's camera
//! ([`StreamingRenderer::set_next_camera`]), a probe pass of it (`probe.rs`) runs every ray of
//! its pixels, secondary rays included, against what is resident first: what it meets is built
//! ahead of the guard band's, and only what it saw is kept (what its rays pass through
//! included: each TLAS's *marks* BLAS, seen only by probe rays, holds its resident clusters'
//! boxes; see `probe.rs`). A probe ray stops at its first non-resident structure, so later
//! probe rounds ([`StreamOptions::probe_rounds`]) trace again only the pixels a round left
//! open, against what its prefetch built, and prefetch what their rays reach from there;
//! verifying rounds ([`StreamOptions::probe_verify_rounds`]) then probe every pixel again and
//! bring back what the prefetch evicted that the next frame's rays still pass through.
//!
//! # Eviction and the budget
//! Allocations go through `motu-alloc` (standard blocks a 64th of the budget, a block of its
//! own for any request above half of one), whose blocks never exceed the budget (host-visible
//! staging counts against it on unified-memory devices). Shared blocks for structures about a
//! block in size stranded free space no later structure fitted: a fifth to a quarter of the
//! budget held nothing while structures were evicted for room.
//! When one fails, the least-recently-visible BLASes not built in the current step are evicted
//! and it is retried. Only when a single BLAS does not fit next to the skeleton does the frame
//! fail with [`GpuError::Budget`] naming it; the CLI refuses a budget below the floor up front.

mod budget;
mod buffers;
mod cache;
mod defrag;
mod demand;
mod floor;
mod frame;
mod params;
mod passes;
mod persistent;
mod probe;
mod proxy_boxes;
mod rebuild;
mod residency;
mod shading;
mod skeleton;
mod tlas_records;

pub use cache::StructureCache;
pub use floor::{
    persistent_tlas_estimate, streamed_mesh_total_bytes, streaming_floor, streaming_floor_planned,
    FloorSizes, StreamFloor,
};
pub use skeleton::StreamPlan;

/// Whether BLAS `b` is streamed (built on demand, evicted under the budget): a triangle BLAS
/// with geometry. The rest (AABB BLASes of programmable instances) stay in the skeleton.
pub(super) fn streamable(b: &motu_abi::BlasRecord) -> bool {
    b.kind == motu_abi::BLAS_TRIANGLES && b.item_count > 0
}
pub use persistent::{PersistentEstimate, TlasUpdate};

use std::collections::BTreeSet;

use motu_abi::HierarchyView;
use motu_alloc::{MemoryClass, Residency, MIB};
use motu_vk::{Context, GpuHeap, HeapBuffer};
use serde::Serialize;

use crate::error::{GpuError, Result};
use crate::render::{Backend, Tracer};
use crate::scene::{AccelStruct, BuildOptions, MeshBlobSource, MeshGpu, Uploader, SLOT_COUNT};

/// `PI_EMPTY_BLAS` of `common.glsl`: a proxy box standing for a non-resident triangle BLAS.
pub const PI_EMPTY_BLAS: u32 = 2;
/// `GUARD_BIAS` of `common.glsl`: packed pixel-list coordinates are biased by it.
const GUARD_BIAS: i32 = 4096;
const IDENTITY: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// How a [`StreamingRenderer`] works.
#[derive(Clone, Copy, Debug)]
pub struct StreamOptions {
    /// The VRAM budget (`--vram-budget`): blocks counted against it never exceed it.
    pub budget_bytes: u64,
    /// Cap on `VkDeviceMemory` allocations.
    pub max_allocations: u32,
    /// Build–traverse passes per frame before giving up on the remaining pixels; 0: sized
    /// from the structure count (see [`StreamingRenderer::max_passes`]).
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
    /// ([`StreamingRenderer::set_next_camera`]): every ray of every `probe_stride`-th pixel
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
    /// image 13% sooner and the whole frame 19% longer; BENCHMARKS.md, session 22).
    pub probe_rounds: u32,
    /// Verifying probe rounds after those (`--stream-probe-verify`; 0: none): every pixel of
    /// the next camera probed again against what the prefetch left resident, and what its
    /// rays now find missing prefetched, until a round finds nothing missing, its prefetch
    /// builds nothing, or this many ran. The prefetch evicts for room what no probe ray met,
    /// and some of that the next frame's rays pass through on their way to their hits; a
    /// verifying round finds it before the frame does. A round's own prefetch may evict
    /// another such structure, so the default is two: one round left the H200's third at
    /// 1.455 passes after the first, two at 1.000. H200, island 0.3 along shotCam, two rounds
    /// against none (BENCHMARKS.md, session 28): primary visibility at a quarter of the full
    /// build 1.909 → 1.091 passes after the first at about the same frame time; shaded at half
    /// 1.182 → 1.000 (frames +12%), at a third 1.182 → 1.000 (+53%), at a quarter 2.364 →
    /// 2.182 (capacity-bound). Each round costs a probe trace and, when it finds something, a
    /// build step with its TLAS rebuilds.
    pub probe_verify_rounds: u32,
    /// Pass marks of the probe (see [`PassMarks`]); [`PassMarks::Auto`] by default.
    pub pass_marks: PassMarks,
    /// Bytes (meshes plus acceleration structures) one frame may build; 0: unbounded. At least
    /// one structure is built per frame, so a frame may overshoot by one; when it is spent the
    /// frame stops (unfinished pixels, or fallback) and later frames go on refining.
    pub frame_build_bytes: u64,
    /// Milliseconds of building one frame may spend; 0: unbounded (same rules).
    pub frame_build_ms: f64,
    /// Whether TLASes are persistent and updated as residency changes, or rebuilt over their
    /// resident instances (`--stream-tlas`; see `persistent.rs`).
    pub tlas_update: TlasUpdate,
    /// Before evicting for a TLAS rebuild's room or after a refused allocation, drain the
    /// emptiest memory blocks instead: their streamed BLASes, meshes and textures are copied
    /// into free space other blocks have and the emptied blocks return their bytes to the
    /// budget (`defrag.rs`; `defrag_*` per frame in `--stats`). Off by default: measured on
    /// lavapipe only (the default island along shotCam at a third of its full build, 64×36:
    /// 1.857 → 1.571 passes after the first, evictions on refusal 3.6 → 0 a frame; a quarter
    /// unchanged; every image equal to the full build's), not yet on a GPU.
    pub defrag: bool,
    /// Where streamed meshes (positions, indices, primitive maps, shading attributes) live
    /// (`--stream-mesh-memory`; see [`MeshMemory`]).
    pub mesh_memory: MeshMemory,
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
            probe_rounds: 2,
            probe_verify_rounds: 2,
            pass_marks: PassMarks::Auto,
            fallback: StreamFallback::Off,
            frame_build_bytes: 0,
            frame_build_ms: 0.0,
            tlas_update: TlasUpdate::Auto,
            defrag: false,
            mesh_memory: MeshMemory::Auto,
        }
    }
}

/// Per-frame streaming statistics (`--stats`, one entry per frame).
#[derive(Clone, Debug, Default, Serialize)]
pub struct FrameStreamStats {
    pub frame: u64,
    /// Build–traverse passes this frame.
    pub passes: u32,
    /// False when `max_passes` ran out with pixels still incomplete.
    pub complete: bool,
    /// Pixels still incomplete after the last pass (rendered as misses, or as the fallback).
    pub incomplete_pixels: u64,
    /// Of those, pixels shown by the fallback (`StreamOptions::fallback`): not exact.
    pub fallback_pixels: u64,
    /// The frame stopped because its build budget (`frame_build_bytes`/`frame_build_ms`) was
    /// spent.
    pub build_budget_spent: bool,
    /// Pixels whose traversal was cut short this frame (a stack overflow or the trace cap).
    pub truncated_rays: u64,
    /// Pixels traced again in passes after the first.
    pub reshot_pixels: u64,
    /// Guard-band rays traced (prefetch probes).
    pub guard_rays: u64,
    /// Triangle BLASes built (demand plus prefetch).
    pub blas_built: u32,
    /// Child TLASes made resident.
    pub tlas_built: u32,
    /// Resident TLASes rebuilt because their instance set changed (with their proxies).
    pub tlas_rebuilt: u32,
    /// Groups those rebuilds ran in: large TLASes (the pieces of a split root) one at a time,
    /// small ones together, so a rebuild's transient is one group's.
    pub tlas_rebuild_groups: u32,
    /// Structures built after the frame from the guard band and the next camera's probe.
    pub prefetched: u32,
    /// Structures the prefetch wanted but left unbuilt: no room beside what the probe saw
    /// resident and the TLAS rebuilds' reserve (the next frame's first pass opens those its
    /// rays need).
    pub prefetch_skipped: u32,
    /// Rays of the probe of the next frame's camera (its pixels' primary rays; 0: no probe),
    /// and the probe's trace time (not in `trace_ms`).
    pub probe_rays: u64,
    pub probe_ms: f64,
    /// Probe rounds run after this frame (`StreamOptions::probe_rounds`): the first probes
    /// the next camera's pixels, each later one only the pixels the round before left open,
    /// after the prefetch built what they needed.
    pub probe_rounds: u32,
    /// Of `probe_rounds`: verifying rounds (`StreamOptions::probe_verify_rounds`), each over
    /// every pixel after the rounds before had prefetched.
    pub probe_verify_rounds: u32,
    /// The row stride of the probe's pass marks after this frame (0: none;
    /// `StreamOptions::pass_marks`), and the resident BLASes they refreshed: passed by a final
    /// probe ray, met by no probe ray's hit or open walk.
    pub probe_pass_rows: u32,
    pub probe_pass_marks: u32,
    /// The resident streamed BLASes the probe rounds' rays hit or passed through (met, or
    /// marked passed), and their bytes (structures, and each of their meshes once): what of
    /// the resident set the next frame's rays use. With everything resident and pass marks
    /// on every row (`--stream-probe-pass-rows 1`), the next frame's *one-pass need*: above
    /// its `room_bytes`, no residency order can serve that frame in one pass while whole
    /// BLASes are the unit (exactly so for primary visibility; a shadow ray may also be
    /// served by another of its occluders). Pass marks off, passed BLASes are not counted.
    pub probe_need_blases: u32,
    pub probe_need_bytes: u64,
    /// Of `probe_need_bytes`: the meshes (geometry and shading attributes), what a unit of
    /// residency smaller than a BLAS and its meshes could leave out for structures rays only
    /// pass or only shadow and AO rays meet.
    pub probe_need_mesh_bytes: u64,
    /// Structures evicted (BLASes and TLASes), and the bytes released (structures plus their
    /// meshes; also those of structures a refused TLAS rebuild gave back, counted in
    /// `deferred`).
    pub evicted: u32,
    pub evicted_bytes: u64,
    /// Of `evicted`: made up front for TLAS rebuilds (their buffers are dedicated blocks, so
    /// only emptied blocks count), and after the budget refused an allocation. The rest made
    /// room for BLAS build groups by estimate.
    pub evicted_for_tlas: u32,
    pub evicted_on_refusal: u32,
    /// Demanded structures left unbuilt in a pass because they did not fit next to what the
    /// pass's incomplete pixels need (built in a later pass, once those pixels completed).
    pub deferred: u32,
    /// Mesh bytes streamed from the source to the device.
    pub bytes_streamed: u64,
    /// Bytes built this frame: acceleration structures plus the meshes streamed for them.
    pub built_bytes: u64,
    /// Triangles in the BLASes built.
    pub triangles_built: u64,
    /// BLASes restored from the structure cache by copy instead of built (`cache.rs`), their
    /// bytes, from which tier, and the time the restores took (part of `build_ms`).
    pub restored_blases: u32,
    pub restored_bytes: u64,
    pub restored_from_host: u32,
    pub restored_from_disk: u32,
    pub restore_ms: f64,
    /// Cached BLASes built instead of restored: no room for their copy next to what the
    /// step must keep.
    pub restore_skipped: u32,
    /// Of `blas_built`: BLASes this renderer had built (or restored) before, built again, and
    /// their structure bytes: what a cache saves.
    pub rebuilt_blases: u32,
    pub rebuilt_bytes: u64,
    /// BLASes serialised into the structure cache after their builds, the bytes, the time
    /// (part of `build_ms`), and those skipped for want of room to read them back.
    pub cache_stored: u32,
    pub cache_stored_bytes: u64,
    pub cache_store_ms: f64,
    pub cache_skipped: u32,
    pub build_ms: f64,
    /// Wall time of the trace submissions.
    pub trace_ms: f64,
    /// Wall time of the whole frame (passes, build steps, prefetch, readback).
    pub frame_ms: f64,
    /// Host work of the pass loop outside traces and build steps: stamp and request
    /// readback, demand lists, pixel lists, per-pass table writes.
    pub host_ms: f64,
    /// Of `build_ms`: streaming meshes (and their textures) from the source to the device.
    pub mesh_ms: f64,
    /// Of `build_ms`: triangle BLAS builds (with compaction).
    pub blas_ms: f64,
    /// Of `build_ms`: TLAS (and proxy BLAS) rebuilds, including their evict-and-retry rounds.
    pub tlas_ms: f64,
    /// Of `build_ms`: choosing and releasing eviction victims.
    pub evict_ms: f64,
    /// Of `build_ms`: rewriting the per-step tables (TLAS and mesh addresses, shading).
    pub tables_ms: f64,
    /// Build steps (one after each pass that left pixels open, plus the prefetch).
    pub build_steps: u32,
    /// BLAS build groups attempted, and how many of them the budget refused (a refused group
    /// is retried in halves; its meshes were streamed for nothing).
    pub build_groups: u32,
    pub refused_groups: u32,
    /// TLAS builds (each rebuild of a dirty TLAS counts, retries included) and the instance
    /// records written for them (for persistent TLASes: the records patched).
    pub tlas_builds: u32,
    pub tlas_instances_written: u64,
    /// Of `tlas_builds`: updates of persistent TLASes (a refit over every instance, no new
    /// structure; see `StreamOptions::tlas_update`).
    pub tlas_updates: u32,
    /// The largest of the frame's TLAS rebuilds while it builds: its instance records, the
    /// structures as built and their build scratch, by the driver's size queries (the proxies
    /// and the compacted copies aside). Held only during the rebuild, so `room_bytes`
    /// (measured after the frame) does not count it: a rebuild leaves about `room_bytes`
    /// less this for BLASes, which is why a frame whose working set is within `room_bytes`
    /// can still need more than one pass.
    pub tlas_rebuild_transient_bytes: u64,
    /// Allocations moved to empty memory blocks (`StreamOptions::defrag`), the bytes of blocks
    /// that freed, and the time it took (part of `build_ms`).
    pub defrag_moves: u32,
    pub defrag_freed_bytes: u64,
    pub defrag_ms: f64,
    /// The frame's working set: distinct BLASes its rays used (hit or open while resident,
    /// or built for them) and their bytes (structures plus meshes). Above what the budget
    /// leaves for structures, some BLAS must be built more than once in the frame.
    pub working_set_blases: u32,
    pub working_set_bytes: u64,
    /// Of `working_set_bytes`: the working set's meshes, each once (resident at the frame's
    /// end), where they count against the budget (0 with meshes in host memory). With everything resident, a frame's one-pass need under a unit of residency that
    /// keeps meshes apart from structures is at most the previous frame's `probe_need_bytes`
    /// less its `probe_need_mesh_bytes` plus this: only BLASes rays hit need their meshes
    /// (`tools/stream-need.sh` prints that bound).
    pub working_set_mesh_bytes: u64,
    /// Why the first pass found structures missing (each one needed by some pixel, so the
    /// frame takes another pass), judged against the previous frame's probe of this camera:
    /// resident while the probe ran but met by none of its rays (passed without a hit: the
    /// hardware reports no such pass) and evicted since, by the prefetch or for the frame;
    /// not resident then and met by no probe ray (secondary rays from hits the probe could not
    /// see yet, or no probe ran); met by the probe but not resident now (the prefetch skipped
    /// it or evicted it again). Zero when the first pass completed the frame.
    pub first_pass_missed_evicted: u32,
    pub first_pass_missed_unprobed: u32,
    pub first_pass_missed_probed: u32,
    /// Per pass: where its time went.
    pub pass_log: Vec<PassStats>,
    /// Resident acceleration-structure and geometry bytes after the frame (counted against
    /// the budget).
    pub resident_bytes: u64,
    /// Resident meshes' bytes in host memory outside the budget after the frame
    /// ([`MeshMemory`]; 0 where meshes are device-local or host memory counts).
    pub resident_host_mesh_bytes: u64,
    pub resident_blases: u32,
    pub resident_tlases: u32,
    /// Image textures resident after the frame (they stream with the meshes that sample them).
    pub resident_textures: u32,
    /// Highest bytes of blocks counted against the budget so far (never above it).
    pub vram_peak_bytes: u64,
    pub vram_budget_bytes: u64,
    /// After the frame: bytes of blocks counted against the budget, and of the live
    /// allocations in them. Their difference is free space inside blocks that only requests
    /// fitting its ranges can use.
    pub heap_block_bytes: u64,
    pub heap_in_use_bytes: u64,
    /// The budget less what stays in use beside BLASes and their meshes after the frame
    /// (skeleton, tables, frame buffers, pipeline, staging): the most that structures may hold
    /// at once. A pass walks only what is resident, so a frame whose `working_set_bytes` is
    /// above it needs at least `ceil(working_set_bytes / room_bytes)` passes at this budget.
    pub room_bytes: u64,
}

/// One pass of a frame (`FrameStreamStats::pass_log`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct PassStats {
    /// Pixels (and guard rays) traced in this pass.
    pub traced: u64,
    /// Pixels still open after it.
    pub open_pixels: u64,
    /// Structures the pass demanded (nearest open) and saw open behind those.
    pub needed: u32,
    pub later: u32,
    pub trace_ms: f64,
    pub host_ms: f64,
    /// Its build step (0 after the last pass).
    pub build_ms: f64,
    pub tlas_ms: f64,
    pub blas_built: u32,
    /// Structure bytes its BLAS builds made (as `FrameStreamStats::built_bytes`).
    pub built_bytes: u64,
    pub evicted: u32,
    /// Bytes its evictions released (as `FrameStreamStats::evicted_bytes`).
    pub evicted_bytes: u64,
    /// Of `evicted`: up front for TLAS rebuilds, after a refused allocation.
    pub evicted_for_tlas: u32,
    pub evicted_on_refusal: u32,
}

/// Totals over all frames rendered so far.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StreamTotals {
    pub frames: u64,
    pub passes: u64,
    pub blas_built: u64,
    pub tlas_built: u64,
    pub tlas_rebuilt: u64,
    pub tlas_rebuild_groups: u64,
    pub evicted: u64,
    pub deferred: u64,
    /// Frames that ran out of passes with pixels still incomplete.
    pub incomplete_frames: u64,
    /// Pixels shown by the fallback, over all frames.
    pub fallback_pixels: u64,
    pub bytes_streamed: u64,
    pub built_bytes: u64,
    pub triangles_built: u64,
    pub build_ms: f64,
    /// The structure cache (`cache.rs`): restores, rebuilds and stores over all frames (as
    /// [`FrameStreamStats`]), and the restores' rate in GB/s.
    pub restored_blases: u64,
    pub restored_bytes: u64,
    pub restore_ms: f64,
    pub restore_gb_per_s: f64,
    pub rebuilt_blases: u64,
    pub rebuilt_bytes: u64,
    pub cache_stored: u64,
    pub cache_stored_bytes: u64,
    pub cache_store_ms: f64,
    /// Triangles of every buildable triangle BLAS: what one full build costs.
    pub scene_triangles: u64,
    /// Bytes the skeleton (tables, PI BLASes, root TLAS, proxies) took at start.
    pub skeleton_bytes: u64,
    /// Boxes inside the streamable BLASes (top boxes and leaves, `proxy_boxes.rs`) that a ray
    /// must enter, beside a member instance's box, to open a BLAS; and the milliseconds
    /// computing them from the meshes took at start.
    pub proxy_boxes: u64,
    pub proxy_boxes_ms: f64,
    /// Milliseconds of the start's other phases: the derived tables (parents per BLAS, proxy
    /// clusters per TLAS, the GPU tables' records), choosing persistent TLASes (driver size
    /// queries), and the resident skeleton (tables uploaded, PI BLASes, TLASes and proxies
    /// built).
    pub derived_ms: f64,
    pub persistent_choice_ms: f64,
    pub skeleton_ms: f64,
    /// How TLASes followed residency (`update` or `rebuild`, as `--stream-tlas` resolved),
    /// the persistent ones, and the VRAM they and their placeholders keep (structures at
    /// full residency, update scratch, and records where host memory counts).
    pub tlas_mode: &'static str,
    pub persistent_tlases: u32,
    pub persistent_tlas_bytes: u64,
    /// A BLAS did not fit next to the persistent TLASes, so they were dropped and TLASes
    /// rebuilt from then on (the floor is sized for rebuilt TLASes).
    pub persistent_dropped: bool,
    /// Where streamed meshes live ([`MeshMemory`] resolved: `device` or `host`) and whether
    /// they count against the budget (host memory does on unified memory).
    pub mesh_memory: &'static str,
    pub meshes_budgeted: bool,
    /// Whether host-visible memory (staging, persistent TLASes' records, host meshes) counts
    /// against the budget: unified memory (lavapipe, integrated GPUs), not a discrete GPU.
    pub host_memory_counted: bool,
    /// Most bytes of resident meshes in host memory outside the budget after any frame.
    pub host_mesh_peak_bytes: u64,
    pub vram_peak_bytes: u64,
    pub vram_budget_bytes: u64,
}

/// A resident TLAS with its proxy BLAS (present while it has non-resident triangle instances).
struct TlasGpu {
    accel: AccelStruct,
    proxy: Option<AccelStruct>,
    /// The resident clusters' boxes (instance mask [`MARKS_MASK`]): only probe passes' rays
    /// meet them, to mark what they pass through (present while some cluster is resident).
    marks: Option<AccelStruct>,
    /// Present when the TLAS is persistent (every instance, updated: `persistent.rs`).
    persistent: Option<persistent::Persistent>,
}

impl TlasGpu {
    fn release(self, heap: &mut GpuHeap) {
        self.accel.release(heap);
        for a in [self.proxy, self.marks].into_iter().flatten() {
            a.release(heap);
        }
        if let Some(p) = self.persistent {
            p.release(heap);
        }
    }

    /// VRAM it holds (`host_counts`: whether host-visible memory counts against the budget).
    fn size_bytes(&self, host_counts: bool) -> u64 {
        self.accel.size_bytes
            + self
                .persistent
                .as_ref()
                .map_or(0, |p| p.size_bytes(host_counts))
            + [&self.proxy, &self.marks]
                .into_iter()
                .flatten()
                .map(|a| a.size_bytes)
                .sum::<u64>()
    }
}

/// Instance mask of the marks BLASes (`CULL_MASK_*` of `common.glsl`): first walks cull with
/// bit 0 only, so they never meet the resident clusters' boxes; probe passes' mark walks
/// (`CULL_MASK_MARK_WALK | CULL_MASK_MARKS`) do.
pub(super) const MARKS_MASK: u8 = 0x02;
/// Instance mask of a streamed TLAS's triangle instances: bit 0 only, so a ray's mark walk
/// (`CULL_MASK_MARK_WALK`, bit 2: PI and proxy instances keep 0xFF) tests no triangle twice.
pub(super) const TRIANGLE_MASK: u8 = 0x01;

/// Renders a hierarchy whose acceleration structures need not fit the budget: see the module
/// docs. Holds the view and the mesh source for its lifetime.
pub struct StreamingRenderer<'a> {
    // Acceleration structures first (destroyed before the heap's blocks).
    blas: Vec<Option<AccelStruct>>,
    /// The persistent TLASes' placeholder BLASes (empty unless some TLAS is persistent).
    placeholders: persistent::Placeholders,
    /// Per TLAS: persistent (built over every instance, then updated) rather than rebuilt.
    persistent_mode: Vec<bool>,
    tlas: Vec<Option<TlasGpu>>,
    meshes: Vec<Option<MeshGpu>>,
    mesh_refs: Vec<u32>,
    /// The memory streamed meshes are allocated in ([`StreamOptions::mesh_memory`] resolved)
    /// and whether it counts against the budget.
    mesh_class: MemoryClass,
    meshes_budgeted: bool,
    tables: Vec<HeapBuffer>,
    blas_stamps: Option<HeapBuffer>,
    /// Per BLAS: the latest pass stamp it was resident in (host copy of `walked_buf`).
    walked: Vec<u32>,
    walked_buf: Option<HeapBuffer>,
    up: Option<Uploader>,
    tracer: Option<(Backend, u32, Tracer)>,
    /// State kept between frames: the frame buffers, the frame's build clock.
    kept: budget::Kept,
    heap: GpuHeap,
    addresses: [u64; SLOT_COUNT],
    /// GPU table indices (into `tables`) rewritten while streaming.
    pis_table: usize,
    mesh_geo_table: usize,
    tlas_addr_table: usize,
    /// Device address of the proxy clusters' member table (u32 global instance indices), 0
    /// when no TLAS has a proxy.
    cluster_members: u64,
    /// `[first, fan]` per BLAS and the boxes inside BLASes (`proxy_boxes.rs`): 0 when none.
    proxy_box_index: u64,
    proxy_boxes: u64,
    shading: shading::StreamShading,
    view: HierarchyView<'a>,
    source: &'a dyn MeshBlobSource,
    opts: StreamOptions,
    build_opts: BuildOptions,
    /// Per TLAS: its proxy boxes (clusters of triangle instances of one BLAS).
    clusters: Vec<Vec<skeleton::ProxyCluster>>,
    /// Per TLAS: first proxy PI slot and proxy BLAS id in the GPU tables.
    proxy_pi_base: Vec<u32>,
    /// Per TLAS: the GPU BLAS record of its marks BLAS (`NONE_U32`: no clusters), rewritten
    /// with each rebuild, and the GPU table holding BLAS records.
    marks_blas: Vec<u32>,
    blases_table: usize,
    /// Per BLAS: TLASes instancing it.
    parents: Vec<Vec<u32>>,
    /// Per BLAS: its instance count in each of `parents` (same order).
    parent_counts: Vec<Vec<u32>>,
    buildable: Vec<bool>,
    residency: Residency,
    /// Per item (BLAS, then TLAS): the last pass stamp that saw it.
    last_seen: Vec<u32>,
    /// Per BLAS: bytes it held when last resident (structure plus meshes), and the last frame
    /// whose rays used it (walked while resident and seen, or built for them): the frame's
    /// working set.
    blas_bytes: Vec<u64>,
    used_in_frame: Vec<u64>,
    /// Resident TLASes whose instance set changed since their build.
    dirty: BTreeSet<u32>,
    /// Pins of the current build step (items that must not be evicted): what the latest
    /// pass's incomplete pixels need (or, when prefetching, everything this frame saw), plus
    /// what the step built.
    pinned: Vec<bool>,
    /// Items the current build step made resident, in build (priority) order.
    built_now: Vec<u32>,
    /// BLASes per build group to try first (see `build_blas_queue`).
    group_hint: usize,
    stamp: u32,
    /// The first stamp whose sightings a prefetch keeps resident: the frame's first pass, or
    /// the probe of the next camera once it ran.
    frame_first_stamp: u32,
    /// The last frame after which [`PassMarks::auto_wanted`] held (0: none yet).
    pass_marks_held: u64,
    /// The next frame's camera, probed after this frame (`set_next_camera`).
    next_camera: Option<motu_abi::camera::CameraParams>,
    /// Per BLAS, what the last probe saw (`PROBE_MET`, `PROBE_RESIDENT` bits), kept for the
    /// next frame's first pass to say why it missed what it missed; empty when no probe ran.
    probe_sighting: Vec<u8>,
    /// What the probe rounds after this frame used of the resident set (`probe.rs`).
    probe_need: probe::ProbeNeed,
    /// BLASes evicted since the renderer started (also those given back; never decremented):
    /// whether a prefetch removed anything since a probe.
    evictions: u64,
    /// Built structures kept for reuse (`cache.rs`).
    reuse: cache::Reuse,
    /// Set when a failed build step left the root TLAS referencing freed memory.
    poisoned: Option<String>,
    frame: u64,
    frame_stats: FrameStreamStats,
    totals: StreamTotals,
    ctx: Context,
}

impl<'a> StreamingRenderer<'a> {
    fn walked_table(&self) -> Result<&HeapBuffer> {
        self.walked_buf
            .as_ref()
            .ok_or_else(|| GpuError::InvalidRequest("streaming: no walked table".into()))
    }

    /// The pass cap of a frame: `StreamOptions::max_passes`, or (0) a safety net sized from
    /// the structure count. Every pass builds at least one structure some pixel still needs,
    /// so a frame needs about as many passes as BLASes at worst (primary rays once each,
    /// shadow rays that start late once more); a frame that hits the cap reports its
    /// unfinished pixels.
    pub fn max_passes(&self) -> u32 {
        if self.opts.max_passes > 0 {
            return self.opts.max_passes;
        }
        let n = self.buildable.iter().filter(|&&b| b).count() as u32;
        n.saturating_mul(4).saturating_add(16)
    }

    fn item_count(&self) -> usize {
        self.view.blases.len() + self.view.tlases.len()
    }

    /// A per-frame allocation (frame buffers, trace pipeline) that does not fit even with
    /// every structure evicted: the budget is too small for the skeleton itself.
    fn skeleton_error(&self, what: &str, e: GpuError) -> GpuError {
        match e {
            GpuError::Budget(msg) => {
                let report = self.heap.report();
                GpuError::Budget(format!(
                    "streaming: {what} do not fit under the budget of {} bytes next to the \
                     resident skeleton ({} bytes) with every structure evicted ({} bytes in \
                     use); raise --vram-budget or render smaller images ({msg})",
                    report.budget_bytes, self.totals.skeleton_bytes, report.budget_in_use_bytes
                ))
            }
            e => e,
        }
    }

    fn frame_first_stamp(&self) -> u32 {
        self.frame_first_stamp
    }

    /// Names the camera of the next frame (a camera path's, a flight's): after the next
    /// [`Self::render_frame`] a probe of it prefetches what its rays will meet, primary and
    /// secondary, so that frame mostly completes in one pass. Used by one frame; a camera of
    /// another size is not probed.
    pub fn set_next_camera(&mut self, camera: Option<motu_abi::camera::CameraParams>) {
        self.next_camera = camera;
    }

    /// Drains every block it can now (`defrag.rs`), after evicting every other resident
    /// streamed BLAS when `thin_out` (free ranges inside the blocks). Tests: the next frame
    /// must be unchanged.
    #[cfg(test)]
    pub(crate) fn defragment_now(&mut self, thin_out: bool) -> Result<defrag::Drained> {
        if thin_out {
            let resident: Vec<usize> = (0..self.blas.len())
                .filter(|&b| self.blas[b].is_some() && self.buildable[b])
                .collect();
            for b in resident.into_iter().step_by(2) {
                self.evict(b);
            }
        }
        self.defragment(u64::MAX)
    }

    /// Moves the pass stamp on to `stamp` (tests of the stamp limit: 2^29 passes otherwise).
    #[cfg(test)]
    pub(crate) fn skip_stamps_to(&mut self, stamp: u32) {
        self.stamp = self.stamp.max(stamp);
    }

    /// Whether host-visible memory counts against the budget (unified memory: lavapipe,
    /// integrated GPUs), where persistent TLASes' records count too.
    #[cfg(test)]
    pub(crate) fn host_visible_counts_against_budget(&self) -> bool {
        self.heap.host_visible_counts_against_budget()
    }

    /// Statistics of the run so far.
    pub fn totals(&self) -> StreamTotals {
        let mut t = self.totals.clone();
        t.vram_peak_bytes = self.heap.report().peak_block_bytes;
        t
    }

    /// The allocator's statistics now.
    pub fn alloc_report(&self) -> motu_alloc::AllocReport {
        self.heap.report()
    }

    /// Whether BLAS `b` / TLAS `t` of the hierarchy is resident now.
    pub fn blas_resident(&self, b: u32) -> bool {
        self.blas.get(b as usize).is_some_and(|a| a.is_some())
    }

    pub fn tlas_resident(&self, t: u32) -> bool {
        self.tlas.get(t as usize).is_some_and(|a| a.is_some())
    }
}
