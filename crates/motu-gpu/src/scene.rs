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

use std::borrow::Cow;
use std::sync::{Mutex, MutexGuard};
use std::time::Instant;

use ash::vk;
use motu_abi::{HierarchyView, MeshRecord, BLAS_AABBS, BLAS_TRIANGLES, FLAG_NEEDS_ANY_HIT};
use motu_alloc::{
    effective_budget_bytes, plan_build_batches, AllocKind, AllocLimits, AllocReport, BatchLimits,
    BuildSize, MemoryClass, SafetyMargin, MIB,
};
use serde::Serialize;

use crate::accel::{AsBuildFlags, BlasGeometry, ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT};
use crate::context::Context;
use crate::error::{GpuError, Result};
use crate::heap::{GpuHeap, HeapBuffer};
use crate::memory::BufferUsage;

/// Geometry of one compiled mesh, by its index in the hierarchy's mesh table (e.g. slices of a
/// mapped package chunk, borrowed).
pub trait MeshBlobSource {
    /// Positions (`vertex_count` of them) and `3 × triangle_count` indices.
    #[allow(clippy::type_complexity)]
    fn mesh_data(
        &self,
        mesh_record: u32,
    ) -> std::result::Result<(Cow<'_, [[f32; 3]]>, Cow<'_, [u32]>), String>;

    /// The primitive map (`triangle_count` source triangle ids) of a mesh record with
    /// `FLAG_PRIMITIVE_MAP` (a cluster of a partitioned mesh). Sources without clusters keep
    /// the default; a record with the flag then fails to upload rather than report cluster
    /// primitive ids as source ones.
    fn primitive_map(
        &self,
        _mesh_record: u32,
    ) -> std::result::Result<Option<Cow<'_, [u32]>>, String> {
        Ok(None)
    }

    /// Per-vertex normals and texture coordinates for shading, where the mesh has them
    /// (default: none, so shading uses geometric normals and constant colours).
    #[allow(clippy::type_complexity)]
    fn mesh_shading(
        &self,
        _mesh_record: u32,
    ) -> std::result::Result<(Option<Cow<'_, [[f32; 3]]>>, Option<Cow<'_, [[f32; 2]]>>), String>
    {
        Ok((None, None))
    }
}

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
}

impl Default for BuildOptions {
    fn default() -> Self {
        Self {
            budget_bytes: u64::MAX,
            max_allocations: 4096,
            scratch_budget_bytes: 128 * MIB,
            max_batch_result_bytes: 256 * MIB,
            staging_bytes: 16 * MIB,
            compact: true,
        }
    }
}

/// Bytes and counts per kind of resource (`--stats`).
#[derive(Clone, Debug, Default, Serialize)]
pub struct ResourceReport {
    /// Structures the root cannot reach (e.g. other elements under `--subset`): not built.
    pub unreachable_tlases: u64,
    pub unreachable_blases: u64,
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

/// Table slots in the shaders' push constants (`common.glsl`, same order).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(usize)]
pub(crate) enum Slot {
    Frame = 0,
    Tlases,
    Instances,
    Blases,
    Geometries,
    Pis,
    Selectors,
    LodLevels,
    Meshes,
    Materials,
    MeshGeo,
    TlasAddresses,
    Aov,
    Rgba,
    Stats,
    /// Streaming parameters (`stream.rs`); 0 outside streaming.
    Stream,
}

pub(crate) const SLOT_COUNT: usize = 16;

/// An acceleration structure in a heap buffer. Destroyed before its buffer (Drop order).
pub(crate) struct AccelStruct {
    ctx: Context,
    pub(crate) handle: vk::AccelerationStructureKHR,
    pub(crate) address: u64,
    pub(crate) size_bytes: u64,
    buffer: Option<HeapBuffer>,
}

impl AccelStruct {
    pub(crate) fn new(
        ctx: &Context,
        heap: &mut GpuHeap,
        label: &str,
        size_bytes: u64,
        ty: vk::AccelerationStructureTypeKHR,
    ) -> Result<AccelStruct> {
        let kind = if ty == vk::AccelerationStructureTypeKHR::TOP_LEVEL {
            AllocKind::TlasStorage
        } else {
            AllocKind::BlasStorage
        };
        let buffer = heap.alloc_buffer(
            label,
            size_bytes,
            BufferUsage::ACCELERATION_STRUCTURE_STORAGE,
            kind,
            MemoryClass::DeviceLocal,
            ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT,
        )?;
        let accel = ctx.accel_device()?;
        let info = vk::AccelerationStructureCreateInfoKHR::default()
            .buffer(buffer.handle())
            .offset(0)
            .size(size_bytes)
            .ty(ty);
        // SAFETY: the buffer is bound, has AS-storage usage and holds `size_bytes`.
        let handle = match unsafe { accel.create_acceleration_structure(&info, None) } {
            Ok(h) => h,
            Err(e) => {
                heap.free(buffer);
                return Err(GpuError::Vulkan {
                    call: "vkCreateAccelerationStructureKHR",
                    result: e,
                });
            }
        };
        ctx.shared.set_name(handle, label);
        let addr_info =
            vk::AccelerationStructureDeviceAddressInfoKHR::default().acceleration_structure(handle);
        // SAFETY: the handle was just created from this device.
        let address = unsafe { accel.get_acceleration_structure_device_address(&addr_info) };
        Ok(AccelStruct {
            ctx: ctx.clone(),
            handle,
            address,
            size_bytes,
            buffer: Some(buffer),
        })
    }

    /// Destroys the structure and returns its memory to the heap.
    pub(crate) fn release(mut self, heap: &mut GpuHeap) {
        self.destroy_handle();
        if let Some(b) = self.buffer.take() {
            heap.free(b);
        }
    }

