//! A compiled hierarchy on the GPU: tables, geometry and acceleration structures, built under a
//! VRAM budget, an allocation-count cap and a scratch budget.
//!
//! Build order: node tables are uploaded through a bounded host-visible staging ring; BLASes
//! (one per `BlasRecord`: triangles, one geometry per mesh, or the AABBs of its programmable
//! instances) are built in batches planned by `motu_alloc::plan_build_batches` with one shared
//! scratch pool. Uploads and builds are pipelined: batch k's mesh copies (from one half of the
//! ring), a `TRANSFER → ACCELERATION_STRUCTURE_BUILD` barrier and its builds go in one
//! submission that is not waited on while the CPU loads, checks and stages batch k+1's meshes
//! into the other half; batch k's fence is waited on only before its compacted sizes are read
//! (no queue-wait-idle). Each batch is then compacted (sizes queried, copied, originals freed)
//! before the next, so the peak stays near the compacted total. The report's
//! `upload_build_overlap_batches`/`upload_overlap_ms` show the overlap. TLASes follow the same path with per-batch instance buffers.
//! TLASes are independent objects: a PI's target TLAS is reached at trace time through the
//! per-TLAS device-address table.
//!
//! Files: this one holds `GpuScene` and its build steps; `scene/upload.rs` the staging ring and
//! mesh buffers, `scene/batch.rs` batched and pipelined builds with compaction,
//! `scene/structures.rs` the table slots (AS objects and size queries are motu-vk's), `scene/tables.rs` the
//! encoding of BLAS geometry, TLAS instances and PI AABBs, `scene/budget.rs` the usable budget.

use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

use motu_abi::{HierarchyView, BLAS_AABBS, BLAS_TRIANGLES, FLAG_NEEDS_ANY_HIT};
use motu_alloc::{AllocKind, AllocLimits, AllocReport, BuildSize, MemoryClass, MIB};
use motu_vk::{AsGeometry, AsLevel, BufferUsage, Context, GpuHeap, HeapBuffer};

use crate::error::{GpuError, Result};

mod batch;
mod budget;
mod lod_pass;
pub(crate) mod shading;
mod source;
mod structures;
mod tables;
mod upload;

pub(crate) use batch::{build_batched, build_pipelined, plan_one_batch, BatchStager};
pub(crate) use budget::{
    allocator_slack_bytes, block_bytes_for_budget, staging_bytes_for_budget, usable_budget_bytes,
    FULL_BUILD_STAGING_CAP_BYTES,
};
pub use budget::{full_build_overhead, FullBuildOverhead};
pub(crate) use lod_pass::{InstanceLodGpu, LodTlas, Push as LodPush};
pub(crate) use motu_vk::{AccelStruct, SizeQueries};
pub(crate) use structures::{Slot, SLOT_COUNT};
pub(crate) use tables::{
    aabbs_geometry, blas_geometry, box_list_instances, encode_instance, pi_aabbs, pi_capacity,
    set_instance_mask, MAX_PI_CAPACITY,
};
pub(crate) use upload::{
    streamed_attribute_bytes, streamed_mesh_bytes, upload_streamed_group, MeshGpu, MeshStager,
    UploadSplit, Uploader,
};

pub use crate::error::MeshSourceError;
pub use source::{ChunkReads, MeshBlobSource};

/// The least allocation cap under which a budgeted full build uses small blocks (see
/// `GpuScene::build`): twice the most it can take (64 blocks, 1,024 dedicated items, a few
/// host-visible blocks).
const MIN_ALLOCATIONS_FOR_SMALL_BLOCKS: u32 = 2048;

