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

use std::collections::BTreeSet;
use std::time::Instant;

use ash::vk;
use bytemuck::{Pod, Zeroable};
use motu_abi::aov::AovRecord;
use motu_abi::camera::CameraParams;
use motu_abi::{
    BlasRecord, HierarchyView, InstanceRecord, PiRecord, TlasRecord, BLAS_AABBS, BLAS_TRIANGLES,
    FLAG_NEEDS_ANY_HIT, NONE_U32,
};
use motu_alloc::{AllocKind, AllocLimits, BuildSize, ItemId, MemoryClass, Residency, MIB};
use serde::Serialize;

use crate::accel::AsBuildFlags;
use crate::context::Context;
use crate::error::{GpuError, Result};
use crate::heap::{GpuHeap, HeapBuffer};
use crate::memory::BufferUsage;
use crate::render::{
    frame_params, Backend, RenderOptions, RenderOutput, RenderStats, Tracer, STAT_WORDS,
};
use crate::scene::{
    blas_geometry, build_batched, encode_instance, table_usage, AccelStruct, BuildOptions,
    MeshBlobSource, MeshGpu, ResourceReport, Slot, Uploader, SLOT_COUNT,
};

/// `PI_EMPTY_BLAS` of `common.glsl`: a proxy box standing for a non-resident triangle BLAS.
pub const PI_EMPTY_BLAS: u32 = 2;
/// `GUARD_BIAS` of `common.glsl`: packed pixel-list coordinates are biased by it.
const GUARD_BIAS: i32 = 4096;
const IDENTITY: [f32; 12] = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];

/// `StreamParams` of `common.glsl` (64 bytes).
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
#[repr(C)]
struct StreamParams {
    blas_stamps: u64,
    tlas_stamps: u64,
    pixel_list: u64,
    incomplete: u64,
    stamp: u32,
    full_count: u32,
    list_count: u32,
    /// Requests of TLAS `t` are at index `blas_count + t`.
    blas_count: u32,
    /// u32 per BLAS, then per TLAS: rays of the pass that need it (build priority).
    requests: u64,
    /// `[f32; 2]` per pixel: where its primary and shadow rays resume next pass.
    resume: u64,
}

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

/// Work of one build step: (id, requests) pairs, most requested first.
#[derive(Default)]
struct Demand {
    blases: Vec<(u32, u32)>,
    tlases: Vec<(u32, u32)>,
}

impl Demand {
    fn is_empty(&self) -> bool {
        self.blases.is_empty() && self.tlases.is_empty()
    }

    fn len(&self) -> usize {
        self.blases.len() + self.tlases.len()
    }

    /// Most requested first (ties: lower id first, so runs are deterministic).
    fn sort(&mut self) {
        for v in [&mut self.blases, &mut self.tlases] {
            v.sort_unstable_by_key(|&(id, n)| (std::cmp::Reverse(n), id));
        }
    }
}

/// Buffers of one frame, freed at its end.
struct FrameBuffers {
    params: HeapBuffer,
    stream: HeapBuffer,
    aov: HeapBuffer,
    rgba: HeapBuffer,
    stats: HeapBuffer,
    incomplete: HeapBuffer,
    requests: HeapBuffer,
    resume: HeapBuffer,
    pixel_list: HeapBuffer,
    readback: HeapBuffer,
}

impl FrameBuffers {
    fn release(self, heap: &mut GpuHeap) {
        for b in [
            self.params,
            self.stream,
            self.aov,
            self.rgba,
            self.stats,
            self.incomplete,
            self.requests,
            self.resume,
            self.pixel_list,
            self.readback,
        ] {
            heap.free(b);
        }
    }
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

fn transformed_box(m: &[f32; 12], lo: [f32; 3], hi: [f32; 3]) -> [f32; 6] {
    let mut out = [
        f32::INFINITY,
        f32::INFINITY,
        f32::INFINITY,
        -f32::INFINITY,
        -f32::INFINITY,
        -f32::INFINITY,
    ];
    for c in 0..8 {
        let p = [
            if c & 1 == 0 { lo[0] } else { hi[0] },
            if c & 2 == 0 { lo[1] } else { hi[1] },
            if c & 4 == 0 { lo[2] } else { hi[2] },
        ];
        let q = motu_abi::xform_point(m, p);
        for a in 0..3 {
            out[a] = out[a].min(q[a]);
            out[3 + a] = out[3 + a].max(q[a]);
        }
    }
    out
}

impl<'a> StreamingRenderer<'a> {
    /// Uploads the skeleton (tables, PI BLASes, the root TLAS with its proxy) under the budget.
    pub fn new(
        ctx: &Context,
        view: HierarchyView<'a>,
        source: &'a dyn MeshBlobSource,
        opts: &StreamOptions,
    ) -> Result<StreamingRenderer<'a>> {
        let span = tracing::info_span!(
            "stream_init",
            blases = view.blases.len(),
            tlases = view.tlases.len()
        );
        let _g = span.enter();
        view.check_references()
            .map_err(|e| GpuError::InvalidRequest(e.to_string()))?;
        let too_many = |what: &str| GpuError::InvalidRequest(format!("streaming: too many {what}"));
        let budget = crate::scene::usable_budget_bytes(ctx, opts.budget_bytes)?;
        // Staging and scratch come out of the budget (staging does on unified memory): an
        // eighth each at most, so small budgets leave room for the structures themselves.
        let opts = &StreamOptions {
            staging_bytes: opts.staging_bytes.min(budget / 8).max(64 * 1024),
            scratch_budget_bytes: opts.scratch_budget_bytes.min(budget / 8).max(64 * 1024),
            ..*opts
        };
        let device_cap = ctx
            .limits()
            .max_memory_allocation_count
            .saturating_sub(ctx.allocation_count());
        let limits = AllocLimits {
            max_allocation_count: opts.max_allocations.min(device_cap).max(1),
            max_allocation_size_bytes: ctx.limits().max_memory_allocation_size,
            budget_bytes: budget,
            host_visible_budget_bytes: opts.staging_bytes.max(64 * MIB) * 4,
        };
        let heap = GpuHeap::new(ctx, limits)?;
        let nb = view.blases.len();
        let nt = view.tlases.len();

        // Derived structure: triangle instances per TLAS, parents per BLAS, proxy ids.
        let buildable: Vec<bool> = view
            .blases
            .iter()
            .map(|b| b.kind == BLAS_TRIANGLES && b.item_count > 0)
            .collect();
        let mut tri_instances = vec![Vec::new(); nt];
        let mut parents = vec![Vec::new(); nb];
        let mut instance_boxes = vec![[0.0f32; 6]; view.instances.len()];
        for (t, rec) in view.tlases.iter().enumerate() {
            for k in 0..rec.instance_count {
                let i = (rec.instance_base + k) as usize;
                let inst = &view.instances[i];
                let b = inst.blas as usize;
                if !parents[b].contains(&(t as u32)) {
                    parents[b].push(t as u32);
                }
                if buildable[b] {
                    tri_instances[t].push(k);
                    let br = &view.blases[b];
                    instance_boxes[i] =
                        transformed_box(&inst.tlas_from_blas, br.bounds_min, br.bounds_max);
                }
            }
        }
        // GPU tables: TLAS ranges grow by the proxy instance; proxy BLASes and PI slots follow
        // the originals.
        let mut gpu_tlases: Vec<TlasRecord> = Vec::with_capacity(nt);
        let mut gpu_instances: Vec<InstanceRecord> = Vec::with_capacity(view.instances.len() + nt);
        let mut gpu_blases: Vec<BlasRecord> = view.blases.to_vec();
        let mut gpu_pis: Vec<PiRecord> = view.pis.to_vec();
        let mut proxy_pi_base = vec![NONE_U32; nt];
        for (t, rec) in view.tlases.iter().enumerate() {
            let base = u32::try_from(gpu_instances.len()).map_err(|_| too_many("instances"))?;
            let range =
                rec.instance_base as usize..(rec.instance_base + rec.instance_count) as usize;
            gpu_instances.extend_from_slice(&view.instances[range]);
            let mut count = rec.instance_count;
            if !tri_instances[t].is_empty() {
                let pi_base = u32::try_from(gpu_pis.len()).map_err(|_| too_many("PIs"))?;
                let blas_id = u32::try_from(gpu_blases.len()).map_err(|_| too_many("BLASes"))?;
                proxy_pi_base[t] = pi_base;
                for &k in &tri_instances[t] {
                    let i = (rec.instance_base + k) as usize;
                    gpu_pis.push(proxy_pi(view.instances[i].blas, &instance_boxes[i]));
                }
                let n = tri_instances[t].len() as u32;
                gpu_blases.push(BlasRecord {
                    kind: BLAS_AABBS,
                    item_base: pi_base,
                    item_count: n,
                    level: rec.level + 1,
                    bounds_min: rec.bounds_min,
                    primitive_count: n,
                    bounds_max: rec.bounds_max,
                    _pad: 0,
                });
                gpu_instances.push(InstanceRecord {
                    tlas_from_blas: IDENTITY,
                    blas: blas_id,
                    flags: 0,
                    element: NONE_U32,
                    _pad: 0,
                });
                count += 1;
            }
            gpu_tlases.push(TlasRecord {
                instance_base: base,
                instance_count: count,
                ..*rec
            });
        }

