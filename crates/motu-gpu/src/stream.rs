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
//! Each pixel keeps its state across the passes of a frame (`Carry`, 176 bytes):
//! the current sample's primary best hit so far, *resolved* (source mesh, primitive, LOD,
//! material, geometric and shading normals, textured base colour) while its BLAS was resident,
//! sample 0's AOV record, the colour summed so far, and which ray is open (the primary, the
//! n-th secondary ray: lights' shadow rays, then AO rays, or a `--bounces` path's bounce ray,
//! a closest-hit ray carried like the primary) since which pass, with the path's vertex,
//! throughput and the next vertex's incoming ray. A pass
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
//!
//! # Parts
//! [`StreamingRenderer`] keeps its state in parts, each a struct in its own file that states
//! its invariants; the procedures that span parts (a frame, a build step, a TLAS rebuild)
//! are methods of the renderer in the files named after them, and the long ones run as
//! context structs with a method per phase (`tlas_build.rs`'s `TlasBuild`).
//!
//! | part (field) | file | owns |
//! |---|---|---|
//! | `Topology` (`topo`) | `topology.rs` | what the view implies and never changes: streamed BLASes, parents with instance counts, proxy clusters ([`StreamPlan`]) and their GPU slots |
//! | `GpuTables` (`gpu`) | `tables.rs` | the GPU node tables, member table, boxes inside BLASes, stamp buffers |
//! | `Resident` (`res`) | `residency.rs` | resident BLASes and meshes, the LRU, pins, sizes, working set, eviction count |
//! | `Tlases` (`tlases`) | `tlases.rs` | every TLAS with its proxy and marks, persistent mode and placeholders, dirty set |
//! | `FrameState` (`frame`) | `frame.rs` | the frame in progress (number, stats, pass stamps), probe sightings, trace pipeline, kept frame buffers |
//! | `StreamShading` (`shading`) | `shading.rs` | texture residency and the shading tables |
//! | `Reuse` (`reuse`) | `cache.rs` | built structures kept for reuse, the structure cache |
//! | [`StreamTotals`] (`totals`) | `stats.rs` | statistics over the run ([`FrameStreamStats`] per frame) |
//!
//! The renderer itself holds what every part uses: the device context, the heap, the staging
//! ring, the view, the mesh source and the options.
//! `Topology`, `GpuTables` and `FrameState` keep their fields private (read and changed
//! through their methods only; the frame's counters through `stats_mut`); the other parts'
//! fields are still open to the module's files, their invariants kept by the renderer's
//! methods in the part's file (`residency.rs`'s eviction and mesh references,
//! `rebuild.rs`/`tlas_build.rs` for the dirty set).

mod budget;
mod buffers;
mod cache;
mod clock;
mod clones;
mod defrag;
mod demand;
mod fits;
mod floor;
mod flying;
mod frame;
mod instance_table;
mod member_boxes;
mod options;
mod params;
mod passes;
mod persistent;
mod piece_order;
mod plan_cache;
mod probe;
mod proxy_boxes;
mod proxy_count;
mod rebuild;
mod residency;
mod restore_rule;
mod room_split;
mod shading;
mod skeleton;
mod stats;
mod store_policy;
mod tables;
mod tlas_build;
mod tlas_compact;
mod tlas_encode;
mod tlas_records;
mod tlases;
mod topology;
mod transfer;

pub use cache::StructureCache;
pub use clones::HostCacheMode;
pub use fits::{full_build_fits, FullBuildFit};
pub use floor::{
    persistent_tlas_estimate, streamed_mesh_total_bytes, streaming_floor, streaming_floor_planned,
    FloorSizes, StreamFloor,
};
pub use options::{
    FrameCaps, MeshMemory, PassMarks, ProbeLater, ProbePaths, ProbeSettings, StreamFallback,
    StreamOptions, TlasRecordsMode, AUTO_PASS_FRAMES, AUTO_PASS_ROWS, CLOCKED_PROBE,
    DEFAULT_TLAS_HEADROOM, MAX_TLAS_HEADROOM,
};
pub use proxy_count::{ProxyCalls, ProxyWork};
pub use stats::{FrameStreamStats, PassStats, RoomSplit, StreamTotals};
pub use store_policy::{HostStorePolicy, StorePolicyStats};
pub use topology::{ClustersSource, StreamPlan};

/// Whether BLAS `b` is streamed (built on demand, evicted under the budget): a triangle BLAS
/// with geometry. The rest (AABB BLASes of programmable instances) stay in the skeleton.
pub(super) fn streamable(b: &motu_abi::BlasRecord) -> bool {
    b.kind == motu_abi::BLAS_TRIANGLES && b.item_count > 0
}
pub use persistent::{PersistentEstimate, TlasUpdate};

use motu_abi::HierarchyView;
use motu_alloc::{MemoryClass, MIB};
use motu_vk::{Context, GpuHeap};

use crate::error::{GpuError, Result};
use crate::scene::{BuildOptions, MeshBlobSource, Uploader};