    fn destroy_handle(&mut self) {
        if self.handle == vk::AccelerationStructureKHR::null() {
            return;
        }
        if let Ok(accel) = self.ctx.accel_device() {
            // SAFETY: every submission using it was fenced before its owner let go of it.
            unsafe { accel.destroy_acceleration_structure(self.handle, None) };
        }
        self.handle = vk::AccelerationStructureKHR::null();
    }
}

impl Drop for AccelStruct {
    fn drop(&mut self) {
        self.destroy_handle();
    }
}

/// A compacted-size query pool.
struct SizeQueries {
    ctx: Context,
    pool: vk::QueryPool,
    count: u32,
}

impl SizeQueries {
    fn new(ctx: &Context, count: u32) -> Result<SizeQueries> {
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR)
            .query_count(count.max(1));
        // SAFETY: valid create info; the AS extension is enabled (caller checked).
        let pool = unsafe { ctx.shared.device.create_query_pool(&info, None) }
            .map_err(GpuError::vk("vkCreateQueryPool"))?;
        Ok(SizeQueries {
            ctx: ctx.clone(),
            pool,
            count: count.max(1),
        })
    }

    fn read(&self, n: u32) -> Result<Vec<u64>> {
        let mut out = vec![0u64; n as usize];
        if n == 0 {
            return Ok(out);
        }
        // SAFETY: the first n queries were written by a fenced submission.
        unsafe {
            self.ctx.shared.device.get_query_pool_results(
                self.pool,
                0,
                &mut out,
                vk::QueryResultFlags::TYPE_64 | vk::QueryResultFlags::WAIT,
            )
        }
        .map_err(GpuError::vk("vkGetQueryPoolResults"))?;
        Ok(out)
    }
}

impl Drop for SizeQueries {
    fn drop(&mut self) {
        // SAFETY: no pending submission uses the pool (all are fenced).
        unsafe { self.ctx.shared.device.destroy_query_pool(self.pool, None) };
    }
}

/// Bounded host-visible staging ring: copies are queued and flushed (one fenced submission)
/// whenever the ring is full, so host memory never holds more than the ring.
///
/// Double-buffered mode (pipelined builds) splits the ring in two halves: the copies queued in
/// one half are recorded into a build batch's command buffer ([`Uploader::record_pending`]),
/// and the next batch is staged into the other half while that batch runs on the GPU.
pub(crate) struct Uploader {
    pub(crate) staging: HeapBuffer,
    cursor: u64,
    pending: Vec<(vk::Buffer, u64, u64, u64)>,
    flushes: u32,
    /// Time spent in fenced flushes (submission and wait).
    flush_wait: std::time::Duration,
    double_buffered: bool,
    /// The half being filled (double-buffered mode).
    half: u64,
}

impl Uploader {
    pub(crate) fn new(heap: &mut GpuHeap, size_bytes: u64) -> Result<Uploader> {
        let staging = heap.alloc_buffer(
            "staging-ring",
            size_bytes.max(64 * 1024),
            BufferUsage::TRANSFER_SRC,
            AllocKind::Staging,
            MemoryClass::HostVisible,
            16,
        )?;
        Ok(Uploader {
            staging,
            cursor: 0,
            pending: Vec::new(),
            flushes: 0,
            flush_wait: std::time::Duration::ZERO,
            double_buffered: false,
            half: 0,
        })
    }

    /// The byte range of the ring being filled.
    fn region(&self) -> (u64, u64) {
        let cap = self.staging.size_bytes();
        if !self.double_buffered {
            return (0, cap);
        }
        let mid = cap / 2 / 16 * 16;
        if self.half == 0 {
            (0, mid)
        } else {
            (mid, cap)
        }
    }

    /// Switches between one ring and two halves. Call with nothing queued (after a flush or
    /// `record_pending`) and every earlier copy out of the ring complete.
    pub(crate) fn set_double_buffered(&mut self, on: bool) {
        debug_assert!(self.pending.is_empty());
        self.pending.clear();
        self.double_buffered = on;
        self.half = 0;
        self.cursor = self.region().0;
    }

    /// Queues `bytes` for `dst` at `dst_offset`. `dst` must stay alive until the next `flush`
    /// (or until the submission `record_pending` recorded into completes).
    pub(crate) fn upload(
        &mut self,
        ctx: &Context,
        dst: &HeapBuffer,
        dst_offset: u64,
        bytes: &[u8],
    ) -> Result<()> {
        let mut done = 0usize;
        while done < bytes.len() {
            let (_, end) = self.region();
            if self.cursor >= end {
                self.flush(ctx)?;
            }
            let n = ((end - self.cursor) as usize).min(bytes.len() - done);
            self.staging
                .write_bytes(self.cursor, &bytes[done..done + n])?;
            self.pending.push((
                dst.handle(),
                self.cursor,
                dst_offset + done as u64,
                n as u64,
            ));
            // Keep copies 16-byte aligned in the ring.
            self.cursor = (self.cursor + n as u64).div_ceil(16) * 16;
            done += n;
        }
        Ok(())
    }

    /// Records the queued copies into `cmd` (whose submission the caller fences before the
    /// ring region is reused) and moves to the other half. Returns whether anything was recorded.
    ///
    /// # Safety
    /// `cmd` must be in the recording state on `device`, and every queued destination must
    /// stay alive until that submission completes.
    pub(crate) unsafe fn record_pending(
        &mut self,
        device: &ash::Device,
        cmd: vk::CommandBuffer,
    ) -> bool {
        let any = !self.pending.is_empty();
        for &(dst, src_off, dst_off, size) in &self.pending {
            let region = vk::BufferCopy {
                src_offset: src_off,
                dst_offset: dst_off,
                size,
            };
            // SAFETY: per the function contract; the staging buffer outlives the submission
            // (freed only after every build batch was waited on).
            unsafe { device.cmd_copy_buffer(cmd, self.staging.handle(), dst, &[region]) };
        }
        self.pending.clear();
        if self.double_buffered {
            self.half ^= 1;
        }
        self.cursor = self.region().0;
        any
    }

    /// Forgets queued copies (their destinations are about to be freed after a failure).
    pub(crate) fn abandon(&mut self) {
        self.pending.clear();
        self.cursor = self.region().0;
    }