/// How to build a [`GpuScene`].
#[derive(Clone, Copy, Debug)]
pub struct BuildOptions {
    /// The user's VRAM budget (`--vram-budget`); the device's available budget minus a margin
    /// lowers it further.
    pub budget_bytes: u64,
    /// Cap on `VkDeviceMemory` allocations (`--max-allocations`); the device limit lowers it.
    pub max_allocations: u32,
    /// Scratch bytes one build batch may use (the shared scratch pool).
    pub scratch_budget_bytes: u64,
    /// Summed result bytes of one batch before compaction.
    pub max_batch_result_bytes: u64,
    /// Host-visible staging ring size.
    pub staging_bytes: u64,
    /// Compact acceleration structures after building.
    pub compact: bool,
    /// How BLASes are built (their size queries use the same flags).
    pub blas_build: motu_vk::BlasBuild,
    /// How TLASes are built (the full build's: fast trace; `--stream-tlas-build` for the
    /// streamer's rebuilt ones).
    pub tlas_build: motu_vk::TlasBuild,
}

impl BuildOptions {
    /// The flags TLASes are built with (the size query and the build must agree).
    pub fn tlas_flags(&self) -> motu_vk::AsBuildFlags {
        self.tlas_build.flags(self.compact)
    }
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            budget_bytes: u64::MAX,
            max_allocations: 4096,
            scratch_budget_bytes: 128 * MIB,
            max_batch_result_bytes: 256 * MIB,
            staging_bytes: FULL_BUILD_STAGING_CAP_BYTES,
            compact: true,
            blas_build: motu_vk::BlasBuild::FastTrace,
            tlas_build: motu_vk::TlasBuild::FastTrace,
        }
    }
}

/// Bytes and counts per kind of resource (`resources` in `--stats`: the JSON is
/// `motu_render::stats::ResourceReport`).
#[derive(Clone, Debug, Default)]
pub struct ResourceReport {
    /// Structures the root cannot reach (e.g. other elements under `--subset`): not built.
    pub unreachable_tlases: u64,
    pub unreachable_blases: u64,
    /// TLASes with a box list (PIs tested in raygen, not in the hardware walk) and the
    /// AABB instances those lists took out of the hardware TLASes.
    pub box_list_tlases: u32,
    pub box_list_instances: u64,
    pub budget_bytes: u64,
    pub max_allocations: u32,
    pub blas_count: u32,
    pub tlas_count: u32,
    /// BLAS bytes as built (before compaction).
    pub blas_bytes: u64,
    /// BLAS bytes after compaction (= `blas_bytes` without compaction).
    pub blas_compacted_bytes: u64,
    pub tlas_bytes: u64,
    pub tlas_compacted_bytes: u64,
    /// Acceleration-structure bytes resident now.
    pub as_bytes: u64,
    pub scratch_peak_bytes: u64,
    pub instance_buffer_peak_bytes: u64,
    pub geometry_bytes: u64,
    pub table_bytes: u64,
    /// Image textures (records and mip chains) resident for shading.
    pub texture_bytes: u64,
    /// Per-vertex normals and texture coordinates resident for shading.
    pub shading_attribute_bytes: u64,
    pub build_batches: u32,
    /// Highest bytes in memory blocks counted against the budget.
    pub peak_bytes: u64,
    /// `VkDeviceMemory` allocations now / at the peak.
    pub allocation_count: u32,
    pub peak_allocation_count: u32,
    pub build_ms: f64,
    /// Build batches during which the next batch's geometry was loaded, checked and staged on
    /// the CPU while the GPU built (pipelined uploads); 0 with a single batch.
    pub upload_build_overlap_batches: u32,
    /// Geometry bytes staged while a build batch was in flight.
    pub upload_overlap_bytes: u64,
    /// CPU milliseconds spent loading, checking and staging while a build batch was in flight
    /// (not counting `upload_stall_ms`).
    pub upload_overlap_ms: f64,
    /// Milliseconds that staging waited behind the batch in flight because the next batch's
    /// geometry outgrew its half of the staging ring (a larger `staging_bytes` removes it).
    pub upload_stall_ms: f64,
    /// The allocator's own statistics, per kind and class.
    pub alloc: Option<AllocReport>,
}

