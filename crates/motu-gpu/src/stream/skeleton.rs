//! The resident skeleton: the heap ([`HeapSetup`]), node tables (GPU copies with proxy
//! instances, derived by `topology.rs`), stamps, PI BLASes and every TLAS, built once by
//! [`StreamingRenderer::new`] in phases ([`StreamingRenderer::raise_skeleton`]); the address
//! tables rewritten as structures come and go.

use motu_abi::{HierarchyView, InstanceRecord, BLAS_AABBS};
use motu_alloc::{AllocKind, AllocLimits, MemoryClass, MIB};
use motu_vk::{BufferUsage, Context, GpuHeap, HeapBuffer};

use super::buffers::staging_released;
use super::instance_table::{InstanceTable, TableMemory};
use super::persistent::{auto_persistent, persistent_estimate, persistent_records, TlasUpdate};
use super::proxy_boxes::Box6;
use super::topology::SkeletonRecords;
use super::{MeshMemory, StreamOptions, StreamingRenderer};
use crate::error::{GpuError, Result};
use crate::scene::{alloc_node_table, upload_node_table, Slot, Uploader};

/// The heap a streamer allocates from and the options as the budget bounds them.
pub(super) struct HeapSetup {
    /// The options with staging and scratch capped by the budget.
    pub opts: StreamOptions,
    /// The usable budget.
    pub budget_bytes: u64,
    pub max_allocation_count: u32,
    pub heap: GpuHeap,
    /// Whether host-visible memory counts against the budget (unified memory).
    pub host_counts: bool,
    /// The memory streamed meshes live in ([`StreamOptions::mesh_memory`] resolved) and
    /// whether it counts against the budget.
    pub mesh_class: MemoryClass,
    pub meshes_budgeted: bool,
}

impl HeapSetup {
    pub fn new(ctx: &Context, view: &HierarchyView<'_>, opts: &StreamOptions) -> Result<HeapSetup> {
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
                // Tables in host memory (opt-in, `MOTU_STREAM_TABLES`): dedicated blocks.
                + TableMemory::from_env().host_bytes_bound(view)
                + if opts.mesh_memory == MeshMemory::Device {
                    0
                } else {
                    2 * super::streamed_mesh_total_bytes(view)
                        + 4 * crate::scene::block_bytes_for_budget(budget)
                },
        };
        let max_allocation_count = limits.max_allocation_count;
        let block = crate::scene::block_bytes_for_budget(budget);
        // Structures, meshes and their transients come and go in sizes up to about a block:
        // from half a block each gets its own (freed whole when evicted), or the free space
        // they strand inside shared blocks, up to a quarter of the budget, fits nothing.
        let mut heap = GpuHeap::with_blocks(ctx, limits, Some(block), Some(block / 2))?;
        let host_counts = heap.host_visible_counts_against_budget();
        let mesh_class = match opts.mesh_memory {
            MeshMemory::Device => MemoryClass::DeviceLocal,
            MeshMemory::Host => MemoryClass::HostVisible,
            MeshMemory::Auto if host_counts => MemoryClass::DeviceLocal,
            MeshMemory::Auto => MemoryClass::HostVisible,
        };
        let meshes_budgeted = mesh_class == MemoryClass::DeviceLocal || host_counts;
        // Meshes in host memory outside the budget: each host block made ahead, off the frame
        // (`heap/spare.rs`: one block more than the policy holds, so not where host blocks
        // count against the budget); `MOTU_HOST_BLOCKS_AHEAD=0` makes them in the frame as
        // before (A/B measurements).
        let ahead = std::env::var("MOTU_HOST_BLOCKS_AHEAD").map_or(true, |v| v != "0");
        heap.set_host_blocks_ahead(ahead && !meshes_budgeted);
        Ok(HeapSetup {
            opts: *opts,
            budget_bytes: budget,
            max_allocation_count,
            heap,
            host_counts,
            mesh_class,
            meshes_budgeted,
        })
    }
}

/// The boxes inside streamable BLASes (`proxy_boxes.rs`): `[first, fan]` per BLAS, and the
/// boxes.
pub(super) struct ProxyBoxes {
    pub index: Vec<[u32; 2]>,
    pub boxes: Vec<Box6>,
}

