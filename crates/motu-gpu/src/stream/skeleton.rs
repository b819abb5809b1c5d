//! The resident skeleton: node tables (GPU copies with proxy instances), stamps, PI BLASes and
//! the root TLAS, built once by [`StreamingRenderer::new`]; the address tables rewritten as
//! structures come and go.

use std::collections::BTreeSet;

use motu_abi::{
    BlasRecord, HierarchyView, InstanceRecord, PiRecord, TlasRecord, BLAS_AABBS, NONE_U32,
};
use motu_alloc::{AllocKind, AllocLimits, MemoryClass, Residency, MIB};
use motu_vk::{BufferUsage, Context, GpuHeap};

use super::persistent::{auto_persistent, persistent_estimate, persistent_records, TlasUpdate};
use super::proxy_boxes::padded;
use super::PI_EMPTY_BLAS;
use super::{
    FrameStreamStats, MeshMemory, StreamOptions, StreamTotals, StreamingRenderer, IDENTITY,
};
use crate::error::{GpuError, Result};
use crate::scene::{upload_node_table, BuildOptions, MeshBlobSource, Slot, Uploader, SLOT_COUNT};

pub(super) fn transformed_box(m: &[f32; 12], lo: [f32; 3], hi: [f32; 3]) -> [f32; 6] {
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

/// Triangle instances of one BLAS per proxy box at most. One box per instance made the
/// resident skeleton (proxy BLAS, PI records, and the TLAS sized for every instance) grow with
/// the instance count: 26 MB of the default island's 46 MB floor. A box over a cluster of
/// neighbouring instances of the same BLAS stays exact where it matters (the BLAS is open for a
/// ray that enters the box, a superset of the rays that could hit an instance) and only costs
/// a build when a ray passes between the instances before the BLAS was walked.
pub(super) const PROXY_CLUSTER_INSTANCES: usize = 16;

/// One proxy box: a spatially coherent cluster of a TLAS's instances of one triangle BLAS.
#[derive(Clone, Debug)]
pub(super) struct ProxyCluster {
    pub blas: u32,
    /// `[min, max]` in the TLAS's space: the union of the instances' transformed BLAS bounds.
    pub bounds: [f32; 6],
    /// The member instances: indices in the TLAS's instance range (= their custom index).
    pub members: Vec<u32>,
    /// Where `members` start in the GPU member table (global instance-table indices): a ray
    /// that enters the box tests the members' boxes, so a BLAS is demanded only by rays that
    /// enter one of its instances' boxes (set by [`StreamingRenderer::new`]).
    pub member_first: u32,
}

/// The proxy clusters of TLAS `t`: its instances of each buildable BLAS, cut by the compiler's
/// binned SAH over instance bounds into pieces of at most [`PROXY_CLUSTER_INSTANCES`], in BLAS
/// order. Deterministic: the renderer and the floor ([`super::streaming_floor`]) both call it.
pub(super) fn proxy_clusters(
    view: &HierarchyView<'_>,
    t: usize,
    buildable: impl Fn(usize) -> bool,
) -> Vec<ProxyCluster> {
    let rec = &view.tlases[t];
    type Bounds = ([f32; 3], [f32; 3]);
    let mut by_blas: std::collections::BTreeMap<u32, (Vec<u32>, Vec<Bounds>)> = Default::default();
    for (local, inst) in view.instances[rec.instance_range()].iter().enumerate() {
        let b = inst.blas as usize;
        if !buildable(b) {
            continue;
        }
        let br = &view.blases[b];
        let x = transformed_box(&inst.tlas_from_blas, br.bounds_min, br.bounds_max);
        let entry = by_blas.entry(inst.blas).or_default();
        entry.0.push(local as u32);
        entry.1.push(([x[0], x[1], x[2]], [x[3], x[4], x[5]]));
    }
    let mut out = Vec::new();
    let mut ranges = Vec::new();
    for (blas, (mut items, mut bounds)) in by_blas {
        ranges.clear();
        motu_compile::sah_partition(
            &mut items,
            &mut bounds,
            PROXY_CLUSTER_INSTANCES,
            &mut ranges,
        );
        for &(begin, end) in &ranges {
            let mut b = [
                f32::INFINITY,
                f32::INFINITY,
                f32::INFINITY,
                -f32::INFINITY,
                -f32::INFINITY,
                -f32::INFINITY,
            ];
            for (lo, hi) in &bounds[begin..end] {
                for a in 0..3 {
                    b[a] = b[a].min(lo[a]);
                    b[3 + a] = b[3 + a].max(hi[a]);
                }
            }
            out.push(ProxyCluster {
                blas,
                bounds: padded(b),
                members: items[begin..end].to_vec(),
                member_first: 0,
            });
        }
    }
    out
}

/// What the floor ([`super::streaming_floor_planned`]) and the renderer
/// ([`StreamingRenderer::with_plan`]) both derive from a view before anything is built: the
/// proxy clusters of every TLAS (binned SAH over millions of instances: seconds at island
/// scale, so made once per render, the TLASes in parallel).
pub struct StreamPlan {
    pub(super) clusters: Vec<Vec<ProxyCluster>>,
    instances: usize,
}

impl StreamPlan {
    pub fn new(view: &HierarchyView<'_>) -> StreamPlan {
        use rayon::prelude::*;
        let _span = tracing::info_span!("proxy_clusters", tlases = view.tlases.len()).entered();
        let buildable = |b: usize| super::streamable(&view.blases[b]);
        let clusters = (0..view.tlases.len())
            .into_par_iter()
            .map(|t| proxy_clusters(view, t, buildable))
            .collect();
        StreamPlan {
            clusters,
            instances: view.instances.len(),
        }
    }

    /// A plan made for another view is a caller's mistake, refused rather than trusted.
    pub(super) fn check(&self, view: &HierarchyView<'_>) -> Result<()> {
        if self.clusters.len() != view.tlases.len() || self.instances != view.instances.len() {
            return Err(GpuError::InvalidRequest(format!(
                "streaming: a plan of {} TLASes and {} instances for a view of {} and {}",
                self.clusters.len(),
                self.instances,
                view.tlases.len(),
                view.instances.len()
            )));
        }
        Ok(())
    }
}

impl<'a> StreamingRenderer<'a> {
    /// Uploads the skeleton (tables, PI BLASes, the root TLAS with its proxy) under the budget.
    pub fn new(
        ctx: &Context,
        view: HierarchyView<'a>,
        source: &'a dyn MeshBlobSource,
        opts: &StreamOptions,
    ) -> Result<StreamingRenderer<'a>> {
        let plan = StreamPlan::new(&view);
        Self::with_plan(ctx, view, plan, source, opts)
    }

    /// [`Self::new`] with the proxy clusters already made (`plan`, of this `view`, as the
    /// floor used them).
    pub fn with_plan(
        ctx: &Context,
        view: HierarchyView<'a>,
        plan: StreamPlan,
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
        plan.check(&view)?;
        let too_many = |what: &str| GpuError::InvalidRequest(format!("streaming: too many {what}"));
        let budget = crate::scene::usable_budget_bytes(ctx, opts.budget_bytes)?;
        // Staging and scratch come out of the budget (staging does on unified memory): an
        // eighth (scratch) and a 32nd (staging) at most, so small budgets leave room for the
        // structures themselves.
        let opts = &StreamOptions {
            staging_bytes: crate::scene::staging_bytes_for_budget(budget, opts.staging_bytes),
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
            // Staging and readback, and the persistent TLASes' instance records (host memory
            // their builds and updates read; dedicated blocks, beside two standard blocks of
            // the others' partly used space).
            host_visible_budget_bytes: opts.staging_bytes.max(64 * MIB) * 4
                + if opts.tlas_update == TlasUpdate::Rebuild {
                    0
                } else {
                    view.tlases
                        .iter()
                        .map(|t| {
                            u64::from(persistent_records(t.instance_count))
                                * super::tlas_records::RECORD_BYTES as u64
                        })
                        .sum::<u64>()
                        + 2 * crate::scene::block_bytes_for_budget(budget)
                }
                // Meshes in host memory: at most every mesh at once, twice over for the free
                // space their comings and goings strand in shared blocks (a cap, not a
                // reservation: blocks are made as meshes arrive).
                + if opts.mesh_memory == MeshMemory::Device {
                    0
                } else {
                    2 * super::streamed_mesh_total_bytes(&view)
                        + 4 * crate::scene::block_bytes_for_budget(budget)
                },
        };
        let block = crate::scene::block_bytes_for_budget(budget);
        // Structures, meshes and their transients come and go in sizes up to about a block:
        // from half a block each gets its own (freed whole when evicted), or the free space
        // they strand inside shared blocks, up to a quarter of the budget, fits nothing.
        let heap = GpuHeap::with_blocks(ctx, limits, Some(block), Some(block / 2))?;
        let host_counts = heap.host_visible_counts_against_budget();
        let mesh_class = match opts.mesh_memory {
            MeshMemory::Device => MemoryClass::DeviceLocal,
            MeshMemory::Host => MemoryClass::HostVisible,
            MeshMemory::Auto if host_counts => MemoryClass::DeviceLocal,
            MeshMemory::Auto => MemoryClass::HostVisible,
        };
        let meshes_budgeted = mesh_class == MemoryClass::DeviceLocal || host_counts;
        let nb = view.blases.len();
        let nt = view.tlases.len();

        // Derived structure: proxy clusters per TLAS, parents per BLAS, proxy ids.
        let t_derived = std::time::Instant::now();
        let buildable: Vec<bool> = view.blases.iter().map(super::streamable).collect();
        let mut parents: Vec<Vec<u32>> = vec![Vec::new(); nb];
        let mut parent_counts: Vec<Vec<u32>> = vec![Vec::new(); nb];
        for (t, rec) in view.tlases.iter().enumerate() {
            for inst in &view.instances[rec.instance_range()] {
                let b = inst.blas as usize;
                match parents[b].iter().position(|&p| p == t as u32) {
                    Some(k) => parent_counts[b][k] += 1,
                    None => {
                        parents[b].push(t as u32);
                        parent_counts[b].push(1);
                    }
                }
            }
        }
        let mut clusters = plan.clusters;
        // The member table: per cluster, its instances' global indices in the GPU instance
        // table (each TLAS's range there starts at the running total of the ranges before it,
        // each grown by its proxy instance).
        let mut members: Vec<u32> = Vec::new();
        let mut gpu_base = 0u32;
        for (t, rec) in view.tlases.iter().enumerate() {
            for c in &mut clusters[t] {
                c.member_first = u32::try_from(members.len()).map_err(|_| too_many("instances"))?;
                members.extend(c.members.iter().map(|&local| gpu_base + local));
            }
            let grown = rec.instance_count + 2 * u32::from(!clusters[t].is_empty());
            gpu_base = gpu_base
                .checked_add(grown)
                .ok_or_else(|| too_many("instances"))?;
        }
        // GPU tables: TLAS ranges grow by the proxy and marks instances; proxy and marks
        // BLAS records and PI slots (one per cluster, shared: non-resident clusters first,
        // then resident ones, rewritten with each rebuild) follow the originals.
        let mut gpu_tlases: Vec<TlasRecord> = Vec::with_capacity(nt);
        let mut gpu_instances: Vec<InstanceRecord> = Vec::with_capacity(view.instances.len() + nt);
        let mut gpu_blases: Vec<BlasRecord> = view.blases.to_vec();
        let mut gpu_pis: Vec<PiRecord> = view.pis.to_vec();
        let mut proxy_pi_base = vec![NONE_U32; nt];
        let mut marks_blas = vec![NONE_U32; nt];
        for (t, rec) in view.tlases.iter().enumerate() {
            let base = u32::try_from(gpu_instances.len()).map_err(|_| too_many("instances"))?;
            let range = rec.instance_range();
            gpu_instances.extend_from_slice(&view.instances[range]);
            let mut count = rec.instance_count;
            if !clusters[t].is_empty() {
                let pi_base = u32::try_from(gpu_pis.len()).map_err(|_| too_many("PIs"))?;
                let blas_id = u32::try_from(gpu_blases.len()).map_err(|_| too_many("BLASes"))?;
                proxy_pi_base[t] = pi_base;
                for c in &clusters[t] {
                    gpu_pis.push(proxy_pi(c));
                }
                let n = clusters[t].len() as u32;
                // The proxy (non-resident clusters), then the marks (resident ones: none yet).
                gpu_blases.push(proxy_blas_record(rec, pi_base, n));
                gpu_blases.push(proxy_blas_record(rec, pi_base + n, 0));
                marks_blas[t] = blas_id + 1;
                for id in [blas_id, blas_id + 1] {
                    gpu_instances.push(InstanceRecord {
                        tlas_from_blas: IDENTITY,
                        blas: id,
                        flags: 0,
                        element: NONE_U32,
                        _pad: 0,
                    });
                }
                count += 2;
            }
            gpu_tlases.push(TlasRecord {
                instance_base: base,
                instance_count: count,
                // No box lists: streamed TLASes keep every PI (and proxy) in the hardware walk.
                box_list_instances: 0,
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
            blas_build: opts.blas_build,
        };
        let scene_triangles = view
            .blases
            .iter()
            .zip(&buildable)
            .filter(|(_, &ok)| ok)
            .map(|(b, _)| u64::from(b.primitive_count))
            .sum();
        let has_clusters: Vec<bool> = clusters.iter().map(|c| !c.is_empty()).collect();
        let derived_ms = ms_since(t_derived);
        let mut r = StreamingRenderer {
            blas: (0..nb).map(|_| None).collect(),
            placeholders: Default::default(),
            persistent_mode: vec![false; nt],
            tlas: (0..nt).map(|_| None).collect(),
            meshes: (0..view.meshes.len()).map(|_| None).collect(),
            mesh_refs: vec![0; view.meshes.len()],
            mesh_class,
            meshes_budgeted,
            tables: Vec::new(),
            blas_stamps: None,
            walked_buf: None,
            walked: vec![0; nb],
            up: None,
            tracer: None,
            heap,
            addresses: [0; SLOT_COUNT],
            pis_table: 0,
            mesh_geo_table: 0,
            tlas_addr_table: 0,
            cluster_members: 0,
            proxy_box_index: 0,
            proxy_boxes: 0,
            shading: Default::default(),
            view,
            source,
            opts: *opts,
            build_opts,
            clusters,
            proxy_pi_base,
            marks_blas,
            blases_table: 0,
            parents,
            parent_counts,
            buildable,
            residency: Residency::new(),
            last_seen: vec![0; nb + nt],
            blas_bytes: vec![0; nb],
            used_in_frame: vec![0; nb],
            dirty: BTreeSet::new(),
            pinned: vec![false; nb + nt],
            built_now: Vec::new(),
            group_hint: 16,
            stamp: 0,
            frame_first_stamp: 1,
            pass_marks_held: 0,
            next_camera: None,
            probe_sighting: Vec::new(),
            probe_need: Default::default(),
            evictions: 0,
            poisoned: None,
            reuse: super::cache::Reuse::new(nb),
            frame: 0,
            kept: Default::default(),
            frame_stats: FrameStreamStats::default(),
            totals: StreamTotals {
                scene_triangles,
                vram_budget_bytes: budget,
                mesh_memory: match mesh_class {
                    MemoryClass::DeviceLocal => "device",
                    MemoryClass::HostVisible => "host",
                },
                meshes_budgeted,
                host_memory_counted: host_counts,
                derived_ms,
                ..Default::default()
            },
            ctx: ctx.clone(),
        };
        let t_persistent = std::time::Instant::now();
        r.persistent_mode = r.choose_persistent(&has_clusters)?;
        r.totals.persistent_choice_ms = ms_since(t_persistent);
        let t_boxes = std::time::Instant::now();
        let (box_index, box_count) = super::proxy_boxes::layout(&view, |b| r.buildable[b]);
        let boxes = super::proxy_boxes::compute(&view, source, &box_index, box_count);
        r.totals.proxy_boxes = boxes.len() as u64;
        r.totals.proxy_boxes_ms = t_boxes.elapsed().as_secs_f64() * 1e3;
        tracing::info!(
            boxes = r.totals.proxy_boxes,
            ms = r.totals.proxy_boxes_ms,
            "boxes inside streamable BLASes made from their meshes"
        );
        let t_skeleton = std::time::Instant::now();
        r.init_skeleton(
            &gpu_tlases,
            &gpu_instances,
            &gpu_blases,
            &gpu_pis,
            &members,
            (&box_index, &boxes),
        )?;
        r.totals.skeleton_ms = ms_since(t_skeleton);
        let report = r.heap.report();
        r.totals.skeleton_bytes = report.budget_in_use_bytes;
        tracing::info!(
            skeleton_bytes = r.totals.skeleton_bytes,
            budget_bytes = budget,
            derived_ms = r.totals.derived_ms,
            persistent_choice_ms = r.totals.persistent_choice_ms,
            skeleton_ms = r.totals.skeleton_ms,
            scene_triangles,
            "streaming skeleton resident"
        );
        Ok(r)
    }

    /// Which TLASes are persistent (`StreamOptions::tlas_update`): with `Auto`, all the
    /// candidates when they are large and their structures at full residency, update
    /// scratch, placeholders (and records where host memory counts) take a small share of
    /// the budget (`auto_persistent`), else none (a rebuild then holds only what is
    /// resident, which small budgets need).
    fn choose_persistent(&self, has_clusters: &[bool]) -> Result<Vec<bool>> {
        let mut mode = vec![false; self.view.tlases.len()];
        if self.opts.tlas_update == TlasUpdate::Rebuild {
            return Ok(mode);
        }
        let ctx = self.ctx.clone();
        let (candidates, estimate) = persistent_estimate(
            &self.view,
            has_clusters,
            ctx.limits().max_instance_count,
            self.heap.host_visible_counts_against_budget(),
            self.placeholder_build_size()?.result_bytes,
            |n| super::FloorSizes::tlas_updatable(&ctx, n),
        )?;
        if candidates.is_empty() {
            return Ok(mode);
        }
        let budget = self.build_opts.budget_bytes;
        let on = match self.opts.tlas_update {
            TlasUpdate::Update => true,
            _ => auto_persistent(estimate.instances, estimate.bytes, budget),
        };
        tracing::info!(
            candidates = candidates.len(),
            instances = estimate.instances,
            bytes = estimate.bytes,
            budget,
            on,
            "persistent TLASes (updated, not rebuilt)"
        );
        if on {
            for t in candidates {
                mode[t as usize] = true;
            }
        }
        Ok(mode)
    }

    /// Allocates a device-local table for `bytes`, queues its upload and keeps it in
    /// `tables`; returns its device address.
    fn upload_table(&mut self, ctx: &Context, label: &str, bytes: &[u8]) -> Result<u64> {
        let up = self.up.as_mut().ok_or_else(staging_released)?;
        let (buf, address) = upload_node_table(ctx, &mut self.heap, up, label, bytes)?;
        self.tables.push(buf);
        Ok(address)
    }

    pub(super) fn init_skeleton(
        &mut self,
        gpu_tlases: &[TlasRecord],
        gpu_instances: &[InstanceRecord],
        gpu_blases: &[BlasRecord],
        gpu_pis: &[PiRecord],
        cluster_members: &[u32],
        (box_index, boxes): (&[[u32; 2]], &[super::proxy_boxes::Box6]),
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
            match slot {
                Slot::Pis => self.pis_table = self.tables.len(),
                Slot::Blases => self.blases_table = self.tables.len(),
                Slot::MeshGeo => self.mesh_geo_table = self.tables.len(),
                Slot::TlasAddresses => self.tlas_addr_table = self.tables.len(),
                _ => {}
            }
            self.addresses[slot as usize] =
                self.upload_table(&ctx, &format!("stream-table-{slot:?}"), bytes)?;
        }
        if !cluster_members.is_empty() {
            self.cluster_members =
                self.upload_table(&ctx, "stream-cluster-members", cast_slice(cluster_members))?;
        }
        if !boxes.is_empty() {
            self.proxy_box_index =
                self.upload_table(&ctx, "stream-proxy-box-index", cast_slice(box_index))?;
            self.proxy_boxes = self.upload_table(&ctx, "stream-proxy-boxes", cast_slice(boxes))?;
        }
        let stamp_usage = BufferUsage::STORAGE
            | BufferUsage::DEVICE_ADDRESS
            | BufferUsage::TRANSFER_SRC
            | BufferUsage::TRANSFER_DST;
        let stamp_bytes = (view.blases.len().max(1) * 4) as u64;
        let buf = self.heap.alloc_buffer(
            "blas-stamps",
            stamp_bytes,
            stamp_usage,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
            16,
        )?;
        let mut rec = ctx.record("clear stamps")?;
        rec.fill_buffer(&buf, 0, stamp_bytes, 0)?;
        rec.submit_and_wait()?;
        self.blas_stamps = Some(buf);
        // Written by the host before each pass (which BLASes that pass walks).
        let walked = self.heap.alloc_buffer(
            "blas-walked",
            stamp_bytes,
            BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
            AllocKind::Other,
            MemoryClass::HostVisible,
            16,
        )?;
        walked.write(0, &vec![0u32; view.blases.len().max(1)])?;
        self.walked_buf = Some(walked);
        self.init_shading()?;
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
        // Every TLAS (no triangle instance resident: only their proxy boxes and PI instances):
        // TLASes are never evicted, so a ray reaches every BLAS box and only BLASes stream.
        let all: Vec<u32> = (0..view.tlases.len() as u32).collect();
        if self.persistent_mode.iter().any(|&p| p) {
            self.build_placeholders()?;
        }
        loop {
            let persistent = self.persistent_mode.iter().filter(|&&p| p).count();
            match self.build_tlases(&all) {
                Ok(()) => break,
                // A persistent TLAS that did not fit is rebuilt instead: try again.
                Err(GpuError::Budget(_))
                    if self.persistent_mode.iter().filter(|&&p| p).count() < persistent => {}
                Err(e) => return Err(e),
            }
        }
        // The persistent TLASes' first updates ran: the whole-bounds placeholders are unused.
        self.placeholders.release_full(&mut self.heap);
        if !self.persistent_mode.iter().any(|&p| p) {
            self.placeholders.release(&mut self.heap);
        }
        let host_counts = self.heap.host_visible_counts_against_budget();
        self.totals.persistent_tlases = self.persistent_mode.iter().filter(|&&p| p).count() as u32;
        self.totals.tlas_mode = if self.totals.persistent_tlases > 0 {
            "update"
        } else {
            "rebuild"
        };
        self.totals.persistent_tlas_bytes = self
            .tlas
            .iter()
            .flatten()
            .filter_map(|g| {
                Some(g.accel.size_bytes + g.persistent.as_ref()?.size_bytes(host_counts))
            })
            .sum::<u64>()
            + self.placeholders.bytes;
        self.upload_tlas_addresses()?;
        Ok(())
    }

    pub(super) fn up_mut(&mut self) -> Result<&mut Uploader> {
        self.up.as_mut().ok_or_else(staging_released)
    }

    pub(super) fn upload_tlas_addresses(&mut self) -> Result<()> {
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
        self.queue_mesh_attrs()?;
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
}

/// The GPU BLAS record of TLAS `rec`'s proxy or marks BLAS: `n` PI slots from `item_base`.
pub(super) fn proxy_blas_record(rec: &TlasRecord, item_base: u32, n: u32) -> BlasRecord {
    BlasRecord {
        kind: BLAS_AABBS,
        item_base,
        item_count: n,
        level: rec.level + 1,
        bounds_min: rec.bounds_min,
        primitive_count: n,
        bounds_max: rec.bounds_max,
        _pad: 0,
    }
}

/// The PI record of cluster `c`'s proxy box. A proxy has no child transform: its first two
/// words (`child_from_parent[0..2]`, read as u32 by `candidates.glsl`'s `record_proxy`)
/// carry the cluster's member range in the member table.
pub(super) fn proxy_pi(c: &ProxyCluster) -> PiRecord {
    let b = &c.bounds;
    let mut child_from_parent = [0.0f32; 12];
    child_from_parent[0] = f32::from_bits(c.member_first);
    child_from_parent[1] = f32::from_bits(c.members.len() as u32);
    PiRecord {
        child_from_parent,
        aabb_min: [b[0], b[1], b[2]],
        kind: PI_EMPTY_BLAS,
        aabb_max: [b[3], b[4], b[5]],
        target: c.blas,
    }
}

pub(super) fn staging_released() -> GpuError {
    GpuError::InvalidRequest("streaming: staging ring released".into())
}

fn ms_since(t: std::time::Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