    pub(crate) fn flush(&mut self, ctx: &Context) -> Result<()> {
        if self.pending.is_empty() {
            self.cursor = self.region().0;
            return Ok(());
        }
        let rec = ctx.record("upload")?;
        let (c, cmd) = rec.raw();
        for &(dst, src_off, dst_off, size) in &self.pending {
            let region = vk::BufferCopy {
                src_offset: src_off,
                dst_offset: dst_off,
                size,
            };
            // SAFETY: recording state; the staging buffer and every queued destination are alive
            // until this function returns (callers keep them; the submission is waited on).
            unsafe {
                c.shared
                    .device
                    .cmd_copy_buffer(cmd, self.staging.handle(), dst, &[region])
            };
        }
        let t = Instant::now();
        let r = rec.submit_and_wait();
        self.flush_wait += t.elapsed();
        self.pending.clear();
        self.cursor = self.region().0;
        r?;
        self.flushes += 1;
        Ok(())
    }
}

/// Stages the meshes of each BLAS build batch (each mesh once, at its first batch) through
/// the double-buffered ring.
struct MeshStager<'s, 'v> {
    ctx: &'s Context,
    up: &'s mut Uploader,
    source: &'s dyn MeshBlobSource,
    view: &'s HierarchyView<'v>,
    /// Build index → BLAS index.
    order: &'s [usize],
    meshes: &'s [Option<MeshGpu>],
    staged: Vec<bool>,
}

impl BatchStager for MeshStager<'_, '_> {
    fn stage(&mut self, builds: std::ops::Range<usize>) -> Result<(u64, std::time::Duration)> {
        let stalled_before = self.up.flush_wait;
        let mut bytes = 0u64;
        for k in builds {
            let Some(&b) = self.order.get(k) else {
                continue;
            };
            let rec = &self.view.blases[b];
            if rec.kind != BLAS_TRIANGLES {
                continue;
            }
            let items = rec.item_base as usize..(rec.item_base + rec.item_count) as usize;
            for geo in self.view.geometries.get(items).unwrap_or(&[]) {
                let m = geo.mesh as usize;
                let Some(Some(g)) = self.meshes.get(m) else {
                    continue;
                };
                if self.staged[m] {
                    continue;
                }
                bytes += g.upload(self.ctx, self.up, self.source, m)?;
                self.staged[m] = true;
            }
        }
        Ok((bytes, self.up.flush_wait.saturating_sub(stalled_before)))
    }

    unsafe fn record(&mut self, device: &ash::Device, cmd: vk::CommandBuffer) -> bool {
        // SAFETY: per the trait contract; the mesh buffers live in the scene being built.
        unsafe { self.up.record_pending(device, cmd) }
    }

    fn abandon(&mut self) {
        self.up.abandon();
    }
}

/// Per compiled mesh on the GPU.
pub(crate) struct MeshGpu {
    pub(crate) buffer: HeapBuffer,
    pub(crate) positions_address: u64,
    pub(crate) indices_address: u64,
    pub(crate) vertex_count: u32,
    pub(crate) triangle_count: u32,
    /// A cluster: its primitive map follows the indices (`indices_address + 12 × triangles`,
    /// where the shaders read it).
    pub(crate) has_primitive_map: bool,
    /// Streaming only ([`MeshGpu::alloc_streamed`]): the shading normals and texture
    /// coordinates after the indices (0: none), so they stream and evict with the mesh.
    pub(crate) normals_address: u64,
    pub(crate) uvs_address: u64,
}

/// Bytes of a streamed mesh's shading attributes (`FLAG_HAS_NORMALS`: 12 per vertex,
/// `FLAG_HAS_UVS`: 8 per vertex, each 16-byte aligned) after its geometry: what
/// [`MeshGpu::alloc_streamed`] adds, and the streaming floor's attribute term.
pub(crate) fn streamed_attribute_bytes(rec: &MeshRecord) -> (u64, u64) {
    let vc = u64::from(rec.vertex_count);
    let normals = if rec.flags & motu_abi::FLAG_HAS_NORMALS != 0 {
        (vc * 12).div_ceil(16) * 16
    } else {
        0
    };
    let uvs = if rec.flags & motu_abi::FLAG_HAS_UVS != 0 {
        (vc * 8).div_ceil(16) * 16
    } else {
        0
    };
    (normals, uvs)
}

impl MeshGpu {
    /// Allocates the buffer of mesh record `m` (positions, then indices at a 16-byte offset,
    /// then a cluster's primitive map).
    pub(crate) fn alloc(heap: &mut GpuHeap, m: usize, rec: &MeshRecord) -> Result<MeshGpu> {
        Self::alloc_with(heap, m, rec, false)
    }

    /// [`MeshGpu::alloc`] plus room for the mesh's shading attributes after its geometry (the
    /// streaming renderer: they must be resident whenever a hit on the mesh is resolved).
    pub(crate) fn alloc_streamed(
        heap: &mut GpuHeap,
        m: usize,
        rec: &MeshRecord,
    ) -> Result<MeshGpu> {
        Self::alloc_with(heap, m, rec, true)
    }

    fn alloc_with(
        heap: &mut GpuHeap,
        m: usize,
        rec: &MeshRecord,
        attributes: bool,
    ) -> Result<MeshGpu> {
        let pos_bytes = u64::from(rec.vertex_count) * 12;
        let idx_offset = pos_bytes.div_ceil(16) * 16;
        let has_primitive_map = rec.flags & motu_abi::FLAG_PRIMITIVE_MAP != 0;
        let map_bytes = if has_primitive_map {
            u64::from(rec.triangle_count) * 4
        } else {
            0
        };
        let mut geometry = idx_offset + u64::from(rec.triangle_count) * 12 + map_bytes;
        let (normal_bytes, uv_bytes) = if attributes {
            streamed_attribute_bytes(rec)
        } else {
            (0, 0)
        };
        if normal_bytes + uv_bytes > 0 {
            geometry = geometry.div_ceil(16) * 16;
        }
        let size = geometry + normal_bytes + uv_bytes;
        let buf = heap.alloc_buffer(
            &format!("mesh-{m}"),
            size,
            BufferUsage::STORAGE
                | BufferUsage::DEVICE_ADDRESS
                | BufferUsage::TRANSFER_DST
                | BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT,
            AllocKind::Geometry,
            MemoryClass::DeviceLocal,
            16,
        )?;
        let base = match buf.device_address() {
            Ok(a) => a.0,
            Err(e) => {
                heap.free(buf);
                return Err(e);
            }
        };
        Ok(MeshGpu {
            buffer: buf,
            positions_address: base,
            indices_address: base + idx_offset,
            vertex_count: rec.vertex_count,
            triangle_count: rec.triangle_count,
            has_primitive_map,
            normals_address: if normal_bytes > 0 { base + geometry } else { 0 },
            uvs_address: if uv_bytes > 0 {
                base + geometry + normal_bytes
            } else {
                0
            },
        })
    }