        let build_opts = BuildOptions {
            budget_bytes: budget,
            max_allocations: limits.max_allocation_count,
            scratch_budget_bytes: opts.scratch_budget_bytes,
            max_batch_result_bytes: (opts.scratch_budget_bytes.max(MIB) * 2).min(budget / 4),
            staging_bytes: opts.staging_bytes,
            compact: opts.compact,
        };
        let scene_triangles = view
            .blases
            .iter()
            .zip(&buildable)
            .filter(|(_, &ok)| ok)
            .map(|(b, _)| u64::from(b.primitive_count))
            .sum();
        let mut r = StreamingRenderer {
            blas: (0..nb).map(|_| None).collect(),
            tlas: (0..nt).map(|_| None).collect(),
            meshes: (0..view.meshes.len()).map(|_| None).collect(),
            mesh_refs: vec![0; view.meshes.len()],
            tables: Vec::new(),
            blas_stamps: None,
            tlas_stamps: None,
            up: None,
            tracer: None,
            heap,
            addresses: [0; SLOT_COUNT],
            pis_table: 0,
            mesh_geo_table: 0,
            tlas_addr_table: 0,
            view,
            source,
            opts: *opts,
            build_opts,
            tri_instances,
            proxy_pi_base,
            parents,
            instance_boxes,
            buildable,
            residency: Residency::new(),
            last_seen: vec![0; nb + nt],
            dirty: BTreeSet::new(),
            pinned: vec![false; nb + nt],
            built_now: Vec::new(),
            group_hint: 16,
            stamp: 0,
            frame_first_stamp: 1,
            poisoned: None,
            frame: 0,
            frame_stats: FrameStreamStats::default(),
            totals: StreamTotals {
                scene_triangles,
                vram_budget_bytes: budget,
                ..Default::default()
            },
            ctx: ctx.clone(),
        };
        r.init_skeleton(&gpu_tlases, &gpu_instances, &gpu_blases, &gpu_pis)?;
        let report = r.heap.report();
        r.totals.skeleton_bytes = report.budget_in_use_bytes;
        tracing::info!(
            skeleton_bytes = r.totals.skeleton_bytes,
            budget_bytes = budget,
            scene_triangles,
            "streaming skeleton resident"
        );
        Ok(r)
    }

    fn init_skeleton(
        &mut self,
        gpu_tlases: &[TlasRecord],
        gpu_instances: &[InstanceRecord],
        gpu_blases: &[BlasRecord],
        gpu_pis: &[PiRecord],
    ) -> Result<()> {
        use bytemuck::cast_slice;
        let ctx = self.ctx.clone();
        let view = self.view;
        self.up = Some(Uploader::new(&mut self.heap, self.opts.staging_bytes)?);
        let mesh_geo = vec![0u64; 2 * view.meshes.len()];
        let tlas_addrs = vec![0u64; view.tlases.len()];
        let tables: [(Slot, &[u8]); 11] = [
            (Slot::Tlases, cast_slice(gpu_tlases)),
            (Slot::Instances, cast_slice(gpu_instances)),
            (Slot::Blases, cast_slice(gpu_blases)),
            (Slot::Geometries, cast_slice(view.geometries)),
            (Slot::Pis, cast_slice(gpu_pis)),
            (Slot::Selectors, cast_slice(view.lod_selectors)),
            (Slot::LodLevels, cast_slice(view.lod_levels)),
            (Slot::Meshes, cast_slice(view.meshes)),
            (Slot::Materials, cast_slice(view.materials)),
            (Slot::MeshGeo, cast_slice(&mesh_geo)),
            (Slot::TlasAddresses, cast_slice(&tlas_addrs)),
        ];
        for (slot, bytes) in tables {
            if bytes.is_empty() {
                continue;
            }
            let buf = self.heap.alloc_buffer(
                &format!("stream-table-{slot:?}"),
                bytes.len() as u64,
                table_usage(),
                AllocKind::NodeTable,
                MemoryClass::DeviceLocal,
                16,
            )?;
            self.addresses[slot as usize] = buf.device_address()?.0;
            self.up_mut()?.upload(&ctx, &buf, 0, bytes)?;
            match slot {
                Slot::Pis => self.pis_table = self.tables.len(),
                Slot::MeshGeo => self.mesh_geo_table = self.tables.len(),
                Slot::TlasAddresses => self.tlas_addr_table = self.tables.len(),
                _ => {}
            }
            self.tables.push(buf);
        }
        let stamp_usage = BufferUsage::STORAGE
            | BufferUsage::DEVICE_ADDRESS
            | BufferUsage::TRANSFER_SRC
            | BufferUsage::TRANSFER_DST;
        for (i, n) in [view.blases.len(), view.tlases.len()]
            .into_iter()
            .enumerate()
        {
            let buf = self.heap.alloc_buffer(
                ["blas-stamps", "tlas-stamps"][i],
                (n.max(1) * 4) as u64,
                stamp_usage,
                AllocKind::Other,
                MemoryClass::DeviceLocal,
                16,
            )?;
            let rec = ctx.record("clear stamps")?;
            let mut rec = rec;
            rec.fill_buffer(&buf, 0, (n.max(1) * 4) as u64, 0)?;
            rec.submit_and_wait()?;
            if i == 0 {
                self.blas_stamps = Some(buf);
            } else {
                self.tlas_stamps = Some(buf);
            }
        }
        self.up_mut()?.flush(&ctx)?;

        // PI BLASes: the skeleton, built once from the PI boxes (input freed after).
        let aabbs = crate::scene::pi_aabbs(&view);
        if !aabbs.is_empty() {
            let buf = self.heap.alloc_buffer(
                "pi-aabbs",
                (aabbs.len() * 24) as u64,
                BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
                AllocKind::Geometry,
                MemoryClass::DeviceLocal,
                16,
            )?;
            let r = (|| -> Result<()> {
                self.up_mut()?.upload(&ctx, &buf, 0, cast_slice(&aabbs))?;
                self.up_mut()?.flush(&ctx)?;
                let base = buf.device_address()?.0;
                let ids: Vec<usize> = (0..view.blases.len())
                    .filter(|&b| view.blases[b].kind == BLAS_AABBS && view.blases[b].item_count > 0)
                    .collect();
                let built = self.build_blas_set(&ids, base)?;
                for (b, a) in built {
                    self.blas[b] = Some(a);
                }
                Ok(())
            })();
            self.heap.free(buf);
            r?;
        }
        // The root TLAS (all its triangle instances empty).
        let root = view.root_tlas;
        self.build_tlases(&[root])?;
        self.upload_tlas_addresses()?;
        Ok(())
    }