/// Everything one compiled hierarchy needs on the GPU. Drop releases it all.
pub struct GpuScene {
    // Acceleration structures first: destroyed before the buffers and blocks they live in.
    pub(crate) blases: Vec<Option<AccelStruct>>,
    pub(crate) tlases: Vec<AccelStruct>,
    meshes: Vec<Option<MeshGpu>>,
    pub(crate) tables: Vec<HeapBuffer>,
    /// Instance-level LOD's per-frame pass (`lod_instances.rs`), when enabled.
    pub(crate) instance_lod: Option<InstanceLodGpu>,
    pub(crate) addresses: [u64; SLOT_COUNT],
    pub(crate) root_tlas: u32,
    /// Candidate slots of the traversal payload this scene needs ([`pi_capacity`]).
    pub(crate) pi_capacity: u32,
    /// `FrameParams::shading`: the shading tables' header (`shading.rs`).
    pub(crate) shading_address: u64,
    pub(crate) heap: Mutex<GpuHeap>,
    pub(crate) report: ResourceReport,
    pub(crate) ctx: Context,
}

impl std::fmt::Debug for GpuScene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuScene")
            .field("blases", &self.blases.len())
            .field("tlases", &self.tlases.len())
            .field("as_bytes", &self.report.as_bytes)
            .finish()
    }
}

pub(crate) fn table_usage() -> BufferUsage {
    BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS | BufferUsage::TRANSFER_DST
}

/// A device-local node table holding `bytes`, its upload queued on `up`: the buffer and its
/// device address (the full scene's tables and the streaming skeleton's).
pub(crate) fn upload_node_table(
    ctx: &Context,
    heap: &mut GpuHeap,
    up: &mut Uploader,
    label: &str,
    bytes: &[u8],
) -> Result<(HeapBuffer, u64)> {
    let (buf, address) = alloc_node_table(heap, label, bytes.len() as u64)?;
    up.upload(ctx, &buf, 0, bytes)?;
    Ok((buf, address))
}

/// A device-local node table of `size_bytes`, not yet filled: the buffer and its device
/// address.
pub(crate) fn alloc_node_table(
    heap: &mut GpuHeap,
    label: &str,
    size_bytes: u64,
) -> Result<(HeapBuffer, u64)> {
    let buf = heap.alloc_buffer(
        label,
        size_bytes,
        table_usage(),
        AllocKind::NodeTable,
        MemoryClass::DeviceLocal,
        16,
    )?;
    let address = buf.device_address()?.0;
    Ok((buf, address))
}

struct Pending {
    accel: AccelStruct,
    index: usize,
}