    /// [`MeshGpu::upload`] plus the shading attributes of a mesh from
    /// [`MeshGpu::alloc_streamed`]; an attribute the source lacks (or gives at the wrong
    /// length) is dropped, as the full build's shading tables drop it.
    pub(crate) fn upload_streamed(
        &mut self,
        ctx: &Context,
        up: &mut Uploader,
        source: &dyn MeshBlobSource,
        m: usize,
    ) -> Result<u64> {
        use bytemuck::cast_slice;
        let mut bytes = self.upload(ctx, up, source, m)?;
        if self.normals_address == 0 && self.uvs_address == 0 {
            return Ok(bytes);
        }
        let (normals, uvs) = source
            .mesh_shading(m as u32)
            .map_err(|e| GpuError::InvalidRequest(format!("mesh record {m}: {e}")))?;
        let vc = self.vertex_count as usize;
        let base = self.positions_address;
        match normals.as_deref().filter(|n| n.len() == vc) {
            Some(n) if self.normals_address != 0 => {
                up.upload(
                    ctx,
                    &self.buffer,
                    self.normals_address - base,
                    cast_slice(n),
                )?;
                bytes += (n.len() * 12) as u64;
            }
            _ => self.normals_address = 0,
        }
        match uvs.as_deref().filter(|u| u.len() == vc) {
            Some(u) if self.uvs_address != 0 => {
                up.upload(ctx, &self.buffer, self.uvs_address - base, cast_slice(u))?;
                bytes += (u.len() * 8) as u64;
            }
            _ => self.uvs_address = 0,
        }
        Ok(bytes)
    }

    /// Bytes of its buffer.
    pub(crate) fn size_bytes(&self) -> u64 {
        self.buffer.size_bytes()
    }

    /// Loads mesh record `m` from `source`, checks it against the record and queues its upload.
    pub(crate) fn upload(
        &self,
        ctx: &Context,
        up: &mut Uploader,
        source: &dyn MeshBlobSource,
        m: usize,
    ) -> Result<u64> {
        use bytemuck::cast_slice;
        let (positions, indices) = source
            .mesh_data(m as u32)
            .map_err(|e| GpuError::InvalidRequest(format!("mesh record {m}: {e}")))?;
        if positions.len() != self.vertex_count as usize
            || indices.len() != 3 * self.triangle_count as usize
        {
            return Err(GpuError::InvalidRequest(format!(
                "mesh record {m}: {} positions and {} indices, the record says {} and {}",
                positions.len(),
                indices.len(),
                self.vertex_count,
                3 * self.triangle_count
            )));
        }
        if let Some(bad) = indices.iter().find(|&&i| i >= self.vertex_count) {
            return Err(GpuError::InvalidRequest(format!(
                "mesh record {m}: index {bad} >= vertex count {}",
                self.vertex_count
            )));
        }
        let map = source
            .primitive_map(m as u32)
            .map_err(|e| GpuError::InvalidRequest(format!("mesh record {m}: {e}")))?;
        let map_len = match (&map, self.has_primitive_map) {
            (Some(map), true) if map.len() == self.triangle_count as usize => map.len(),
            (None, false) => 0,
            (got, _) => {
                return Err(GpuError::InvalidRequest(format!(
                    "mesh record {m}: the record {} a primitive map of {} entries, the source \
                     gave {}",
                    if self.has_primitive_map {
                        "needs"
                    } else {
                        "has no"
                    },
                    self.triangle_count,
                    got.as_ref()
                        .map_or("none".to_string(), |g| g.len().to_string())
                )))
            }
        };
        up.upload(ctx, &self.buffer, 0, cast_slice(&positions[..]))?;
        let idx_off = self.indices_address - self.positions_address;
        up.upload(ctx, &self.buffer, idx_off, cast_slice(&indices[..]))?;
        if let Some(map) = &map {
            let map_off = idx_off + u64::from(self.triangle_count) * 12;
            up.upload(ctx, &self.buffer, map_off, cast_slice(&map[..]))?;
        }
        Ok((positions.len() * 12 + indices.len() * 4 + map_len * 4) as u64)
    }
}