    fn up_mut(&mut self) -> Result<&mut Uploader> {
        self.up
            .as_mut()
            .ok_or_else(|| GpuError::InvalidRequest("streaming: staging ring released".into()))
    }

    /// Builds the BLASes `ids` of the original hierarchy (meshes must be resident; `aabb_base`
    /// for PI BLASes) in batches. On failure nothing is left allocated.
    fn build_blas_set(
        &mut self,
        ids: &[usize],
        aabb_base: u64,
    ) -> Result<Vec<(usize, AccelStruct)>> {
        let mut descs = Vec::with_capacity(ids.len());
        let mut sizes = Vec::with_capacity(ids.len());
        let mut order = Vec::with_capacity(ids.len());
        for &b in ids {
            let meshes = &self.meshes;
            let Some((g, c, shape)) =
                blas_geometry(&self.view, b, |m| meshes[m].as_ref(), aabb_base)?
            else {
                continue;
            };
            let sz = self.ctx.blas_build_sizes(&shape, AsBuildFlags::default())?;
            sizes.push(BuildSize {
                result_bytes: sz.acceleration_structure_size_bytes,
                scratch_bytes: sz.build_scratch_size_bytes,
            });
            descs.push((g, c));
            order.push(b);
        }
        let mut report = ResourceReport::default();
        let built = build_batched(
            &self.ctx,
            &mut self.heap,
            &mut report,
            &sizes,
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
            &self.build_opts,
            |k| (descs[k].0.clone(), descs[k].1.clone()),
            |_, _| Ok(()),
        )?;
        Ok(built.into_iter().map(|(k, a)| (order[k], a)).collect())
    }

    /// (Re)builds TLASes `ids` with their proxies from the current residency. The old ones are
    /// released first (old and new together would double the largest transient of a small
    /// budget, the root's); on failure they stay absent and dirty for the caller to retry with
    /// less resident (never traced: the caller rebuilds or poisons before the next trace).
    fn build_tlases(&mut self, ids: &[u32]) -> Result<()> {
        use bytemuck::cast_slice;
        let ctx = self.ctx.clone();
        let view = self.view;
        for &t in ids {
            if let Some(old) = self.tlas[t as usize].take() {
                old.accel.release(&mut self.heap);
                if let Some(p) = old.proxy {
                    p.release(&mut self.heap);
                }
                self.dirty.insert(t);
            }
        }
        // 1. Proxy BLASes: boxes of the non-resident triangle instances, compacted; their PI
        // slots are rewritten to match.
        let mut proxy_boxes: Vec<[f32; 6]> = Vec::new();
        let mut proxy_items: Vec<(u32, u32, u32)> = Vec::new(); // (tlas, first box, count)
        let mut pi_rewrites: Vec<(u32, Vec<PiRecord>)> = Vec::new();
        for &t in ids {
            let rec = &view.tlases[t as usize];
            let first = proxy_boxes.len() as u32;
            let mut pis = Vec::new();
            for &k in &self.tri_instances[t as usize] {
                let i = (rec.instance_base + k) as usize;
                let b = view.instances[i].blas as usize;
                if self.blas[b].is_none() {
                    proxy_boxes.push(self.instance_boxes[i]);
                    pis.push(proxy_pi(b as u32, &self.instance_boxes[i]));
                }
            }
            if !pis.is_empty() {
                proxy_items.push((t, first, pis.len() as u32));
                pi_rewrites.push((t, pis));
            }
        }
        let mut proxies: Vec<(u32, AccelStruct)> = Vec::new();
        if !proxy_boxes.is_empty() {
            let buf = self.heap.alloc_buffer(
                "proxy-aabbs",
                (proxy_boxes.len() * 24) as u64,
                BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
                AllocKind::Geometry,
                MemoryClass::DeviceLocal,
                16,
            )?;
            let r = (|| -> Result<Vec<(usize, AccelStruct)>> {
                self.up_mut()?
                    .upload(&ctx, &buf, 0, cast_slice(&proxy_boxes))?;
                self.up_mut()?.flush(&ctx)?;
                let base = buf.device_address()?.0;
                let mut descs = Vec::new();
                let mut sizes = Vec::new();
                for &(_, first, n) in &proxy_items {
                    let aabbs = vk::AccelerationStructureGeometryAabbsDataKHR::default()
                        .data(vk::DeviceOrHostAddressConstKHR {
                            device_address: base + u64::from(first) * 24,
                        })
                        .stride(24);
                    descs.push((
                        vec![vk::AccelerationStructureGeometryKHR::default()
                            .geometry_type(vk::GeometryTypeKHR::AABBS)
                            .geometry(vk::AccelerationStructureGeometryDataKHR { aabbs })
                            .flags(vk::GeometryFlagsKHR::NO_DUPLICATE_ANY_HIT_INVOCATION)],
                        vec![n],
                    ));
                    let sz = ctx.blas_build_sizes(
                        &[crate::accel::BlasGeometry::Aabbs {
                            aabb_count: n,
                            opaque: false,
                        }],
                        AsBuildFlags::default(),
                    )?;
                    sizes.push(BuildSize {
                        result_bytes: sz.acceleration_structure_size_bytes,
                        scratch_bytes: sz.build_scratch_size_bytes,
                    });
                }
                let mut report = ResourceReport::default();
                build_batched(
                    &ctx,
                    &mut self.heap,
                    &mut report,
                    &sizes,
                    vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
                    &self.build_opts,
                    |k| (descs[k].0.clone(), descs[k].1.clone()),
                    |_, _| Ok(()),
                )
            })();
            self.heap.free(buf);
            for (k, a) in r? {
                proxies.push((proxy_items[k].0, a));
            }
        }
        // 2. TLASes over the resident BLASes (inactive where not) plus the proxy instance.
        let instance_bytes: Vec<Vec<u8>> = ids
            .iter()
            .map(|&t| {
                let rec = &view.tlases[t as usize];
                let mut out = Vec::with_capacity((rec.instance_count as usize + 1) * 64);
                for inst in &view.instances
                    [rec.instance_base as usize..(rec.instance_base + rec.instance_count) as usize]
                {
                    let b = inst.blas as usize;
                    let addr = self.blas[b].as_ref().map_or(0, |a| a.address);
                    out.extend_from_slice(&encode_instance(
                        &inst.tlas_from_blas,
                        view.blases[b].kind == BLAS_AABBS,
                        inst.flags & FLAG_NEEDS_ANY_HIT != 0,
                        addr,
                    ));
                }
                if !self.tri_instances[t as usize].is_empty() {
                    let addr = proxies
                        .iter()
                        .find(|(pt, _)| *pt == t)
                        .map_or(0, |(_, a)| a.address);
                    out.extend_from_slice(&encode_instance(&IDENTITY, true, false, addr));
                }
                out
            })
            .collect();
        let mut sizes = Vec::with_capacity(ids.len());
        for bytes in &instance_bytes {
            let s = ctx.tlas_build_sizes((bytes.len() / 64) as u32, AsBuildFlags::default())?;
            sizes.push(BuildSize {
                result_bytes: s.acceleration_structure_size_bytes,
                scratch_bytes: s.build_scratch_size_bytes,
            });
        }
        let total: u64 = instance_bytes.iter().map(|b| b.len() as u64).sum();
        let mut offsets = Vec::with_capacity(ids.len());
        let mut off = 0u64;
        for b in &instance_bytes {
            offsets.push(off);
            off += b.len() as u64;
        }
        let inst_buf = match self.heap.alloc_buffer(
            "stream-tlas-instances",
            total.max(64),
            BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
            AllocKind::InstanceBuffer,
            MemoryClass::DeviceLocal,
            16,
        ) {
            Ok(b) => b,
            Err(e) => {
                proxies
                    .into_iter()
                    .for_each(|(_, a)| a.release(&mut self.heap));
                return Err(e);
            }
        };
        let built = (|| -> Result<Vec<(usize, AccelStruct)>> {
            for (b, &o) in instance_bytes.iter().zip(&offsets) {
                if !b.is_empty() {
                    self.up_mut()?.upload(&ctx, &inst_buf, o, b)?;
                }
            }
            self.up_mut()?.flush(&ctx)?;
            let inst_addr = inst_buf.device_address()?.0;
            let counts: Vec<u32> = instance_bytes
                .iter()
                .map(|b| (b.len() / 64) as u32)
                .collect();
            let mut report = ResourceReport::default();
            build_batched(
                &ctx,
                &mut self.heap,
                &mut report,
                &sizes,
                vk::AccelerationStructureTypeKHR::TOP_LEVEL,
                &self.build_opts,
                |k| {
                    let instances = vk::AccelerationStructureGeometryInstancesDataKHR::default()
                        .array_of_pointers(false)
                        .data(vk::DeviceOrHostAddressConstKHR {
                            device_address: inst_addr + offsets[k],
                        });
                    (
                        vec![vk::AccelerationStructureGeometryKHR::default()
                            .geometry_type(vk::GeometryTypeKHR::INSTANCES)
                            .geometry(vk::AccelerationStructureGeometryDataKHR { instances })],
                        vec![counts[k]],
                    )
                },
                |_, _| Ok(()),
            )
        })();
        self.heap.free(inst_buf);
        let built = match built {
            Ok(b) => b,
            Err(e) => {
                proxies
                    .into_iter()
                    .for_each(|(_, a)| a.release(&mut self.heap));
                return Err(e);
            }
        };
        // 3. Swap in; rewrite the proxy PI slots.
        for (t, pis) in &pi_rewrites {
            let base = u64::from(self.proxy_pi_base[*t as usize]);
            let pis_buf = &self.tables[self.pis_table];
            self.up
                .as_mut()
                .ok_or_else(|| GpuError::InvalidRequest("streaming: staging ring released".into()))?
                .upload(&ctx, pis_buf, base * 80, cast_slice(pis))?;
        }
        self.up_mut()?.flush(&ctx)?;
        for (k, accel) in built {
            let t = ids[k];
            let proxy = proxies
                .iter()
                .position(|(pt, _)| *pt == t)
                .map(|p| proxies.swap_remove(p).1);
            if let Some(old) = self.tlas[t as usize].replace(TlasGpu { accel, proxy }) {
                old.accel.release(&mut self.heap);
                if let Some(p) = old.proxy {
                    p.release(&mut self.heap);
                }
            }
            self.dirty.remove(&t);
        }
        Ok(())
    }

