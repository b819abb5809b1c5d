//! Out-of-core rendering: lazy, visibility-driven acceleration-structure builds and eviction
//! under a VRAM budget (Lee & Liktor 2020, "multi-pass lazy build", adapted to motu's
//! multi-level hierarchy).
//!
//! # Empty instances
//! Every triangle BLAS and every non-root TLAS starts non-resident. PI (AABB) BLASes, the root
//! TLAS and the node tables form the resident *skeleton*. In the GPU's copy of the tables each
//! TLAS with triangle instances gets one extra instance: a *proxy* AABB BLAS with one box per
//! non-resident triangle instance (the BLAS bounds in TLAS space), whose PI record has kind
//! `PI_EMPTY_BLAS` and names the BLAS. The real instance stays in place with a null BLAS
//! reference (inactive), so instance indices never move. A PI into a non-resident TLAS stays a
//! PI; the TLAS's entry in the address table is 0.
//!
//! # Traversal (both backends, `traverse.glsl`)
//! Every walked TLAS and the BLAS of every closest hit are stamped visible (`atomicMax` of a
//! per-pass stamp). A ray meeting an empty instance in front of its best hit stamps the nearest
//! such instance *needed* (and counts a request for it), becomes *incomplete* (the paper's
//! `trav_valid = false`) and keeps walking only to discover prefetch candidates: it skips
//! shading and shadow rays, stamps its best hit so far *needed* (a pin), records where it
//! stopped and writes nothing; its pixel goes on the next pass's list. An incomplete ray has no
//! hit before its nearest empty instance (none in front of it, no resident one hit), so its
//! next pass *resumes* there (per-pixel `t_min`, primary and shadow ray): what it already
//! passed may be evicted without costing it anything, and each pass moves it forward. Resident
//! triangle BLASes are walked by the hardware without a shader callback, so only the one hit
//! is stamped: a resident BLAS that rays cross without hitting ages in the LRU order.
//!
//! # Build–traverse loop ([`StreamingRenderer::render_frame`])
//! Pass 1 traces every pixel plus a sparse *guard band* of primary rays around the image.
//! After each pass the host reads the stamps, the request counts and the incomplete-pixel
//! list, and builds the needed-but-empty structures **most requested first**: meshes stream
//! through the staging ring, BLASes build in groups that halve when the budget refuses them
//! (groups use free memory only; single builds evict for room), uncompacted when compaction
//! saves nothing or does not fit. What does not fit is *deferred*: its pixels stay incomplete
//! and the next pass, once the pixels now served are complete, builds it. Then each resident
//! TLAS whose instance set changed is rebuilt with its proxy BLAS (the old one freed first, so
//! the root's rebuild never needs two roots' memory; a TLAS rebuild costs one pass over its
//! instances, small next to BLAS builds over triangles), and only the incomplete pixels are
//! re-shot. The loop ends when no pixel is incomplete or after `max_passes` (reported in
//! [`FrameStreamStats::complete`] and `StreamTotals::incomplete_frames`; remaining pixels are
//! misses, magenta in colour). Structures the guard band saw are built after the frame as a
//! prefetch (evicting only what this frame did not see; what does not fit is skipped), and
//! everything stays resident until evicted, so on a camera path later frames mostly need one
//! pass.
//!
//! # Eviction and the budget
//! Allocations go through `motu-alloc`, whose blocks never exceed the budget (host-visible
//! staging counts against it on unified-memory devices; staging and scratch are each capped
//! at an eighth of it). When one fails, the least-recently-visible unpinned structures (BLAS
//! with the meshes only it uses, or child TLAS) are evicted and it is retried. Pinned in a
//! build step: what the latest pass's incomplete pixels need (their best hits, walked TLASes)
//! and what the step built; pixels completed earlier in the frame are final, so what only they
//! used may go. When not even one structure fits next to those pins, the pins go too (their
//! pixels find them again); when a TLAS rebuild does not fit, the step's least requested builds
//! are given back. Only when a single structure does not fit next to the resident skeleton
//! (tables, PI BLASes, root TLAS and proxies, frame buffers, trace pipeline, staging ring) does
//! the frame fail, with [`GpuError::Budget`] naming the structure and the bytes: motu does not
//! silently render a coarser image. Evicting a BLAS rebuilds its resident parents before the
//! next trace.

mod buffers;
mod demand;
mod frame;
mod passes;
mod rebuild;
mod residency;
mod skeleton;

use std::collections::BTreeSet;

use motu_abi::HierarchyView;
use motu_alloc::{ItemId, Residency, MIB};
use serde::Serialize;