/// Everything one compiled hierarchy needs on the GPU. Drop releases it all.
pub struct GpuScene {
    // Acceleration structures first: destroyed before the buffers and blocks they live in.
    pub(crate) blases: Vec<Option<AccelStruct>>,
    pub(crate) tlases: Vec<AccelStruct>,
    meshes: Vec<Option<MeshGpu>>,
    pub(crate) tables: Vec<HeapBuffer>,
    /// Instance-level LOD's per-frame pass (`lod_instances.rs`), when enabled.
    pub(crate) instance_lod: Option<crate::lod_instances::InstanceLodGpu>,
    pub(crate) addresses: [u64; SLOT_COUNT],
    pub(crate) root_tlas: u32,
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
        view.check_references()
            .map_err(|e| GpuError::InvalidRequest(e.to_string()))?;
        let budget = usable_budget_bytes(ctx, opts.budget_bytes)?;
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
        let mut heap = GpuHeap::new(ctx, limits)?;
        let mut scene = GpuScene {
            blases: Vec::new(),
            tlases: Vec::new(),
            meshes: Vec::new(),
            tables: Vec::new(),
            instance_lod: None,
            addresses: [0; SLOT_COUNT],
            root_tlas: view.root_tlas,
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
        let buf = heap.alloc_buffer(
            &format!("table-{slot:?}"),
            bytes.len() as u64,
            table_usage(),
            AllocKind::NodeTable,
            MemoryClass::DeviceLocal,
            16,
        )?;
        self.addresses[slot as usize] = buf.device_address()?.0;
        self.report.table_bytes += bytes.len() as u64;
        up.upload(ctx, &buf, 0, bytes)?;
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
        let tables: [(Slot, &[u8]); 9] = [
            (Slot::Tlases, cast_slice(view.tlases)),
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
        let (reach_tlas, reach_blas) = reachable(view);
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
        self.build_tlases(ctx, heap, up, view, &reach_tlas, opts)?;
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
        let mut descs: Vec<Option<(Vec<vk::AccelerationStructureGeometryKHR<'static>>, Vec<u32>)>> =
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
            let sz = ctx.blas_build_sizes(&shape, AsBuildFlags::default())?;
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
            vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
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
        reach: &[bool],
        opts: &BuildOptions,
    ) -> Result<()> {
        // An unreachable TLAS is built empty: it keeps its id (and a valid address) for free.
        let count = |t: usize| {
            if reach[t] {
                view.tlases[t].instance_count
            } else {
                0
            }
        };
        let mut sizes = Vec::with_capacity(view.tlases.len());
        for t in 0..view.tlases.len() {
            let s = ctx.tlas_build_sizes(count(t), AsBuildFlags::default())?;
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
            vk::AccelerationStructureTypeKHR::TOP_LEVEL,
            opts,
            |k| {
                let instances = vk::AccelerationStructureGeometryInstancesDataKHR::default()
                    .array_of_pointers(false)
                    .data(vk::DeviceOrHostAddressConstKHR {
                        device_address: inst_addr.get() + inst_offsets.borrow()[k],
                    });
                (
                    vec![vk::AccelerationStructureGeometryKHR::default()
                        .geometry_type(vk::GeometryTypeKHR::INSTANCES)
                        .geometry(vk::AccelerationStructureGeometryDataKHR { instances })],
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

/// Build inputs staged one batch ahead: `stage` loads batch k+1's inputs into host-visible
/// staging while batch k builds on the GPU; `record` puts the staged copies into the batch's
/// own command buffer, ahead of its build.
pub(crate) trait BatchStager {
    /// Loads and stages the inputs of builds `builds`; returns the bytes staged and the time
    /// spent blocked on the GPU (a full ring region flushes behind the batch in flight). Runs
    /// while the previous batch may still be on the GPU, so it must not touch its resources.
    fn stage(&mut self, builds: std::ops::Range<usize>) -> Result<(u64, std::time::Duration)>;
    /// Records the staged copies into `cmd`; returns whether anything was recorded.
    ///
    /// # Safety
    /// `cmd` is recording on `device`; the caller waits on its submission before the staged
    /// region is reused and before any destination is freed.
    unsafe fn record(&mut self, device: &ash::Device, cmd: vk::CommandBuffer) -> bool;
    /// Drops whatever was staged but not recorded (after a failure).
    fn abandon(&mut self);
}

/// Builds `sizes.len()` structures in batches under the scratch budget, compacting each
/// batch before the next. `geometry(k)` describes build k (addresses valid once
/// `prepare(heap, batch_range)` ran for its batch). Returns (k, structure) pairs. On failure
/// every structure this call created is released before the error returns (a streaming caller
/// evicts and retries).
#[allow(clippy::too_many_arguments)]
pub(crate) fn build_batched<'g>(
    ctx: &Context,
    heap: &mut GpuHeap,
    report: &mut ResourceReport,
    sizes: &[BuildSize],
    ty: vk::AccelerationStructureTypeKHR,
    opts: &BuildOptions,
    geometry: impl Fn(usize) -> (Vec<vk::AccelerationStructureGeometryKHR<'g>>, Vec<u32>),
    prepare: impl FnMut(&mut GpuHeap, std::ops::Range<usize>) -> Result<()>,
) -> Result<Vec<(usize, AccelStruct)>> {
    build_pipelined(ctx, heap, report, sizes, ty, opts, geometry, prepare, None)
}

/// [`build_batched`] with inputs staged one batch ahead by `stager`: batch k's copies and build
/// go in one submission that is not waited on until batch k+1 is staged (the wait comes before
/// the compacted-size read, the compaction copies and the next batch's submission).
#[allow(clippy::too_many_arguments)]
pub(crate) fn build_pipelined<'g>(
    ctx: &Context,
    heap: &mut GpuHeap,
    report: &mut ResourceReport,
    sizes: &[BuildSize],
    ty: vk::AccelerationStructureTypeKHR,
    opts: &BuildOptions,
    geometry: impl Fn(usize) -> (Vec<vk::AccelerationStructureGeometryKHR<'g>>, Vec<u32>),
    mut prepare: impl FnMut(&mut GpuHeap, std::ops::Range<usize>) -> Result<()>,
    mut stager: Option<&mut dyn BatchStager>,
) -> Result<Vec<(usize, AccelStruct)>> {
    if sizes.is_empty() {
        return Ok(Vec::new());
    }
    let accel = ctx.accel_device()?;
    let scratch_align = u64::from(
        ctx.limits()
            .min_acceleration_structure_scratch_offset_alignment
            .max(1),
    )
    .next_power_of_two();
    let plan = plan_build_batches(
        sizes,
        BatchLimits {
            scratch_budget_bytes: opts.scratch_budget_bytes,
            scratch_alignment_bytes: scratch_align,
            scratch_pool_max_bytes: heap.limits().budget_bytes,
            max_batch_result_bytes: Some(opts.max_batch_result_bytes),
        },
    )
    .map_err(|e| GpuError::Budget(e.to_string()))?;
    let scratch = heap.alloc_buffer(
        "scratch-pool",
        plan.scratch_pool_bytes.max(scratch_align),
        BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
        AllocKind::Scratch,
        MemoryClass::DeviceLocal,
        scratch_align,
    )?;
    report.scratch_peak_bytes = report.scratch_peak_bytes.max(scratch.size_bytes());
    let mut out: Vec<(usize, AccelStruct)> = Vec::with_capacity(sizes.len());
    let mut in_flight: Vec<AccelStruct> = Vec::new();
    let result = (|| -> Result<()> {
        let scratch_base = scratch.device_address()?.0.div_ceil(scratch_align) * scratch_align;
        let kind = if ty == vk::AccelerationStructureTypeKHR::TOP_LEVEL {
            "tlas"
        } else {
            "blas"
        };
        if let (Some(st), Some(first)) = (stager.as_deref_mut(), plan.batches.first()) {
            st.stage(first.builds.clone())?;
        }
        for (bi, batch) in plan.batches.iter().enumerate() {
            report.build_batches += 1;
            prepare(heap, batch.builds.clone())?;
            let mut pending: Vec<Pending> = Vec::new();
            for k in batch.builds.clone() {
                match AccelStruct::new(ctx, heap, &format!("{kind}-{k}"), sizes[k].result_bytes, ty)
                {
                    Ok(a) => pending.push(Pending { accel: a, index: k }),
                    Err(e) => {
                        in_flight.extend(pending.into_iter().map(|p| p.accel));
                        return Err(e);
                    }
                }
            }
            // From here on a failure releases this batch through `in_flight`.
            let pending_ref = &pending;
            let run = (|| -> Result<Vec<AccelStruct>> {
                let descs: Vec<_> = batch.builds.clone().map(&geometry).collect();
                let ranges: Vec<Vec<vk::AccelerationStructureBuildRangeInfoKHR>> = descs
                    .iter()
                    .map(|(_, counts)| {
                        counts
                            .iter()
                            .map(|&n| {
                                vk::AccelerationStructureBuildRangeInfoKHR::default()
                                    .primitive_count(n)
                            })
                            .collect()
                    })
                    .collect();
                let infos: Vec<_> = descs
                    .iter()
                    .zip(pending_ref)
                    .map(|((g, _), p)| {
                        vk::AccelerationStructureBuildGeometryInfoKHR::default()
                            .ty(ty)
                            .flags(
                                vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE
                                    | vk::BuildAccelerationStructureFlagsKHR::ALLOW_COMPACTION,
                            )
                            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
                            .dst_acceleration_structure(p.accel.handle)
                            .geometries(g)
                            .scratch_data(vk::DeviceOrHostAddressKHR {
                                device_address: scratch_base + plan.scratch_offsets_bytes[p.index],
                            })
                    })
                    .collect();
                let range_refs: Vec<&[vk::AccelerationStructureBuildRangeInfoKHR]> =
                    ranges.iter().map(|r| r.as_slice()).collect();
                let queries = SizeQueries::new(ctx, pending_ref.len() as u32)?;
                let handles: Vec<_> = pending_ref.iter().map(|p| p.accel.handle).collect();
                let rec = ctx.record(&format!("{kind} build batch {bi}"))?;
                let (c, cmd) = rec.raw();
                let device = &c.shared.device;
                // SAFETY: recording state; destinations, scratch slices (disjoint, aligned),
                // inputs, staged copies and the query pool live until the submission below is
                // waited on (also on every error path: `Submitted` waits when dropped).
                unsafe {
                    if let Some(st) = stager.as_deref_mut() {
                        if st.record(device, cmd) {
                            transfer_to_build_barrier(device, cmd);
                        }
                    }
                    full_barrier(device, cmd);
                    accel.cmd_build_acceleration_structures(cmd, &infos, &range_refs);
                    full_barrier(device, cmd);
                    device.cmd_reset_query_pool(cmd, queries.pool, 0, queries.count);
                    accel.cmd_write_acceleration_structures_properties(
                        cmd,
                        &handles,
                        vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
                        queries.pool,
                        0,
                    );
                }
                let submitted = rec.submit()?;
                // While the GPU builds this batch, load and stage the next one.
                if let (Some(st), Some(next)) = (stager.as_deref_mut(), plan.batches.get(bi + 1)) {
                    let t = Instant::now();
                    match st.stage(next.builds.clone()) {
                        Ok((bytes, stalled)) => {
                            report.upload_build_overlap_batches += 1;
                            report.upload_overlap_bytes += bytes;
                            report.upload_overlap_ms +=
                                t.elapsed().saturating_sub(stalled).as_secs_f64() * 1e3;
                            report.upload_stall_ms += stalled.as_secs_f64() * 1e3;
                        }
                        Err(e) => {
                            st.abandon();
                            // This batch's resources are released by the caller: wait first.
                            let _ = submitted.wait();
                            return Err(e);
                        }
                    }
                }
                submitted.wait()?;
                if !opts.compact {
                    return Ok(Vec::new());
                }
                let compacted = queries.read(pending_ref.len() as u32)?;
                // Nothing to gain (lavapipe reports the built size): keep the originals and
                // skip the copies' second allocation, which would double the peak.
                if pending_ref
                    .iter()
                    .zip(&compacted)
                    .all(|(p, &size)| size.max(1) >= p.accel.size_bytes)
                {
                    return Ok(Vec::new());
                }
                let mut copies = Vec::with_capacity(pending_ref.len());
                for (p, &size) in pending_ref.iter().zip(&compacted) {
                    let size = size.max(1).min(p.accel.size_bytes);
                    match AccelStruct::new(
                        ctx,
                        heap,
                        &format!("{kind}-{}-compact", p.index),
                        size,
                        ty,
                    ) {
                        Ok(a) => copies.push(a),
                        Err(GpuError::Budget(msg)) => {
                            // No room for both copies: the uncompacted ones are valid as they
                            // are, and the budget holds.
                            tracing::debug!(%msg, "compaction skipped under the budget");
                            copies.into_iter().for_each(|c| c.release(heap));
                            return Ok(Vec::new());
                        }
                        Err(e) => {
                            copies.into_iter().for_each(|c| c.release(heap));
                            return Err(e);
                        }
                    }
                }
                let rec = match ctx.record(&format!("{kind} compaction batch {bi}")) {
                    Ok(r) => r,
                    Err(e) => {
                        copies.into_iter().for_each(|c| c.release(heap));
                        return Err(e);
                    }
                };
                let (_, cmd) = rec.raw();
                for (p, dst) in pending_ref.iter().zip(&copies) {
                    let info = vk::CopyAccelerationStructureInfoKHR::default()
                        .src(p.accel.handle)
                        .dst(dst.handle)
                        .mode(vk::CopyAccelerationStructureModeKHR::COMPACT);
                    // SAFETY: both structures live until the fenced submission returns; the
                    // source was built with ALLOW_COMPACTION and dst holds its compacted size.
                    unsafe { accel.cmd_copy_acceleration_structure(cmd, &info) };
                }
                if let Err(e) = rec.submit_and_wait() {
                    copies.into_iter().for_each(|c| c.release(heap));
                    return Err(e);
                }
                Ok(copies)
            })();
            match run {
                Ok(copies) if copies.is_empty() => {
                    out.extend(pending.into_iter().map(|p| (p.index, p.accel)));
                }
                Ok(copies) => {
                    for (p, dst) in pending.into_iter().zip(copies) {
                        p.accel.release(heap);
                        out.push((p.index, dst));
                    }
                }
                Err(e) => {
                    in_flight.extend(pending.into_iter().map(|p| p.accel));
                    return Err(e);
                }
            }
        }
        Ok(())
    })();
    heap.free(scratch);
    match result {
        Ok(()) => Ok(out),
        Err(e) => {
            for a in in_flight {
                a.release(heap);
            }
            for (_, a) in out {
                a.release(heap);
            }
            Err(e)
        }
    }
}

/// Vulkan geometry of one BLAS.
pub(crate) type BlasDesc = (
    Vec<vk::AccelerationStructureGeometryKHR<'static>>,
    Vec<u32>,
    Vec<BlasGeometry>,
);

/// Geometry of BLAS `i` of `view`: one triangle geometry per mesh (`mesh(m)` is mesh record
/// `m` on the GPU) or the AABBs of its programmable instances, read at `aabb_base + 24 × item`.
/// `None` for a BLAS without primitives.
pub(crate) fn blas_geometry<'m>(
    view: &HierarchyView<'_>,
    i: usize,
    mesh: impl Fn(usize) -> Option<&'m MeshGpu>,
    aabb_base: u64,
) -> Result<Option<BlasDesc>> {
    let b = &view.blases[i];
    let range = b.item_base as usize..(b.item_base + b.item_count) as usize;
    let (geoms, counts, shape): (Vec<_>, Vec<u32>, Vec<BlasGeometry>) = if b.kind == BLAS_AABBS {
        if b.item_count == 0 {
            (Vec::new(), Vec::new(), Vec::new())
        } else {
            let aabbs = vk::AccelerationStructureGeometryAabbsDataKHR::default()
                .data(vk::DeviceOrHostAddressConstKHR {
                    device_address: aabb_base + u64::from(b.item_base) * 24,
                })
                .stride(24);
            (
                vec![vk::AccelerationStructureGeometryKHR::default()
                    .geometry_type(vk::GeometryTypeKHR::AABBS)
                    .geometry(vk::AccelerationStructureGeometryDataKHR { aabbs })
                    .flags(vk::GeometryFlagsKHR::NO_DUPLICATE_ANY_HIT_INVOCATION)],
                vec![b.item_count],
                vec![BlasGeometry::Aabbs {
                    aabb_count: b.item_count,
                    opaque: false,
                }],
            )
        }
    } else {
        let mut g = Vec::new();
        let mut c = Vec::new();
        let mut s = Vec::new();
        for geo in &view.geometries[range] {
            let Some(m) = mesh(geo.mesh as usize) else {
                continue;
            };
            let opaque = view.meshes[geo.mesh as usize].flags & FLAG_NEEDS_ANY_HIT == 0;
            let tri = vk::AccelerationStructureGeometryTrianglesDataKHR::default()
                .vertex_format(vk::Format::R32G32B32_SFLOAT)
                .vertex_data(vk::DeviceOrHostAddressConstKHR {
                    device_address: m.positions_address,
                })
                .vertex_stride(12)
                .max_vertex(m.vertex_count - 1)
                .index_type(vk::IndexType::UINT32)
                .index_data(vk::DeviceOrHostAddressConstKHR {
                    device_address: m.indices_address,
                });
            g.push(
                vk::AccelerationStructureGeometryKHR::default()
                    .geometry_type(vk::GeometryTypeKHR::TRIANGLES)
                    .geometry(vk::AccelerationStructureGeometryDataKHR { triangles: tri })
                    .flags(if opaque {
                        vk::GeometryFlagsKHR::OPAQUE
                    } else {
                        vk::GeometryFlagsKHR::NO_DUPLICATE_ANY_HIT_INVOCATION
                    }),
            );
            c.push(m.triangle_count);
            s.push(BlasGeometry::Triangles {
                vertex_count: m.vertex_count,
                triangle_count: m.triangle_count,
                indexed: true,
                opaque,
            });
        }
        // A geometry index must equal its position in the record (gl_GeometryIndexEXT
        // resolves the mesh), so an empty mesh inside a BLAS is an error.
        if g.len() != b.item_count as usize {
            return Err(GpuError::InvalidRequest(format!(
                "BLAS {i}: {} of its {} meshes are empty",
                b.item_count as usize - g.len(),
                b.item_count
            )));
        }
        (g, c, s)
    };
    Ok(if geoms.is_empty() {
        None
    } else {
        Some((geoms, counts, shape))
    })
}

/// One `VkAccelerationStructureInstanceKHR` (64 bytes): triangles use hit group 0 (opaque unless
/// `needs_any_hit`), programmable instances (`aabbs`) hit group 1, never opaque. A
/// `blas_address` of 0 makes the instance inactive (mask 0 as well: some drivers only check
/// the mask). The custom index is `local_index`, the instance's index within its TLAS's
/// record range (< 2^24, which `max_instance_count` bounds): the shaders read it instead of
/// the position in the built TLAS, so a streamed TLAS may hold only its resident instances.
pub(crate) fn encode_instance(
    tlas_from_blas: &[f32; 12],
    aabbs: bool,
    needs_any_hit: bool,
    blas_address: u64,
    local_index: u32,
) -> [u8; 64] {
    let (sbt, flags) = if aabbs {
        (1u32, vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE)
    } else if needs_any_hit {
        (
            0,
            vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE,
        )
    } else {
        (
            0,
            vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE
                | vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE,
        )
    };
    let mut out = [0u8; 64];
    for (i, v) in tlas_from_blas.iter().enumerate() {
        out[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
    }
    // Node ids never travel in 24 bits: only the local instance index does.
    debug_assert!(local_index < 1 << 24, "instance index {local_index} ≥ 2^24");
    let mask = if blas_address == 0 { 0u32 } else { 0xFF };
    out[48..52].copy_from_slice(&((mask << 24) | (local_index & 0xFF_FFFF)).to_le_bytes());
    out[52..56].copy_from_slice(&(sbt | (flags.as_raw() << 24)).to_le_bytes());
    out[56..64].copy_from_slice(&blas_address.to_le_bytes());
    out
}

/// Transfer writes (staged geometry copies) before acceleration-structure builds read them.
///
/// # Safety
/// `cmd` must be in the recording state on `device`.
pub(crate) unsafe fn transfer_to_build_barrier(device: &ash::Device, cmd: vk::CommandBuffer) {
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::TRANSFER_WRITE)
        .dst_access_mask(
            vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR | vk::AccessFlags::SHADER_READ,
        );
    // SAFETY: per the function contract.
    unsafe {
        device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::TRANSFER,
            vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR,
            vk::DependencyFlags::empty(),
            &[barrier],
            &[],
            &[],
        )
    };
}

/// A full memory barrier (coarse: builds are few and large).
///
/// # Safety
/// `cmd` must be in the recording state on `device`.
pub(crate) unsafe fn full_barrier(device: &ash::Device, cmd: vk::CommandBuffer) {
    let barrier = vk::MemoryBarrier::default()
        .src_access_mask(vk::AccessFlags::MEMORY_WRITE)
        .dst_access_mask(vk::AccessFlags::MEMORY_READ | vk::AccessFlags::MEMORY_WRITE);
    // SAFETY: per the function contract.
    unsafe {
        device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::DependencyFlags::empty(),
            &[barrier],
            &[],
            &[],
        )
    };
}

/// TLASes and BLASes reachable from the root: through instances, PIs, LOD levels.
pub(crate) fn reachable(view: &HierarchyView<'_>) -> (Vec<bool>, Vec<bool>) {
    let mut tlas = vec![false; view.tlases.len()];
    let mut blas = vec![false; view.blases.len()];
    let mut todo = vec![view.root_tlas as usize];
    if let Some(r) = tlas.get_mut(view.root_tlas as usize) {
        *r = true;
    }
    let visit = |t: usize, tlas: &mut Vec<bool>, todo: &mut Vec<usize>| {
        if t < tlas.len() && !tlas[t] {
            tlas[t] = true;
            todo.push(t);
        }
    };
    while let Some(t) = todo.pop() {
        let rec = &view.tlases[t];
        let range = rec.instance_base as usize..(rec.instance_base + rec.instance_count) as usize;
        for inst in view.instances.get(range).unwrap_or(&[]) {
            let b = inst.blas as usize;
            if b >= blas.len() || blas[b] {
                continue;
            }
            blas[b] = true;
            let br = &view.blases[b];
            if br.kind != BLAS_AABBS {
                continue;
            }
            let items = br.item_base as usize..(br.item_base + br.item_count) as usize;
            for pi in view.pis.get(items).unwrap_or(&[]) {
                if pi.kind == motu_abi::PI_TLAS {
                    visit(pi.target as usize, &mut tlas, &mut todo);
                } else if let Some(s) = view.lod_selectors.get(pi.target as usize) {
                    let levels = s.level_base as usize..(s.level_base + s.level_count) as usize;
                    for &lt in view.lod_levels.get(levels).unwrap_or(&[]) {
                        visit(lt as usize, &mut tlas, &mut todo);
                    }
                }
            }
        }
    }
    (tlas, blas)
}

/// The budget a build may use: the user's, lowered to what `VK_EXT_memory_budget` says is
/// available on the device-local heaps minus a safety margin. Errors when the device lacks
/// what every build needs.
pub(crate) fn usable_budget_bytes(ctx: &Context, user_budget_bytes: u64) -> Result<u64> {
    if !ctx.caps().acceleration_structure || !ctx.caps().buffer_device_address {
        return Err(GpuError::MissingFeature {
            what: "acceleration structures with buffer device address".into(),
            details: ctx.device_name().to_string(),
        });
    }
    let device_available = ctx
        .heaps()
        .iter()
        .filter(|h| h.device_local)
        .filter_map(|h| {
            h.budget_bytes
                .map(|b| b.saturating_sub(h.usage_bytes.unwrap_or(0)))
        })
        .max();
    Ok(effective_budget_bytes(
        Some(user_budget_bytes),
        device_available,
        SafetyMargin::default(),
    )
    .unwrap_or(user_budget_bytes))
}

/// The AABB build input of every programmable instance (`VkAabbPositionsKHR`: min then max),
/// indexed like the PI table.
pub(crate) fn pi_aabbs(view: &HierarchyView<'_>) -> Vec<[f32; 6]> {
    view.pis
        .iter()
        .map(|p| {
            let (a, b) = (p.aabb_min, p.aabb_max);
            [a[0], a[1], a[2], b[0], b[1], b[2]]
        })
        .collect()
}