    fn upload_tlas_addresses(&mut self) -> Result<()> {
        use bytemuck::cast_slice;
        let ctx = self.ctx.clone();
        let addrs: Vec<u64> = self
            .tlas
            .iter()
            .map(|t| t.as_ref().map_or(0, |t| t.accel.address))
            .collect();
        let mut mesh_geo = vec![0u64; 2 * self.meshes.len()];
        for (m, g) in self.meshes.iter().enumerate() {
            if let Some(g) = g {
                mesh_geo[2 * m] = g.positions_address;
                mesh_geo[2 * m + 1] = g.indices_address;
            }
        }
        let Some(up) = self.up.as_mut() else {
            return Err(GpuError::InvalidRequest(
                "streaming: staging ring released".into(),
            ));
        };
        if !addrs.is_empty() {
            up.upload(
                &ctx,
                &self.tables[self.tlas_addr_table],
                0,
                cast_slice(&addrs),
            )?;
        }
        if !mesh_geo.is_empty() {
            up.upload(
                &ctx,
                &self.tables[self.mesh_geo_table],
                0,
                cast_slice(&mesh_geo),
            )?;
        }
        up.flush(&ctx)
    }

    fn item_count(&self) -> usize {
        self.view.blases.len() + self.view.tlases.len()
    }

    /// Evicts least-recently-visible unpinned structures (at least `bytes` of them, or all that
    /// are left). Returns false when nothing could be evicted.
    fn evict_some(&mut self, bytes: u64) -> Result<bool> {
        let pins = &self.pinned;
        let pinned = |id: ItemId| pins.get(id.0 as usize).copied().unwrap_or(true);
        let victims = match self
            .residency
            .choose_victims_excluding(bytes.max(1), pinned)
        {
            Ok(v) => v,
            Err(e) if e.evictable_bytes > 0 => self
                .residency
                .choose_victims_excluding(e.evictable_bytes, pinned)
                .unwrap_or_default(),
            Err(_) => Vec::new(),
        };
        if victims.is_empty() {
            return Ok(false);
        }
        for id in victims {
            self.evict(id.0 as usize);
        }
        tracing::debug!(resident = self.residency.len(), "evicted");
        Ok(true)
    }

    /// Releases item `i` (a BLAS with the meshes only it used, or a child TLAS with its proxy);
    /// resident parents of a BLAS become dirty.
    fn evict(&mut self, i: usize) {
        let nb = self.view.blases.len();
        self.residency.remove(ItemId(i as u32));
        self.frame_stats.evicted += 1;
        if i < nb {
            if let Some(a) = self.blas[i].take() {
                a.release(&mut self.heap);
            }
            self.release_blas_meshes(i);
            for &p in &self.parents[i] {
                if self.tlas[p as usize].is_some() {
                    self.dirty.insert(p);
                }
            }
        } else {
            if let Some(t) = self.tlas[i - nb].take() {
                t.accel.release(&mut self.heap);
                if let Some(p) = t.proxy {
                    p.release(&mut self.heap);
                }
            }
            // Also when a failed rebuild left it absent: it is no longer wanted.
            self.dirty.remove(&((i - nb) as u32));
        }
    }

    /// Drops BLAS `b`'s references to its meshes, freeing those no other BLAS holds.
    fn release_blas_meshes(&mut self, b: usize) {
        for g in self.blas_meshes(b) {
            self.mesh_refs[g] = self.mesh_refs[g].saturating_sub(1);
            if self.mesh_refs[g] == 0 {
                if let Some(m) = self.meshes[g].take() {
                    self.heap.free(m.buffer);
                }
            }
        }
    }

    fn blas_meshes(&self, b: usize) -> Vec<usize> {
        let r = &self.view.blases[b];
        if r.kind != BLAS_TRIANGLES {
            return Vec::new();
        }
        self.view.geometries[r.item_base as usize..(r.item_base + r.item_count) as usize]
            .iter()
            .map(|g| g.mesh as usize)
            .collect()
    }

    /// Runs `f`, evicting unpinned structures and retrying while the budget refuses it;
    /// returns the budget error once nothing unpinned is left.
    fn with_eviction<T>(&mut self, mut f: impl FnMut(&mut Self) -> Result<T>) -> Result<T> {
        loop {
            match f(self) {
                Err(GpuError::Budget(msg)) => {
                    let step = (self.build_opts.budget_bytes / 32).max(1);
                    if self.evict_some(step)? {
                        continue;
                    }
                    return Err(GpuError::Budget(msg));
                }
                r => return r,
            }
        }
    }

    /// [`with_eviction`](Self::with_eviction) when `evict`, else `f` once.
    fn maybe_evicting<T>(
        &mut self,
        evict: bool,
        mut f: impl FnMut(&mut Self) -> Result<T>,
    ) -> Result<T> {
        if evict {
            self.with_eviction(f)
        } else {
            f(self)
        }
    }