use crate::context::Context;
use crate::error::GpuError;
use crate::heap::{GpuHeap, HeapBuffer};
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
    /// Build–traverse passes per frame before giving up on the remaining pixels.
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
}

impl Default for StreamOptions {
    fn default() -> Self {
        Self {
            budget_bytes: 512 * MIB,
            max_allocations: 4096,
            max_passes: 16,
            scratch_budget_bytes: 32 * MIB,
            staging_bytes: 8 * MIB,
            guard_band_px: 8,
            compact: true,
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
    /// Pixels still incomplete after the last pass (rendered as misses).
    pub incomplete_pixels: u64,
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
    /// Structures built after the frame from the guard band.
    pub prefetched: u32,
    /// Structures evicted (BLASes and TLASes).
    pub evicted: u32,
    /// Demanded structures left unbuilt in a pass because they did not fit next to what the
    /// pass's incomplete pixels need (built in a later pass, once those pixels completed).
    pub deferred: u32,
    /// Mesh bytes streamed from the source to the device.
    pub bytes_streamed: u64,
    /// Triangles in the BLASes built.
    pub triangles_built: u64,
    pub build_ms: f64,
    /// Wall time of the trace submissions.
    pub trace_ms: f64,
    /// Resident acceleration-structure and geometry bytes after the frame.
    pub resident_bytes: u64,
    pub resident_blases: u32,
    pub resident_tlases: u32,
    /// Highest bytes of blocks counted against the budget so far (never above it).
    pub vram_peak_bytes: u64,
    pub vram_budget_bytes: u64,
}

/// Totals over all frames rendered so far.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StreamTotals {
    pub frames: u64,
    pub passes: u64,
    pub blas_built: u64,
    pub tlas_built: u64,
    pub tlas_rebuilt: u64,
    pub evicted: u64,
    pub deferred: u64,
    /// Frames that ran out of passes with pixels still incomplete.
    pub incomplete_frames: u64,
    pub bytes_streamed: u64,
    pub triangles_built: u64,
    pub build_ms: f64,
    /// Triangles of every buildable triangle BLAS: what one full build costs.
    pub scene_triangles: u64,
    /// Bytes the skeleton (tables, PI BLASes, root TLAS, proxies) took at start.
    pub skeleton_bytes: u64,
    pub vram_peak_bytes: u64,
    pub vram_budget_bytes: u64,
}

/// A resident TLAS with its proxy BLAS (present while it has non-resident triangle instances).
struct TlasGpu {
    accel: AccelStruct,
    proxy: Option<AccelStruct>,
}

/// Renders a hierarchy whose acceleration structures need not fit the budget: see the module
/// docs. Holds the view and the mesh source for its lifetime.
pub struct StreamingRenderer<'a> {
    // Acceleration structures first (destroyed before the heap's blocks).
    blas: Vec<Option<AccelStruct>>,
    tlas: Vec<Option<TlasGpu>>,
    meshes: Vec<Option<MeshGpu>>,
    mesh_refs: Vec<u32>,
    tables: Vec<HeapBuffer>,
    blas_stamps: Option<HeapBuffer>,
    tlas_stamps: Option<HeapBuffer>,
    up: Option<Uploader>,
    tracer: Option<(Backend, u32, Tracer)>,
    heap: GpuHeap,
    addresses: [u64; SLOT_COUNT],
    /// GPU table indices (into `tables`) rewritten while streaming.
    pis_table: usize,
    mesh_geo_table: usize,
    tlas_addr_table: usize,
    view: HierarchyView<'a>,
    source: &'a dyn MeshBlobSource,
    opts: StreamOptions,
    build_opts: BuildOptions,
    /// Per TLAS: local indices of its triangle instances (they get proxies).
    tri_instances: Vec<Vec<u32>>,
    /// Per TLAS: first proxy PI slot and proxy BLAS id in the GPU tables.
    proxy_pi_base: Vec<u32>,
    /// Per BLAS: TLASes instancing it.
    parents: Vec<Vec<u32>>,
    /// Per original instance: its BLAS's bounds in its TLAS's space (`[min, max]`).
    instance_boxes: Vec<[f32; 6]>,
    buildable: Vec<bool>,
    residency: Residency,
    /// Per item (BLAS, then TLAS): the last pass stamp that saw it.
    last_seen: Vec<u32>,
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
    frame_first_stamp: u32,
    /// Set when a failed build step left the root TLAS referencing freed memory.
    poisoned: Option<String>,
    frame: u64,
    frame_stats: FrameStreamStats,
    totals: StreamTotals,
    ctx: Context,
}

fn item_of_tlas(blas_count: usize, t: u32) -> ItemId {
    ItemId((blas_count as u32).saturating_add(t))
}

impl<'a> StreamingRenderer<'a> {
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