/// `PI_EMPTY_BLAS` of `common.glsl`: a proxy box standing for a non-resident triangle BLAS.
pub const PI_EMPTY_BLAS: u32 = 2;
/// `GUARD_BIAS` of `common.glsl`: packed pixel-list coordinates are biased by it.
const GUARD_BIAS: i32 = 4096;
const IDENTITY: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// Instance mask of the marks BLASes (`CULL_MASK_*` of `common.glsl`): first walks cull with
/// bit 0 only, so they never meet the resident clusters' boxes; probe passes' mark walks
/// (`CULL_MASK_MARK_WALK | CULL_MASK_MARKS`) do.
pub(super) const MARKS_MASK: u8 = 0x02;
/// Instance mask of a streamed TLAS's triangle instances: bit 0 only, so a ray's mark walk
/// (`CULL_MASK_MARK_WALK`, bit 2: PI and proxy instances keep 0xFF) tests no triangle twice.
pub(super) const TRIANGLE_MASK: u8 = 0x01;

/// Renders a hierarchy whose acceleration structures need not fit the budget: see the module
/// docs. Holds the view and the mesh source for its lifetime. Its state lives in parts, each
/// in its own file with its invariants (the module docs' "Parts" list them).
pub struct StreamingRenderer<'a> {
    // Acceleration structures and buffers first (destroyed before the heap's blocks).
    /// What is resident of the streamed BLASes and meshes, and the choice of what goes.
    res: residency::Resident,
    /// Evicted BLASes cloned into host memory (`clones.rs`).
    clones: clones::HostClones,
    /// The TLASes with their proxies and marks, persistent or rebuilt, and which are dirty.
    tlases: tlases::Tlases,
    /// The GPU copies of the node tables and the stamp buffers the shaders read.
    gpu: tables::GpuTables,
    /// The staging ring every upload goes through (absent only once released).
    up: Option<Uploader>,
    /// The frame in progress and what is kept between frames.
    frame: frame::FrameState,
    heap: GpuHeap,
    shading: shading::StreamShading,
    /// What the view implies and never changes: parents, proxy clusters, their GPU slots.
    topo: topology::Topology,
    view: HierarchyView<'a>,
    source: &'a dyn MeshBlobSource,
    opts: StreamOptions,
    build_opts: BuildOptions,
    /// Built structures kept for reuse (`cache.rs`).
    reuse: cache::Reuse,
    /// Set when a failed build step left the root TLAS referencing freed memory.
    poisoned: Option<String>,
    totals: StreamTotals,
    ctx: Context,
}