impl GpuScene {
    /// Uploads `view` and builds every acceleration structure (see the module docs).
    pub fn build(
        ctx: &Context,
        view: &HierarchyView<'_>,
        meshes: &dyn MeshBlobSource,
        opts: &BuildOptions,
    ) -> Result<GpuScene> {
        let span = tracing::info_span!(
            "gpu_build",
            tlases = view.tlases.len(),
            blases = view.blases.len()
        );
        let _g = span.enter();
        let t0 = Instant::now();
        view.check_references()?;
        let budget = usable_budget_bytes(ctx, opts.budget_bytes)?;
        // The staging ring counts against the budget on unified memory: under a user budget it
        // is a 32nd of it at most (`full_build_overhead` counts the same).
        let opts = &BuildOptions {
            staging_bytes: if opts.budget_bytes == u64::MAX {
                opts.staging_bytes
            } else {
                staging_bytes_for_budget(budget, opts.staging_bytes)
            },
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
        // Under a user budget, blocks are a 64th of it and what is over a 16th of a block gets
        // its own: a partly used block counts against the budget, and an item bigger than the
        // space left in a block strands that space, so shared blocks take small items only
        // (`full_build_overhead` allows four blocks). That takes up to 64 + 1,024 allocations:
        // without a budget, or under a tight `--max-allocations`, the allocator's defaults
        // (fewer, larger blocks).
        let (block, dedicated_above) = if opts.budget_bytes == u64::MAX
            || limits.max_allocation_count < MIN_ALLOCATIONS_FOR_SMALL_BLOCKS
        {
            (None, None)
        } else {
            let block = block_bytes_for_budget(budget);
            (Some(block), Some(block / 16))
        };
        let mut heap = GpuHeap::with_blocks(ctx, limits, block, dedicated_above)?;
        let mut scene = GpuScene {
            blases: Vec::new(),
            tlases: Vec::new(),
            meshes: Vec::new(),
            tables: Vec::new(),
            instance_lod: None,
            addresses: [0; SLOT_COUNT],
            root_tlas: view.root_tlas,
            pi_capacity: pi_capacity(view, true),
            shading_address: 0,
            heap: Mutex::new(GpuHeap::new(ctx, limits)?),
            report: ResourceReport {
                budget_bytes: budget,
                max_allocations: limits.max_allocation_count,
                ..Default::default()
            },
            ctx: ctx.clone(),
        };
        // The placeholder heap above holds no blocks; the real one moves in at the end so a
        // failure anywhere drops everything built so far.
        let result = scene.build_into(&mut heap, view, meshes, opts);
        if let Err(e) = result {
            drop(scene);
            drop(heap);
            return Err(e);
        }
        scene.report.build_ms = t0.elapsed().as_secs_f64() * 1e3;
        let alloc = heap.report();
        scene.report.peak_bytes = alloc.peak_block_bytes;
        scene.report.allocation_count = alloc.allocation_count;
        scene.report.peak_allocation_count = alloc.peak_allocation_count;
        scene.report.alloc = Some(alloc);
        *scene.heap.get_mut().unwrap_or_else(|e| e.into_inner()) = heap;
        tracing::info!(
            as_bytes = scene.report.as_bytes,
            peak_bytes = scene.report.peak_bytes,
            allocations = scene.report.peak_allocation_count,
            ms = scene.report.build_ms,
            "GPU scene built"
        );
        Ok(scene)
    }

    fn build_into(
        &mut self,
        heap: &mut GpuHeap,
        view: &HierarchyView<'_>,
        source: &dyn MeshBlobSource,
        opts: &BuildOptions,
    ) -> Result<()> {
        let ctx = self.ctx.clone();
        let mut up = Uploader::new(heap, opts.staging_bytes)?;
        let result = self.build_steps(&ctx, heap, &mut up, view, source, opts);
        heap.free(up.staging);
        result
    }

    fn upload_table(
        &mut self,
        ctx: &Context,
        heap: &mut GpuHeap,
        up: &mut Uploader,
        slot: Slot,
        bytes: &[u8],
    ) -> Result<()> {
        if bytes.is_empty() {
            return Ok(());
        }
        let (buf, address) = upload_node_table(ctx, heap, up, &format!("table-{slot:?}"), bytes)?;
        self.addresses[slot as usize] = address;
        self.report.table_bytes += bytes.len() as u64;
        self.tables.push(buf);
        Ok(())
    }

    fn build_steps(
        &mut self,
        ctx: &Context,
        heap: &mut GpuHeap,
        up: &mut Uploader,
        view: &HierarchyView<'_>,
        source: &dyn MeshBlobSource,
        opts: &BuildOptions,
    ) -> Result<()> {
        use bytemuck::cast_slice;
        // 1. Node tables.
        let tlas_records = tables::tlases_with_box_lists(view);
        for r in &tlas_records {
            self.report.box_list_tlases += u32::from(r.box_list_instances > 0);
            self.report.box_list_instances += u64::from(r.box_list_instances);
        }
        let tables: [(Slot, &[u8]); 9] = [
            (Slot::Tlases, cast_slice(&tlas_records)),
            (Slot::Instances, cast_slice(view.instances)),
            (Slot::Blases, cast_slice(view.blases)),
            (Slot::Geometries, cast_slice(view.geometries)),
            (Slot::Pis, cast_slice(view.pis)),
            (Slot::Selectors, cast_slice(view.lod_selectors)),
            (Slot::LodLevels, cast_slice(view.lod_levels)),
            (Slot::Meshes, cast_slice(view.meshes)),
            (Slot::Materials, cast_slice(view.materials)),
        ];
        for (slot, bytes) in tables {
            self.upload_table(ctx, heap, up, slot, bytes)?;
        }

        // 2. Geometry of every mesh a reachable triangle BLAS uses: allocate from the records'
        // counts, then load and upload one mesh at a time through the ring. Only what the root
        // reaches is built (`--subset` roots leave the rest of the package on disk).
        let (reach_tlas, reach_blas) = view.reachable();
        self.report.unreachable_tlases = reach_tlas.iter().filter(|r| !**r).count() as u64;
        self.report.unreachable_blases = reach_blas.iter().filter(|r| !**r).count() as u64;
        let mut used = vec![false; view.meshes.len()];
        for (_, b) in view
            .blases
            .iter()
            .enumerate()
            .filter(|(i, b)| b.kind == BLAS_TRIANGLES && reach_blas[*i])
        {
            for g in &view.geometries[b.item_base as usize..(b.item_base + b.item_count) as usize] {
                used[g.mesh as usize] = true;
            }
        }
        self.meshes = (0..view.meshes.len()).map(|_| None).collect();
        for (m, rec) in view.meshes.iter().enumerate() {
            if !used[m] || rec.triangle_count == 0 || rec.vertex_count == 0 {
                continue;
            }
            let g = MeshGpu::alloc(heap, m, rec)?;
            self.report.geometry_bytes += g.size_bytes();
            self.meshes[m] = Some(g);
        }
        // Their data is loaded and uploaded per BLAS build batch (step 4), overlapping the
        // previous batch's build.
        let mut mesh_geo = vec![0u64; 2 * view.meshes.len()];
        for (m, g) in self.meshes.iter().enumerate() {
            if let Some(g) = g {
                mesh_geo[2 * m] = g.positions_address;
                mesh_geo[2 * m + 1] = g.indices_address;
            }
        }
        self.upload_table(ctx, heap, up, Slot::MeshGeo, cast_slice(&mesh_geo))?;
        let shading = crate::shading::upload(
            ctx,
            heap,
            up,
            view,
            source,
            &used,
            crate::shading::Texels::Resident,
        )?;
        self.shading_address = shading.address;
        self.report.texture_bytes = shading.texture_bytes;
        self.report.shading_attribute_bytes = shading.attribute_bytes;
        self.tables.extend(shading.buffers);

        // 3. AABBs of programmable instances (build input only).
        let aabbs = pi_aabbs(view);
        let aabb_buf = if aabbs.is_empty() {
            None
        } else {
            let b = heap.alloc_buffer(
                "pi-aabbs",
                (aabbs.len() * 24) as u64,
                BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
                AllocKind::Geometry,
                MemoryClass::DeviceLocal,
                16,
            )?;
            up.upload(ctx, &b, 0, cast_slice(&aabbs))?;
            Some(b)
        };
        up.flush(ctx)?;

        // 4. BLASes, each batch's meshes staged while the previous batch builds.
        up.set_double_buffered(true);
        let r = self.build_blases(
            ctx,
            heap,
            up,
            view,
            source,
            aabb_buf.as_ref(),
            &reach_blas,
            opts,
        );
        up.abandon();
        up.set_double_buffered(false);
        if let Some(b) = aabb_buf {
            heap.free(b);
        }
        r?;

        // 5. TLASes, then their address table.
        // An unreachable TLAS is built empty: it keeps its id (and a valid address) for free.
        // A box list's instances stay out of the hardware TLAS (tables::box_list_instances).
        let hardware_instances: Vec<u32> = tlas_records
            .iter()
            .zip(&reach_tlas)
            .map(|(r, &reached)| {
                if reached {
                    r.instance_count - r.box_list_instances
                } else {
                    0
                }
            })
            .collect();
        self.build_tlases(ctx, heap, up, view, &hardware_instances, opts)?;
        let addrs: Vec<u64> = self.tlases.iter().map(|t| t.address).collect();
        self.upload_table(ctx, heap, up, Slot::TlasAddresses, cast_slice(&addrs))?;
        up.flush(ctx)?;
        self.report.as_bytes = self
            .blases
            .iter()
            .flatten()
            .map(|a| a.size_bytes)
            .sum::<u64>()
            + self.tlases.iter().map(|a| a.size_bytes).sum::<u64>();
        Ok(())
    }

    #[allow(clippy::too_many_arguments)]
    fn build_blases(
        &mut self,
        ctx: &Context,
        heap: &mut GpuHeap,
        up: &mut Uploader,
        view: &HierarchyView<'_>,
        source: &dyn MeshBlobSource,
        aabb_buf: Option<&HeapBuffer>,
        reach: &[bool],
        opts: &BuildOptions,
    ) -> Result<()> {
        let aabb_base = match aabb_buf {
            Some(b) => b.device_address()?.0,
            None => 0,
        };
        // Geometry descriptions (with addresses) per BLAS; None for empty ones.
        let mut descs: Vec<Option<(Vec<AsGeometry>, Vec<u32>)>> =
            Vec::with_capacity(view.blases.len());
        let mut sizes = Vec::new();
        let mut order = Vec::new();
        for (i, &reached) in reach.iter().enumerate().take(view.blases.len()) {
            if !reached {
                descs.push(None);
                continue;
            }
            let Some((geoms, counts, shape)) =
                blas_geometry(view, i, |m| self.meshes[m].as_ref(), aabb_base)?
            else {
                descs.push(None);
                continue;
            };
            let sz = ctx.blas_build_sizes(&shape, opts.blas_build.flags())?;
            sizes.push(BuildSize {
                result_bytes: sz.acceleration_structure_size_bytes,
                scratch_bytes: sz.build_scratch_size_bytes,
            });
            order.push(i);
            descs.push(Some((geoms, counts)));
        }
        self.blases = (0..view.blases.len()).map(|_| None).collect();
        let mut stager = MeshStager {
            ctx,
            up,
            source,
            view,
            order: &order,
            meshes: &self.meshes,
            staged: vec![false; view.meshes.len()],
        };
        let built = build_pipelined(
            ctx,
            heap,
            &mut self.report,
            &sizes,
            AsLevel::Bottom,
            opts,
            |k| {
                let (g, c) = descs[order[k]]
                    .as_ref()
                    .map(|(g, c)| (g.as_slice(), c.clone()))
                    .unwrap_or((&[], Vec::new()));
                (g.to_vec(), c)
            },
            |_, _| Ok(()),
            Some(&mut stager),
            &mut |_| {},
        );
        // Meshes no build used (none today: every uploaded mesh belongs to a built BLAS) still
        // get their data, for the shaders.
        let leftover = built.and_then(|b| {
            for (m, g) in stager.meshes.iter().enumerate() {
                if let (Some(g), false) = (g, stager.staged[m]) {
                    g.upload(ctx, stager.up, source, m)?;
                }
            }
            stager.up.flush(ctx)?;
            Ok(b)
        });
        let built = match leftover {
            Ok(b) => b,
            Err(e) => {
                stager.up.abandon();
                return Err(e);
            }
        };
        for (k, accel) in built {
            self.report.blas_count += 1;
            self.report.blas_bytes += sizes[k].result_bytes;
            self.report.blas_compacted_bytes += accel.size_bytes;
            self.blases[order[k]] = Some(accel);
        }
        Ok(())
    }

    fn build_tlases(
        &mut self,
        ctx: &Context,
        heap: &mut GpuHeap,
        up: &mut Uploader,
        view: &HierarchyView<'_>,
        hardware_instances: &[u32],
        opts: &BuildOptions,
    ) -> Result<()> {
        let count = |t: usize| hardware_instances[t];
        let mut sizes = Vec::with_capacity(view.tlases.len());
        for t in 0..view.tlases.len() {
            let s = ctx.tlas_build_sizes(count(t), opts.tlas_flags())?;
            sizes.push(BuildSize {
                result_bytes: s.acceleration_structure_size_bytes,
                scratch_bytes: s.build_scratch_size_bytes,
            });
        }
        // Instance records (VkAccelerationStructureInstanceKHR, 64 bytes) of every TLAS.
        let blas_addr: Vec<u64> = self
            .blases
            .iter()
            .map(|b| b.as_ref().map_or(0, |a| a.address))
            .collect();
        let instance_bytes = |t: usize| -> Vec<u8> {
            let rec = &view.tlases[t];
            let n = count(t);
            let mut out = Vec::with_capacity(n as usize * 64);
            for (k, inst) in view.instances
                [rec.instance_base as usize..(rec.instance_base + n) as usize]
                .iter()
                .enumerate()
            {
                let aabbs = view.blases[inst.blas as usize].kind == BLAS_AABBS;
                out.extend_from_slice(&encode_instance(
                    &inst.tlas_from_blas,
                    aabbs,
                    inst.flags & FLAG_NEEDS_ANY_HIT != 0,
                    blas_addr[inst.blas as usize],
                    k as u32,
                ));
            }
            out
        };
        // Per batch: one instance buffer holding its TLASes' instances, uploaded then freed.
        let inst_offsets: std::cell::RefCell<Vec<u64>> =
            std::cell::RefCell::new(vec![0; view.tlases.len()]);
        let inst_addr: std::cell::Cell<u64> = std::cell::Cell::new(0);
        let inst_buf: std::cell::RefCell<Option<HeapBuffer>> = std::cell::RefCell::new(None);
        let peak = std::cell::Cell::new(0u64);
        let built = build_batched(
            ctx,
            heap,
            &mut self.report,
            &sizes,
            AsLevel::Top,
            opts,
            |k| {
                (
                    vec![AsGeometry::Instances {
                        address: inst_addr.get() + inst_offsets.borrow()[k],
                    }],
                    vec![count(k)],
                )
            },
            |heap: &mut GpuHeap, range: std::ops::Range<usize>| {
                if let Some(b) = inst_buf.borrow_mut().take() {
                    heap.free(b);
                }
                let total: u64 = range.clone().map(|t| u64::from(count(t)) * 64).sum();
                if total == 0 {
                    return Ok(());
                }
                let b = heap.alloc_buffer(
                    "tlas-instances",
                    total,
                    BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
                    AllocKind::InstanceBuffer,
                    MemoryClass::DeviceLocal,
                    16,
                )?;
                peak.set(peak.get().max(total));
                inst_addr.set(b.device_address()?.0);
                let mut off = 0u64;
                for t in range {
                    inst_offsets.borrow_mut()[t] = off;
                    let bytes = instance_bytes(t);
                    if !bytes.is_empty() {
                        up.upload(ctx, &b, off, &bytes)?;
                    }
                    off += bytes.len() as u64;
                }
                up.flush(ctx)?;
                *inst_buf.borrow_mut() = Some(b);
                Ok(())
            },
            &mut |_| {},
        );
        if let Some(b) = inst_buf.borrow_mut().take() {
            heap.free(b);
        }
        let built = built?;
        self.report.instance_buffer_peak_bytes = peak.get();
        let mut tl: Vec<Option<AccelStruct>> = (0..view.tlases.len()).map(|_| None).collect();
        for (k, accel) in built {
            self.report.tlas_count += 1;
            self.report.tlas_bytes += sizes[k].result_bytes;
            self.report.tlas_compacted_bytes += accel.size_bytes;
            tl[k] = Some(accel);
        }
        self.tlases = tl
            .into_iter()
            .enumerate()
            .map(|(k, a)| {
                a.ok_or_else(|| GpuError::InvalidRequest(format!("TLAS {k} was not built")))
            })
            .collect::<Result<_>>()?;
        Ok(())
    }

    /// Bytes and counts per kind of resource.
    pub fn report(&self) -> &ResourceReport {
        &self.report
    }

    /// The allocator's statistics now (includes per-render buffers while a render runs).
    pub fn alloc_report(&self) -> AllocReport {
        self.heap().report()
    }

    pub(crate) fn heap(&self) -> MutexGuard<'_, GpuHeap> {
        self.heap.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub fn context(&self) -> &Context {
        &self.ctx
    }

    /// Device address of TLAS `id`'s acceleration structure.
    pub fn tlas_address(&self, id: u32) -> Option<u64> {
        self.tlases.get(id as usize).map(|t| t.address)
    }
}