impl<'a> StreamingRenderer<'a> {
    /// The start after the parts are made: which TLASes are persistent, the boxes inside
    /// streamable BLASes, and the resident skeleton (`records`: the GPU tables), timed in
    /// the totals.
    pub(super) fn raise_skeleton(&mut self, records: &SkeletonRecords) -> Result<()> {
        let view = self.view;
        let t_persistent = std::time::Instant::now();
        let has_clusters: Vec<bool> = self.topo.has_clusters();
        let persistent_mode = self.choose_persistent(&has_clusters)?;
        self.tlases.set_persistent_mode(persistent_mode);
        self.totals.persistent_choice_ms = ms_since(t_persistent);
        let t_boxes = std::time::Instant::now();
        let (index, box_count) = super::proxy_boxes::layout(&view, |b| self.topo.buildable(b));
        let boxes = self.proxy_boxes_start(&index, box_count);
        self.totals.proxy_boxes = boxes.len() as u64;
        self.totals.proxy_boxes_ms = t_boxes.elapsed().as_secs_f64() * 1e3;
        tracing::info!(
            boxes = self.totals.proxy_boxes,
            ms = self.totals.proxy_boxes_ms,
            source = self.totals.proxy_boxes_source,
            "boxes inside streamable BLASes"
        );
        let t_skeleton = std::time::Instant::now();
        self.init_skeleton(records, &ProxyBoxes { index, boxes })?;
        self.totals.skeleton_ms = ms_since(t_skeleton);
        let report = self.heap.report();
        self.totals.skeleton_bytes = report.budget_in_use_bytes;
        tracing::info!(
            skeleton_bytes = self.totals.skeleton_bytes,
            budget_bytes = self.build_opts.budget_bytes,
            derived_ms = self.totals.derived_ms,
            persistent_choice_ms = self.totals.persistent_choice_ms,
            skeleton_ms = self.totals.skeleton_ms,
            scene_triangles = self.totals.scene_triangles,
            "streaming skeleton resident"
        );
        Ok(())
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

    /// Allocates a device-local table for `bytes` and queues its upload; returns it with its
    /// device address.
    fn upload_table(
        &mut self,
        ctx: &Context,
        label: &str,
        bytes: &[u8],
    ) -> Result<(HeapBuffer, u64)> {
        let up = self.up.as_mut().ok_or_else(staging_released)?;
        upload_node_table(ctx, &mut self.heap, up, label, bytes)
    }

    /// The resident skeleton: the tables, the stamp buffers and the shading tables
    /// uploaded, then the PI BLASes and every TLAS built.
    fn init_skeleton(&mut self, records: &SkeletonRecords, boxes: &ProxyBoxes) -> Result<()> {
        let ctx = self.ctx.clone();
        self.up = Some(Uploader::new(&mut self.heap, self.opts.staging_bytes)?);
        self.upload_tables(records, boxes)?;
        self.alloc_stamps()?;
        self.init_shading()?;
        self.up_mut()?.flush(&ctx)?;
        self.build_pi_blases()?;
        self.build_first_tlases()?;
        self.upload_tlas_addresses()
    }

    /// The node tables (with the proxies' records), the member table and the boxes inside
    /// streamable BLASes, queued on the staging ring.
    fn upload_tables(&mut self, records: &SkeletonRecords, boxes: &ProxyBoxes) -> Result<()> {
        use bytemuck::cast_slice;
        let ctx = self.ctx.clone();
        let view = self.view;
        let (gpu_tlases, gpu_blases, gpu_pis, cluster_members) = (
            &records.tlases,
            &records.blases,
            &records.pis,
            &records.members,
        );
        let (box_index, boxes) = (&boxes.index, &boxes.boxes);
        let mesh_geo = vec![0u64; 2 * view.meshes.len()];
        let tlas_addrs = vec![0u64; view.tlases.len()];
        let tables: [(Slot, &[u8]); 10] = [
            (Slot::Tlases, cast_slice(gpu_tlases)),
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
            let (buf, address) =
                self.upload_table(&ctx, &format!("stream-table-{slot:?}"), bytes)?;
            self.gpu.keep_slot(slot, buf, address);
        }
        if records.instances.len() > 0 {
            let (buf, address) = self.upload_instance_table(&ctx, &records.instances)?;
            self.gpu.keep_slot(Slot::Instances, buf, address);
        }
        // Read by member tests only: in host memory with `MOTU_STREAM_TABLES=host`.
        let host = TableMemory::from_env().proxy_tables_in_host();
        if !cluster_members.is_empty() {
            let (buf, address) = self.upload_table_in(
                &ctx,
                "stream-cluster-members",
                cast_slice(cluster_members),
                host,
            )?;
            self.gpu.keep_cluster_members(buf, address);
        }
        if !boxes.is_empty() {
            let index =
                self.upload_table_in(&ctx, "stream-proxy-box-index", cast_slice(box_index), host)?;
            let boxes =
                self.upload_table_in(&ctx, "stream-proxy-boxes", cast_slice(boxes), host)?;
            self.gpu.keep_proxy_boxes(index, boxes);
        }
        Ok(())
    }

    /// [`Self::upload_table`], or with `host` written in place into host memory the GPU reads
    /// (`MOTU_STREAM_TABLES`).
    fn upload_table_in(
        &mut self,
        ctx: &Context,
        label: &str,
        bytes: &[u8],
        host: bool,
    ) -> Result<(HeapBuffer, u64)> {
        if !host {
            return self.upload_table(ctx, label, bytes);
        }
        let buf = self.heap.alloc_buffer(
            label,
            bytes.len() as u64,
            crate::scene::table_usage(),
            AllocKind::NodeTable,
            MemoryClass::HostVisible,
            16,
        )?;
        let address = buf
            .write_bytes(0, bytes)
            .map_err(GpuError::from)
            .and_then(|()| Ok(buf.device_address()?.0));
        match address {
            Ok(a) => Ok((buf, a)),
            Err(e) => {
                self.heap.free(buf);
                Err(e)
            }
        }
    }

    /// The instance table, written into the staging ring a region at a time by several
    /// threads straight from the view (`instance_table.rs`).
    fn upload_instance_table(
        &mut self,
        ctx: &Context,
        table: &InstanceTable,
    ) -> Result<(HeapBuffer, u64)> {
        let record_bytes = std::mem::size_of::<InstanceRecord>();
        if TableMemory::from_env().instances_in_host() {
            return self.write_host_instance_table(table);
        }
        let (buf, address) = alloc_node_table(
            &mut self.heap,
            "stream-table-Instances",
            (table.len() * record_bytes) as u64,
        )?;
        let view = self.view.instances;
        let up = self.up.as_mut().ok_or_else(staging_released)?;
        let per_upload = (up.region_bytes() as usize / record_bytes).max(1);
        let mut first = 0;
        while first < table.len() {
            let n = per_upload.min(table.len() - first);
            let offset = (first * record_bytes) as u64;
            up.upload_in_place(ctx, &buf, offset, n * record_bytes, |bytes| {
                match bytemuck::try_cast_slice_mut::<u8, InstanceRecord>(bytes) {
                    Ok(out) => table.write_parallel(view, first, out),
                    // The ring's regions are 16-byte aligned; a copy only if a map is not.
                    Err(_) => {
                        let mut out = vec![InstanceRecord::default(); n];
                        table.write_parallel(view, first, &mut out);
                        bytes.copy_from_slice(bytemuck::cast_slice(&out));
                    }
                }
            })?;
            first += n;
        }
        Ok((buf, address))
    }

    /// The instance table in host memory the GPU reads (`instance_table_in_host`), written in
    /// place by several threads.
    fn write_host_instance_table(&mut self, table: &InstanceTable) -> Result<(HeapBuffer, u64)> {
        let record_bytes = std::mem::size_of::<InstanceRecord>();
        let bytes = table.len() * record_bytes;
        let buf = self.heap.alloc_buffer(
            "stream-table-Instances-host",
            bytes as u64,
            crate::scene::table_usage(),
            AllocKind::NodeTable,
            MemoryClass::HostVisible,
            16,
        )?;
        let view = self.view.instances;
        let written = buf.with_mapped_mut(0, bytes, |out| {
            match bytemuck::try_cast_slice_mut::<u8, InstanceRecord>(out) {
                Ok(records) => table.write_parallel(view, 0, records),
                // Mapped memory is aligned far beyond a record; a copy only if it were not.
                Err(_) => {
                    let mut records = vec![InstanceRecord::default(); table.len()];
                    table.write_parallel(view, 0, &mut records);
                    out.copy_from_slice(bytemuck::cast_slice(&records));
                }
            }
        });
        let address = written
            .map_err(GpuError::from)
            .and_then(|()| Ok(buf.device_address()?.0));
        match address {
            Ok(a) => Ok((buf, a)),
            Err(e) => {
                self.heap.free(buf);
                Err(e)
            }
        }
    }

    /// The per-BLAS stamp buffers: cleared stamps the shaders write, walked stamps the host
    /// writes before each pass.
    fn alloc_stamps(&mut self) -> Result<()> {
        let ctx = self.ctx.clone();
        let view = self.view;
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
        self.gpu.keep_stamps(buf, walked);
        Ok(())
    }

    /// PI BLASes: the skeleton, built once from the PI boxes (input freed after).
    fn build_pi_blases(&mut self) -> Result<()> {
        use bytemuck::cast_slice;
        let ctx = self.ctx.clone();
        let view = self.view;
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
                    self.res.place_skeleton_blas(b, a);
                }
                Ok(())
            })();
            self.heap.free(buf);
            r?;
        }
        Ok(())
    }

    /// Every TLAS (no triangle instance resident: only their proxy boxes and PI instances):
    /// TLASes are never evicted, so a ray reaches every BLAS box and only BLASes stream.
    /// A persistent TLAS that does not fit is rebuilt instead.
    fn build_first_tlases(&mut self) -> Result<()> {
        let view = self.view;
        let all: Vec<u32> = (0..view.tlases.len() as u32).collect();
        if self.tlases.persistent_count() > 0 {
            self.build_placeholders()?;
        }
        loop {
            let persistent = self.tlases.persistent_count();
            match self.build_tlases(&all) {
                Ok(()) => break,
                // A persistent TLAS that did not fit is rebuilt instead: try again.
                Err(GpuError::Budget(_)) if self.tlases.persistent_count() < persistent => {}
                Err(e) => return Err(e),
            }
        }
        // The persistent TLASes' first updates ran: the whole-bounds placeholders are unused.
        self.tlases.placeholders_mut().release_full(&mut self.heap);
        if self.tlases.persistent_count() == 0 {
            self.tlases.placeholders_mut().release(&mut self.heap);
        }
        let host_counts = self.heap.host_visible_counts_against_budget();
        self.totals.persistent_tlases = self.tlases.persistent_count() as u32;
        self.totals.tlas_mode = if self.totals.persistent_tlases > 0 {
            "update"
        } else {
            "rebuild"
        };
        self.totals.persistent_tlas_bytes = self
            .tlases
            .resident()
            .filter_map(|g| Some(g.accel().size_bytes + g.persistent()?.size_bytes(host_counts)))
            .sum::<u64>()
            + self.tlases.placeholders().bytes;
        Ok(())
    }

    pub(super) fn up_mut(&mut self) -> Result<&mut Uploader> {
        self.up.as_mut().ok_or_else(staging_released)
    }

    pub(super) fn upload_tlas_addresses(&mut self) -> Result<()> {
        use bytemuck::cast_slice;
        let ctx = self.ctx.clone();
        let addrs: Vec<u64> = (0..self.view.tlases.len() as u32)
            .map(|t| self.tlases.get(t).map_or(0, |t| t.accel().address))
            .collect();
        let mut mesh_geo = vec![0u64; 2 * self.res.meshes().len()];
        for (m, g) in self.res.meshes().iter().enumerate() {
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
            up.upload(&ctx, self.gpu.tlas_addresses(), 0, cast_slice(&addrs))?;
        }
        if !mesh_geo.is_empty() {
            up.upload(&ctx, self.gpu.mesh_geo(), 0, cast_slice(&mesh_geo))?;
        }
        up.flush(&ctx)
    }
}

pub(super) fn ms_since(t: std::time::Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}