impl<'a> StreamingRenderer<'a> {
    /// Uploads the skeleton (tables, PI BLASes, the root TLAS with its proxy) under the budget.
    pub fn new(
        ctx: &Context,
        view: HierarchyView<'a>,
        source: &'a dyn MeshBlobSource,
        opts: &StreamOptions,
    ) -> Result<StreamingRenderer<'a>> {
        let plan = StreamPlan::load(&view, source.stored_proxy_clusters(), None);
        Self::with_plan(ctx, view, plan, source, opts)
    }

    /// [`Self::new`] with the proxy clusters already made (`plan`, of this `view`, as the
    /// floor used them). The parts are made from the view (`topology.rs`) and the heap
    /// (`skeleton.rs`), then the skeleton is raised ([`Self::raise_skeleton`]).
    pub fn with_plan(
        ctx: &Context,
        view: HierarchyView<'a>,
        plan: StreamPlan,
        source: &'a dyn MeshBlobSource,
        opts: &StreamOptions,
    ) -> Result<StreamingRenderer<'a>> {
        Self::with_plan_and_cache(ctx, view, plan, source, opts, None)
    }

    /// [`Self::with_plan`] with a structure cache attached from the start
    /// ([`Self::attach_cache`]), so that what the start derives from every mesh (the boxes
    /// inside streamable BLASes) is also kept there and read back by the next process.
    pub fn with_plan_and_cache(
        ctx: &Context,
        view: HierarchyView<'a>,
        plan: StreamPlan,
        source: &'a dyn MeshBlobSource,
        opts: &StreamOptions,
        cache: Option<StructureCache>,
    ) -> Result<StreamingRenderer<'a>> {
        let span = tracing::info_span!(
            "stream_init",
            blases = view.blases.len(),
            tlases = view.tlases.len()
        );
        let _g = span.enter();
        view.check_references()?;
        plan.check(&view)?;
        let setup = skeleton::HeapSetup::new(ctx, &view, opts)?;
        let opts = setup.opts;
        let budget = setup.budget_bytes;
        let (nb, nt) = (view.blases.len(), view.tlases.len());
        // Derived structure: proxy clusters per TLAS, parents per BLAS, proxy ids.
        let t_derived = std::time::Instant::now();
        let (topo, records) = topology::Topology::derive(&view, plan)?;
        let build_opts = BuildOptions {
            budget_bytes: budget,
            max_allocations: setup.max_allocation_count,
            scratch_budget_bytes: opts.scratch_budget_bytes,
            max_batch_result_bytes: (opts.scratch_budget_bytes.max(MIB) * 2).min(budget / 4),
            staging_bytes: opts.staging_bytes,
            compact: opts.compact,
            blas_build: opts.blas_build,
            tlas_build: opts.tlas_build,
        };
        let scene_triangles = view
            .blases
            .iter()
            .zip(topo.buildable_all())
            .filter(|(_, &ok)| ok)
            .map(|(b, _)| u64::from(b.primitive_count))
            .sum();
        let derived_ms = skeleton::ms_since(t_derived);
        let totals = StreamTotals {
            scene_triangles,
            vram_budget_bytes: budget,
            mesh_memory: match setup.mesh_class {
                MemoryClass::DeviceLocal => "device",
                MemoryClass::HostVisible => "host",
            },
            meshes_budgeted: setup.meshes_budgeted,
            host_memory_counted: setup.host_counts,
            derived_ms,
            tlas_records_mode: opts.tlas_records.name(),
            tlas_build: opts.tlas_build.name(),
            tlas_compact: opts.tlas_compact && opts.compact,
            ..Default::default()
        };
        let mut r = StreamingRenderer {
            res: residency::Resident::new(
                nb,
                nt,
                view.meshes.len(),
                setup.mesh_class,
                setup.meshes_budgeted,
            ),
            tlases: tlases::Tlases::new(nt),
            gpu: tables::GpuTables::new(nb),
            up: None,
            frame: frame::FrameState::new(),
            heap: setup.heap,
            shading: Default::default(),
            topo,
            view,
            source,
            opts,
            build_opts,
            reuse: cache::Reuse::new(nb, opts.host_store_policy, opts.fixed_rates),
            clones: clones::HostClones::default(),
            poisoned: None,
            totals,
            ctx: ctx.clone(),
        };
        if let Some(cache) = cache {
            r.attach_cache(cache);
        }
        r.raise_skeleton(&records)?;
        let room_bytes = r.room_bytes(&r.heap.report());
        r.reserve_transfer_staging(room_bytes);
        Ok(r)
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
        self.automatic_pass_cap()
    }

    /// The pass cap when the options set none: four passes a streamed BLAS, plus 16.
    pub(super) fn automatic_pass_cap(&self) -> u32 {
        let n = self.topo.buildable_count() as u32;
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
                GpuError::Budget(msg.explained(format!(
                    "streaming: {what} do not fit under the budget of {} bytes next to the \
                     resident skeleton ({} bytes) with every structure evicted ({} bytes in \
                     use); raise --vram-budget or render smaller images",
                    report.budget_bytes, self.totals.skeleton_bytes, report.budget_in_use_bytes
                )))
            }
            e => e,
        }
    }

    /// The first stamp whose sightings a prefetch step pins (see
    /// [`FrameState::prefetch_pins_from`](frame::FrameState::prefetch_pins_from)).
    fn prefetch_pins_from(&self) -> u32 {
        self.frame.prefetch_pins_from()
    }

    /// Names the camera of the next frame (a camera path's, a flight's): after the next
    /// [`Self::render_frame`] a probe of it prefetches what its rays will meet, primary and
    /// secondary, so that frame mostly completes in one pass. Used by one frame; a camera of
    /// another size is not probed.
    pub fn set_next_camera(&mut self, camera: Option<motu_abi::camera::CameraParams>) {
        self.frame.set_next_camera(camera);
    }

    /// Says whether the next [`Self::render_frame`] is the caller's last (a still frame, a
    /// path's end): no prefetch follows its passes (what its guard band saw, or a probe, is
    /// for a frame that will not come). Used by one frame.
    pub fn set_last_frame(&mut self, last: bool) {
        self.frame.last_frame = last;
    }

    /// Drains every block it can now (`defrag.rs`), after evicting every other resident
    /// streamed BLAS when `thin_out` (free ranges inside the blocks). Tests: the next frame
    /// must be unchanged.
    #[cfg(test)]
    pub(crate) fn defragment_now(&mut self, thin_out: bool) -> Result<defrag::Drained> {
        if thin_out {
            let resident: Vec<usize> = (0..self.res.blases().len())
                .filter(|&b| self.res.has_blas(b) && self.topo.buildable(b))
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
        self.frame.skip_stamps_to(stamp);
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
        t.store_policy = self.reuse.policy_stats();
        t
    }

    /// The allocator's statistics now.
    pub fn alloc_report(&self) -> motu_alloc::AllocReport {
        self.heap.report()
    }

    /// Whether BLAS `b` / TLAS `t` of the hierarchy is resident now.
    pub fn blas_resident(&self, b: u32) -> bool {
        self.res.has_blas(b as usize)
    }

    pub fn tlas_resident(&self, t: u32) -> bool {
        self.tlases.get(t).is_some()
    }
}

#[cfg(test)]
mod tests;