    /// Streams the meshes of BLASes `group` (each BLAS takes a reference on its meshes) and
    /// builds them, pinned, evicting for room when `evict`. On failure the group's references
    /// and the meshes only it held are released: nothing of it stays resident.
    fn build_group(&mut self, group: &[u32], evict: bool) -> Result<()> {
        let mut taken: Vec<usize> = Vec::new();
        let loaded = (|| -> Result<()> {
            for &b in group {
                for m in self.blas_meshes(b as usize) {
                    // Referenced before loading: evicting a BLAS that shares it keeps it.
                    self.mesh_refs[m] += 1;
                    taken.push(m);
                    if self.meshes[m].is_some() {
                        continue;
                    }
                    let rec = self.view.meshes[m];
                    let g = self.maybe_evicting(evict, |s| MeshGpu::alloc(&mut s.heap, m, &rec))?;
                    let ctx = self.ctx.clone();
                    let source = self.source;
                    let up = self.up_mut()?;
                    let bytes = match g.upload(&ctx, up, source, m) {
                        Ok(n) => n,
                        Err(e) => {
                            // Queued copies into it must land before it is destroyed.
                            let _ = up.flush(&ctx);
                            self.heap.free(g.buffer);
                            return Err(e);
                        }
                    };
                    self.frame_stats.bytes_streamed += bytes;
                    self.meshes[m] = Some(g);
                }
            }
            let ctx = self.ctx.clone();
            self.up_mut()?.flush(&ctx)
        })();
        if loaded.is_err() {
            // Copies still queued for the group's meshes must land before any is freed.
            let ctx = self.ctx.clone();
            if let Some(up) = self.up.as_mut() {
                up.flush(&ctx)?;
            }
        }
        let built = loaded.and_then(|()| {
            let ids: Vec<usize> = group.iter().map(|&b| b as usize).collect();
            self.maybe_evicting(evict, |s| s.build_blas_set(&ids, 0))
        });
        let built = match built {
            Ok(b) => b,
            Err(e) => {
                for m in taken {
                    self.mesh_refs[m] = self.mesh_refs[m].saturating_sub(1);
                    if self.mesh_refs[m] == 0 {
                        if let Some(g) = self.meshes[m].take() {
                            self.heap.free(g.buffer);
                        }
                    }
                }
                return Err(e);
            }
        };
        let mut built_ids = BTreeSet::new();
        for (b, accel) in built {
            let mesh_bytes: u64 = self
                .blas_meshes(b)
                .into_iter()
                .map(|m| self.meshes[m].as_ref().map_or(0, |g| g.size_bytes()))
                .sum();
            let bytes = accel.size_bytes + mesh_bytes;
            self.frame_stats.blas_built += 1;
            self.frame_stats.triangles_built += u64::from(self.view.blases[b].primitive_count);
            self.blas[b] = Some(accel);
            let _ = self
                .residency
                .insert(ItemId(b as u32), bytes, u64::from(self.stamp));
            self.pinned[b] = true;
            self.built_now.push(b as u32);
            built_ids.insert(b as u32);
            for &p in &self.parents[b] {
                if self.tlas[p as usize].is_some() {
                    self.dirty.insert(p);
                }
            }
        }
        // A BLAS with nothing to build keeps no references.
        for &b in group {
            if !built_ids.contains(&b) {
                self.release_blas_meshes(b as usize);
            }
        }
        Ok(())
    }

    /// Builds the BLASes of `queue` (priority order) in groups that halve when the budget
    /// refuses them; groups use free memory only, single BLASes evict for room (so eviction
    /// frees about what one build needs). Stops at the first single BLAS that does not fit
    /// (left for a later pass) and returns how many were left. `must_progress`: when nothing
    /// was built yet, evict the current pass's pins too before giving up, then fail with the
    /// numbers.
    fn build_blas_queue(&mut self, queue: &[u32], must_progress: bool) -> Result<usize> {
        let mut i = 0;
        // Group size carries over between steps: a full budget keeps failing large groups,
        // and each failure streams their meshes for nothing.
        let mut chunk = self.group_hint.clamp(1, 64);
        let mut relaxed = false;
        while i < queue.len() {
            let group = &queue[i..(i + chunk).min(queue.len())];
            match self.build_group(group, group.len() == 1) {
                Ok(()) => {
                    i += group.len();
                    chunk = (chunk * 2).min(64);
                    self.group_hint = chunk;
                }
                Err(GpuError::Budget(_)) if group.len() > 1 => {
                    chunk = group.len() / 2;
                    self.group_hint = chunk;
                }
                Err(GpuError::Budget(msg)) => {
                    if !self.built_now.is_empty() || !must_progress {
                        return Ok(queue.len() - i);
                    }
                    if !relaxed {
                        // Nothing fits next to what the incomplete pixels hold: let those go
                        // (their pixels find them again later) rather than fail.
                        relaxed = true;
                        self.unpin_pass_pins();
                        continue;
                    }
                    return Err(self.does_not_fit(queue[i], &msg));
                }
                Err(e) => return Err(e),
            }
        }
        Ok(0)
    }

    /// The error for BLAS `b` not fitting next to the skeleton alone.
    fn does_not_fit(&self, b: u32, msg: &str) -> GpuError {
        let rec = &self.view.blases[b as usize];
        let mesh_bytes: u64 = self
            .blas_meshes(b as usize)
            .into_iter()
            .map(|m| {
                let r = &self.view.meshes[m];
                u64::from(r.vertex_count) * 12 + u64::from(r.triangle_count) * 12
            })
            .sum();
        let report = self.heap.report();
        GpuError::Budget(format!(
            "streaming: BLAS {b} ({} triangles, {mesh_bytes} bytes of meshes plus its \
             acceleration structure and build scratch) does not fit under the budget of {} \
             bytes even with every other structure evicted: {} bytes stay in use (resident \
             skeleton {} bytes, frame buffers, trace pipeline, staging ring); raise \
             --vram-budget or split the scene's meshes finer ({msg})",
            rec.primitive_count,
            report.budget_bytes,
            report.budget_in_use_bytes,
            self.totals.skeleton_bytes,
        ))
    }

    /// Rebuilds every dirty TLAS. When the budget refuses even with everything unpinned
    /// evicted, gives back structures this step built, least requested first (their pixels
    /// stay incomplete); fails only when none is left.
    fn rebuild_dirty(&mut self) -> Result<()> {
        let mut rounds = 0;
        while !self.dirty.is_empty() {
            rounds += 1;
            if rounds > 64 + self.item_count() {
                return Err(GpuError::InvalidRequest(
                    "streaming: TLAS rebuilds do not settle".into(),
                ));
            }
            let ids: Vec<u32> = self.dirty.iter().copied().collect();
            let rebuilt = ids.len() as u32;
            match self.with_eviction(|s| {
                // Eviction may have given some up (a child TLAS): rebuild what is still dirty.
                let now: Vec<u32> = s.dirty.iter().copied().collect();
                s.build_tlases(&now)
            }) {
                Ok(()) => self.frame_stats.tlas_rebuilt += rebuilt,
                Err(GpuError::Budget(_)) if self.unpin_pass_pins() => {}
                Err(GpuError::Budget(msg)) => {
                    let Some(last) = self.built_now.pop() else {
                        let report = self.heap.report();
                        return Err(GpuError::Budget(format!(
                            "streaming: rebuilding {} TLAS(es) does not fit under the budget of \
                             {} bytes with every evictable structure evicted ({} bytes in use, \
                             skeleton {} bytes); raise --vram-budget ({msg})",
                            ids.len(),
                            report.budget_bytes,
                            report.budget_in_use_bytes,
                            self.totals.skeleton_bytes
                        )));
                    };
                    self.frame_stats.deferred += 1;
                    if self.residency.contains(ItemId(last)) {
                        self.evict(last as usize);
                        // Given back, not evicted for room: count it as deferred only.
                        self.frame_stats.evicted -= 1;
                    }
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// Drops the pins that are not this step's builds (the incomplete pixels' best hits: they
    /// are found again later). Returns false if there were none.
    fn unpin_pass_pins(&mut self) -> bool {
        let mut keep = vec![false; self.pinned.len()];
        for &i in &self.built_now {
            if let Some(k) = keep.get_mut(i as usize) {
                *k = true;
            }
        }
        let changed = self.pinned.iter().zip(&keep).any(|(&p, &k)| p && !k);
        self.pinned = keep;
        changed
    }

    /// Makes `demand` resident (streams meshes, builds BLASes, builds child TLASes), most
    /// requested first, evicting least-recently-visible unpinned structures under the budget;
    /// then rebuilds every dirty TLAS and uploads the tables. `pass_pins`: what the latest
    /// pass's incomplete pixels need (never evicted; a step that cannot build anything next
    /// to them lets them go before failing). `None` prefetches: only structures this frame did
    /// not see may be evicted, and what does not fit is skipped.
    fn make_resident(&mut self, demand: &Demand, pass_pins: Option<&[bool]>) -> Result<()> {
        let t0 = Instant::now();
        let nb = self.view.blases.len();
        let prefetch = pass_pins.is_none();
        self.pinned = match pass_pins {
            Some(p) => p.to_vec(),
            None => {
                let first = self.frame_first_stamp();
                (0..self.item_count())
                    .map(|i| self.last_seen[i] >= first)
                    .collect()
            }
        };
        self.built_now.clear();
        for &(b, _) in &demand.blases {
            self.last_seen[b as usize] = self.stamp;
        }
        for &(t, _) in &demand.tlases {
            self.last_seen[nb + t as usize] = self.stamp;
        }
        // 1. BLASes, most requested first.
        let queue: Vec<u32> = demand
            .blases
            .iter()
            .map(|&(b, _)| b)
            .filter(|&b| self.blas[b as usize].is_none() && self.buildable[b as usize])
            .collect();
        let left = self.build_blas_queue(&queue, !prefetch)?;
        let mut deferred = left;
        // 2. Child TLASes (their parents reach them through the address table).
        let new_tlases: Vec<u32> = demand
            .tlases
            .iter()
            .map(|&(t, _)| t)
            .filter(|&t| self.tlas[t as usize].is_none())
            .collect();
        for (k, &t) in new_tlases.iter().enumerate() {
            match self.with_eviction(|s| s.build_tlases(&[t])) {
                Ok(()) => {
                    let bytes = self.tlas[t as usize].as_ref().map_or(0, |g| {
                        g.accel.size_bytes + g.proxy.as_ref().map_or(0, |p| p.size_bytes)
                    });
                    let item = item_of_tlas(nb, t);
                    let _ = self.residency.insert(item, bytes, u64::from(self.stamp));
                    self.pinned[item.0 as usize] = true;
                    self.built_now.push(item.0);
                    self.frame_stats.tlas_built += 1;
                }
                Err(GpuError::Budget(msg)) => {
                    if self.built_now.is_empty() && !prefetch {
                        let report = self.heap.report();
                        return Err(GpuError::Budget(format!(
                            "streaming: TLAS {t} does not fit under the budget of {} bytes with \
                             every other structure evicted ({} bytes in use, skeleton {} \
                             bytes); raise --vram-budget ({msg})",
                            report.budget_bytes,
                            report.budget_in_use_bytes,
                            self.totals.skeleton_bytes
                        )));
                    }
                    deferred += new_tlases.len() - k;
                    break;
                }
                Err(e) => return Err(e),
            }
        }
        // 3. Parents whose instance set changed (builds or evictions).
        self.rebuild_dirty()?;
        self.upload_tlas_addresses()?;
        if prefetch {
            self.frame_stats.prefetched += self.built_now.len() as u32;
        } else {
            self.frame_stats.deferred += deferred as u32;
        }
        self.frame_stats.build_ms += t0.elapsed().as_secs_f64() * 1e3;
        tracing::debug!(
            demanded = demand.len(),
            built = self.built_now.len(),
            deferred,
            prefetch,
            "build step"
        );
        Ok(())
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

    /// Renders one frame: build–traverse passes until every pixel is complete (or
    /// `max_passes`), then a prefetch of what the guard band saw. `opts.frames` is ignored
    /// (one frame per call: a camera path calls this per frame).
    pub fn render_frame(
        &mut self,
        camera: &CameraParams,
        opts: &RenderOptions,
    ) -> Result<(RenderOutput, FrameStreamStats)> {
        if let Some(why) = &self.poisoned {
            return Err(GpuError::InvalidRequest(format!(
                "streaming renderer unusable after an earlier failure: {why}"
            )));
        }
        let (w, h) = (camera.width, camera.height);
        if w == 0 || h == 0 || w >= 1 << 15 || h >= 1 << 15 {
            return Err(GpuError::InvalidRequest(format!(
                "image size {w}×{h} is invalid for streaming (each side 1 to 32767)"
            )));
        }
        let span = tracing::info_span!(
            "stream_frame",
            frame = self.frame + 1,
            width = w,
            height = h
        );
        let _g = span.enter();
        self.frame += 1;
        self.frame_stats = FrameStreamStats {
            frame: self.frame,
            ..Default::default()
        };
        self.frame_first_stamp = self.stamp + 1;
        let need_tracer =
            !matches!(&self.tracer, Some((b, s, _)) if *b == opts.backend && *s == opts.stack_size);
        if need_tracer {
            if let Some((_, _, t)) = self.tracer.take() {
                t.release(&mut self.heap);
            }
            self.pinned = vec![false; self.item_count()];
            let t = self
                .with_eviction(|s| Tracer::new(&s.ctx.clone(), &mut s.heap, opts))
                .map_err(|e| self.skeleton_error("the trace pipeline", e))?;
            self.tracer = Some((opts.backend, opts.stack_size, t));
        }
        let pixels = u64::from(w) * u64::from(h);
        let guard = guard_pixels(w, h, self.opts.guard_band_px);
        let params = frame_params(camera, opts, self.view.root_tlas);
        self.pinned = vec![false; self.item_count()];
        let nitems = self.item_count() as u64;
        let fb = self
            .with_eviction(|s| {
                alloc_frame_buffers(&mut s.heap, pixels, guard.len() as u64, nitems, &params)
            })
            .map_err(|e| self.skeleton_error("the frame buffers", e))?;
        // Making room for the frame may have evicted BLASes that TLASes still reference.
        if !self.dirty.is_empty() {
            self.built_now.clear();
            if let Err(e) = self
                .rebuild_dirty()
                .and_then(|()| self.upload_tlas_addresses())
            {
                fb.release(&mut self.heap);
                self.quarantine_after_failure(&e);
                return Err(e);
            }
        }
        let result = self.run_passes(&fb, w, h, &guard);
        let out = match result {
            Ok(r) => r,
            Err(e) => {
                fb.release(&mut self.heap);
                return Err(e);
            }
        };
        fb.release(&mut self.heap);
        let (records, rgba_words, counters, guard_demand) = out;
        // Prefetch: what the guard band saw, evicting only what this frame did not see (what
        // does not fit is skipped).
        if !guard_demand.is_empty() && self.frame_stats.complete {
            if let Err(e) = self.make_resident(&guard_demand, None) {
                self.quarantine_after_failure(&e);
                return Err(e);
            }
        }
        let report = self.heap.report();
        let st = &mut self.frame_stats;
        st.resident_blases = self
            .blas
            .iter()
            .zip(&self.buildable)
            .filter(|(b, &ok)| ok && b.is_some())
            .count() as u32;
        st.resident_tlases = self.tlas.iter().filter(|t| t.is_some()).count() as u32;
        st.resident_bytes = self
            .blas
            .iter()
            .flatten()
            .map(|a| a.size_bytes)
            .chain(
                self.tlas
                    .iter()
                    .flatten()
                    .map(|t| t.accel.size_bytes + t.proxy.as_ref().map_or(0, |p| p.size_bytes)),
            )
            .chain(self.meshes.iter().flatten().map(|m| m.size_bytes()))
            .sum();
        st.vram_peak_bytes = report.peak_block_bytes;
        st.vram_budget_bytes = report.budget_bytes;
        let tot = &mut self.totals;
        tot.frames += 1;
        tot.passes += u64::from(st.passes);
        tot.blas_built += u64::from(st.blas_built);
        tot.tlas_built += u64::from(st.tlas_built);
        tot.tlas_rebuilt += u64::from(st.tlas_rebuilt);
        tot.evicted += u64::from(st.evicted);
        tot.deferred += u64::from(st.deferred);
        tot.incomplete_frames += u64::from(!st.complete);
        tot.bytes_streamed += st.bytes_streamed;
        tot.triangles_built += st.triangles_built;
        tot.build_ms += st.build_ms;
        tot.vram_peak_bytes = report.peak_block_bytes;

        let (aov, rgba8, heatmap_max) =
            crate::render::frame_outputs(w, h, records, &rgba_words, opts.view);
        let shadow = u64::from(counters[2]);
        let rays = pixels + self.frame_stats.reshot_pixels + shadow;
        let traces: u64 = aov.records.iter().map(|r| u64::from(r.traces)).sum();
        let ms = self.frame_stats.trace_ms;
        let stats = RenderStats {
            width: w,
            height: h,
            backend: opts.backend.name(),
            view: opts.view,
            frames: 1,
            ms_per_frame: ms,
            rays,
            primary_rays: pixels + self.frame_stats.reshot_pixels,
            shadow_rays: shadow,
            rays_per_second: if ms > 0.0 {
                rays as f64 / (ms / 1e3)
            } else {
                0.0
            },
            traces,
            traces_per_ray: traces as f64 / rays.max(1) as f64,
            stack_size: opts.stack_size,
            stack_overflows: u64::from(counters[0]),
            pi_list_overflows: u64::from(counters[1]),
            heatmap_max,
            as_bytes: self
                .blas
                .iter()
                .flatten()
                .map(|a| a.size_bytes)
                .chain(self.tlas.iter().flatten().map(|t| t.accel.size_bytes))
                .sum(),
            vram_budget_bytes: report.budget_bytes,
            vram_peak_bytes: report.peak_block_bytes,
            allocation_count: report.peak_allocation_count,
            passes: self.frame_stats.passes,
        };
        tracing::info!(
            frame = self.frame,
            passes = self.frame_stats.passes,
            blas_built = self.frame_stats.blas_built,
            evicted = self.frame_stats.evicted,
            "stream frame done"
        );
        Ok((RenderOutput { aov, rgba8, stats }, self.frame_stats.clone()))
    }

    #[allow(clippy::type_complexity)]
    fn run_passes(
        &mut self,
        fb: &FrameBuffers,
        w: u32,
        h: u32,
        guard: &[u32],
    ) -> Result<(Vec<AovRecord>, Vec<u32>, Vec<u32>, Demand)> {
        let nb = self.view.blases.len();
        let nt = self.view.tlases.len();
        let pixels = u64::from(w) * u64::from(h);
        let stamps_bytes = ((nb + nt) * 4) as u64;
        let req_off = stamps_bytes.div_ceil(16) * 16;
        let inc_off = req_off + req_off;
        let final_off = (inc_off + 4 + 4 * pixels).div_ceil(16) * 16;
        let mut full_count = pixels as u32;
        let mut list: Vec<u32> = guard.to_vec();
        self.frame_stats.guard_rays = guard.len() as u64;
        let mut guard_demand = Demand::default();
        loop {
            self.stamp += 1;
            self.frame_stats.passes += 1;
            let first = self.frame_stats.passes == 1;
            fb.pixel_list.write(0, &list)?;
            let sp = StreamParams {
                blas_stamps: self
                    .blas_stamps
                    .as_ref()
                    .map_or(Ok(0), |b| b.device_address().map(|a| a.0))?,
                tlas_stamps: self
                    .tlas_stamps
                    .as_ref()
                    .map_or(Ok(0), |b| b.device_address().map(|a| a.0))?,
                pixel_list: fb.pixel_list.device_address()?.0,
                incomplete: fb.incomplete.device_address()?.0,
                stamp: self.stamp,
                full_count,
                list_count: list.len() as u32,
                blas_count: nb as u32,
                requests: fb.requests.device_address()?.0,
                resume: fb.resume.device_address()?.0,
            };
            fb.stream.write(0, std::slice::from_ref(&sp))?;
            let mut addresses = self.addresses;
            addresses[Slot::Frame as usize] = fb.params.device_address()?.0;
            addresses[Slot::Aov as usize] = fb.aov.device_address()?.0;
            addresses[Slot::Rgba as usize] = fb.rgba.device_address()?.0;
            addresses[Slot::Stats as usize] = fb.stats.device_address()?.0;
            addresses[Slot::Stream as usize] = fb.stream.device_address()?.0;
            let push_bytes: &[u8] = bytemuck::cast_slice(&addresses);
            let n = full_count + list.len() as u32;
            let Some((_, _, tracer)) = &self.tracer else {
                return Err(GpuError::InvalidRequest(
                    "streaming: no trace pipeline".into(),
                ));
            };
            let (dims, groups) = match tracer {
                Tracer::Pipeline(_) => {
                    let width = n.clamp(1, 4096);
                    ([width, n.div_ceil(width).max(1)], None)
                }
                Tracer::Query(_) => {
                    let g = n.div_ceil(64).max(1);
                    ([0, 0], Some([g.min(65535), g.div_ceil(65535)]))
                }
            };
            let t0 = Instant::now();
            let mut rec = self.ctx.record("stream pass")?;
            if first {
                rec.fill_buffer(&fb.stats, 0, (STAT_WORDS * 4) as u64, 0)?;
                rec.fill_buffer(&fb.resume, 0, pixels * 8, 0)?;
            }
            rec.fill_buffer(&fb.incomplete, 0, 4, 0)?;
            rec.fill_buffer(&fb.requests, 0, stamps_bytes.max(4), 0)?;
            rec.barrier();
            tracer.record(&mut rec, push_bytes, dims, groups)?;
            rec.barrier();
            if let (Some(bs), Some(ts)) = (&self.blas_stamps, &self.tlas_stamps) {
                if nb > 0 {
                    rec.copy_buffer(bs, 0, &fb.readback, 0, (nb * 4) as u64)?;
                }
                if nt > 0 {
                    rec.copy_buffer(ts, 0, &fb.readback, (nb * 4) as u64, (nt * 4) as u64)?;
                }
            }
            if nb + nt > 0 {
                rec.copy_buffer(&fb.requests, 0, &fb.readback, req_off, stamps_bytes)?;
            }
            rec.copy_buffer(&fb.incomplete, 0, &fb.readback, inc_off, 4 + 4 * pixels)?;
            rec.submit_and_wait()?;
            self.frame_stats.trace_ms += t0.elapsed().as_secs_f64() * 1e3;
            let stamps: Vec<u32> = fb.readback.read_vec(0, nb + nt)?;
            let requests: Vec<u32> = fb.readback.read_vec(req_off, nb + nt)?;
            let count = fb
                .readback
                .read_vec::<u32>(inc_off, 1)?
                .first()
                .copied()
                .unwrap_or(0);
            let count = count.min(pixels as u32);
            let incomplete: Vec<u32> = fb.readback.read_vec(inc_off + 4, count as usize)?;
            // Visible sets: resident ones refresh their LRU age and are pinned when an
            // incomplete pixel needs them (its best hit so far; every walked TLAS); empty ones
            // are demanded (a real pixel needs them) or prefetched (only seen).
            let mut demand = Demand::default();
            let mut pass_pins = vec![false; nb + nt];
            for (i, &v) in stamps.iter().enumerate() {
                if v >> 1 != self.stamp {
                    continue;
                }
                self.last_seen[i] = self.stamp;
                let needed = v & 1 == 1;
                let (resident, wanted) = if i < nb {
                    (self.blas[i].is_some(), self.buildable[i])
                } else {
                    let t = (i - nb) as u32;
                    (self.tlas[t as usize].is_some(), t != self.view.root_tlas)
                };
                if resident {
                    if i >= nb || self.buildable[i] {
                        self.residency
                            .mark_visible(ItemId(i as u32), u64::from(self.stamp));
                        pass_pins[i] = needed || i >= nb;
                    }
                    continue;
                }
                if !wanted {
                    continue;
                }
                let set = if needed {
                    &mut demand
                } else if first {
                    &mut guard_demand
                } else {
                    continue;
                };
                let n = requests.get(i).copied().unwrap_or(0);
                if i < nb {
                    set.blases.push((i as u32, n));
                } else {
                    set.tlases.push(((i - nb) as u32, n));
                }
            }
            demand.sort();
            if count == 0 {
                self.frame_stats.complete = true;
                break;
            }
            if self.frame_stats.passes >= self.opts.max_passes.max(1) {
                self.frame_stats.incomplete_pixels = u64::from(count);
                tracing::warn!(
                    incomplete = count,
                    passes = self.frame_stats.passes,
                    "stream pass cap reached: remaining pixels are rendered as misses"
                );
                list = incomplete;
                break;
            }
            if let Err(e) = self.make_resident(&demand, Some(&pass_pins)) {
                self.quarantine_after_failure(&e);
                return Err(e);
            }
            self.frame_stats.reshot_pixels += u64::from(count);
            full_count = 0;
            list = incomplete
                .iter()
                .map(|&v| {
                    let (x, y) = ((v & 0xffff) as i32, (v >> 16) as i32);
                    pack_biased(x, y)
                })
                .collect();
        }
        // Final readback of the image.
        guard_demand.sort();
        let mut rec = self.ctx.record("stream readback")?;
        rec.copy_buffer(&fb.aov, 0, &fb.readback, final_off, pixels * 16)?;
        rec.copy_buffer(
            &fb.rgba,
            0,
            &fb.readback,
            final_off + pixels * 16,
            pixels * 4,
        )?;
        rec.copy_buffer(
            &fb.stats,
            0,
            &fb.readback,
            final_off + pixels * 20,
            (STAT_WORDS * 4) as u64,
        )?;
        rec.submit_and_wait()?;
        let mut records: Vec<AovRecord> = fb.readback.read_vec(final_off, pixels as usize)?;
        let mut rgba: Vec<u32> = fb
            .readback
            .read_vec(final_off + pixels * 16, pixels as usize)?;
        let counters: Vec<u32> = fb.readback.read_vec(final_off + pixels * 20, STAT_WORDS)?;
        if !self.frame_stats.complete {
            // Never written: misses, magenta so they are not mistaken for sky.
            // `list` holds the last pass's incomplete pixels, unbiased.
            for &v in &list {
                let (x, y) = (v & 0xffff, v >> 16);
                if x < w && y < h {
                    let i = y as usize * w as usize + x as usize;
                    records[i] = AovRecord::MISS;
                    rgba[i] = 0xFFFF_00FF;
                }
            }
        }
        Ok((records, rgba, counters, guard_demand))
    }

    /// After a failed build step, TLASes still referencing evicted BLASes must never be traced:
    /// child ones are evicted (they become empty); a dirty root poisons the renderer.
    fn quarantine_after_failure(&mut self, e: &GpuError) {
        let nb = self.view.blases.len();
        let dirty: Vec<u32> = std::mem::take(&mut self.dirty).into_iter().collect();
        for t in dirty {
            if t == self.view.root_tlas {
                self.poisoned = Some(e.to_string());
                continue;
            }
            if let Some(g) = self.tlas[t as usize].take() {
                g.accel.release(&mut self.heap);
                if let Some(p) = g.proxy {
                    p.release(&mut self.heap);
                }
                self.residency.remove(item_of_tlas(nb, t));
            }
        }
        if self.poisoned.is_none() {
            let _ = self.upload_tlas_addresses();
        }
    }
}

fn proxy_pi(blas: u32, b: &[f32; 6]) -> PiRecord {
    PiRecord {
        child_from_parent: [0.0; 12],
        aabb_min: [b[0], b[1], b[2]],
        kind: PI_EMPTY_BLAS,
        aabb_max: [b[3], b[4], b[5]],
        target: blas,
    }
}

/// Packs image coordinates (possibly outside the image) for the pass's pixel list.
fn pack_biased(x: i32, y: i32) -> u32 {
    let bx = (x + GUARD_BIAS).clamp(0, 0xffff) as u32;
    let by = (y + GUARD_BIAS).clamp(0, 0xffff) as u32;
    bx | (by << 16)
}

/// Every other pixel of a `band`-pixel ring around a `w × h` image (primary rays only).
fn guard_pixels(w: u32, h: u32, band: u32) -> Vec<u32> {
    let band = band.min(GUARD_BIAS as u32 / 2) as i32;
    if band == 0 {
        return Vec::new();
    }
    let (w, h) = (w as i32, h as i32);
    let mut out = Vec::new();
    let mut y = -band;
    while y < h + band {
        let mut x = -band;
        while x < w + band {
            if x < 0 || y < 0 || x >= w || y >= h {
                out.push(pack_biased(x, y));
            }
            x += 2;
        }
        y += 2;
    }
    out
}

fn alloc_frame_buffers(
    heap: &mut GpuHeap,
    pixels: u64,
    guard_count: u64,
    items: u64,
    params: &crate::render::FrameParams,
) -> Result<FrameBuffers> {
    let dev = BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS | BufferUsage::TRANSFER_SRC;
    let host = BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS;
    let stamps_bytes = (items * 4).div_ceil(16) * 16;
    let inc_bytes = 4 + 4 * pixels;
    let readback_bytes =
        (2 * stamps_bytes + inc_bytes).div_ceil(16) * 16 + pixels * 20 + (STAT_WORDS * 4) as u64;
    let specs: [(&str, u64, BufferUsage, AllocKind, MemoryClass); 10] = [
        (
            "frame-params",
            std::mem::size_of::<crate::render::FrameParams>() as u64,
            host,
            AllocKind::Other,
            MemoryClass::HostVisible,
        ),
        (
            "stream-params",
            std::mem::size_of::<StreamParams>() as u64,
            host,
            AllocKind::Other,
            MemoryClass::HostVisible,
        ),
        (
            "aov",
            pixels * 16,
            dev,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "rgba",
            pixels * 4,
            dev,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "stats",
            (STAT_WORDS * 4) as u64,
            dev | BufferUsage::TRANSFER_DST,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "incomplete",
            inc_bytes,
            dev | BufferUsage::TRANSFER_DST,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "requests",
            (items * 4).max(4),
            dev | BufferUsage::TRANSFER_DST,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "resume",
            pixels * 8,
            dev | BufferUsage::TRANSFER_DST,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "pixel-list",
            4 * pixels.max(guard_count).max(1),
            host,
            AllocKind::Other,
            MemoryClass::HostVisible,
        ),
        (
            "stream-readback",
            readback_bytes,
            BufferUsage::TRANSFER_DST,
            AllocKind::Staging,
            MemoryClass::HostVisible,
        ),
    ];
    let mut bufs: Vec<HeapBuffer> = Vec::with_capacity(specs.len());
    for (label, size, usage, kind, class) in specs {
        match heap.alloc_buffer(label, size, usage, kind, class, 16) {
            Ok(b) => bufs.push(b),
            Err(e) => {
                bufs.into_iter().for_each(|b| heap.free(b));
                return Err(e);
            }
        }
    }
    bufs[0].write(0, std::slice::from_ref(params))?;
    let mut it = bufs.into_iter();
    let mut next = || {
        it.next()
            .ok_or_else(|| GpuError::InvalidRequest("frame buffers".into()))
    };
    Ok(FrameBuffers {
        params: next()?,
        stream: next()?,
        aov: next()?,
        rgba: next()?,
        stats: next()?,
        incomplete: next()?,
        requests: next()?,
        resume: next()?,
        pixel_list: next()?,
        readback: next()?,
    })
}
