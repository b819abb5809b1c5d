//! Uploads: the bounded staging ring and mesh buffers (positions, indices, shading attributes).

use std::time::Instant;

use motu_abi::{HierarchyView, MeshRecord, BLAS_TRIANGLES};
use motu_alloc::{AllocKind, MemoryClass};
use motu_vk::{BufferCopy, BufferUsage, CommandRecorder, Context, GpuHeap, HeapBuffer};

use super::{BatchStager, MeshBlobSource};

mod group;
use crate::error::{GpuError, Result};
pub(crate) use group::{upload_streamed_group, UploadSplit};

/// Bounded host-visible staging ring: copies are queued and flushed (one fenced submission)
/// whenever the ring is full, so host memory never holds more than the ring.
///
/// Double-buffered mode (pipelined builds) splits the ring in two halves: the copies queued in
/// one half are recorded into a build batch's command buffer ([`Uploader::record_pending`]),
/// and the next batch is staged into the other half while that batch runs on the GPU.
pub(crate) struct Uploader {
    pub(crate) staging: HeapBuffer,
    cursor: u64,
    pending: Vec<BufferCopy>,
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
            self.pending.push(BufferCopy {
                dst: dst.target(),
                src_offset: self.cursor,
                dst_offset: dst_offset + done as u64,
                size_bytes: n as u64,
            });
            // Keep copies 16-byte aligned in the ring.
            self.cursor = (self.cursor + n as u64).div_ceil(16) * 16;
            done += n;
        }
        Ok(())
    }

    /// Bytes of the ring region being filled: the most one [`Uploader::upload_in_place`]
    /// takes.
    pub(crate) fn region_bytes(&self) -> u64 {
        let (start, end) = self.region();
        end - start
    }

    /// Queues a copy of `len` bytes to `dst` at `dst_offset` that `fill` writes in place in
    /// the mapped ring (no host copy in between: encoders fill it, in parallel if they like).
    /// `len` is at most [`Uploader::region_bytes`]; `dst` as for [`Uploader::upload`].
    pub(crate) fn upload_in_place(
        &mut self,
        ctx: &Context,
        dst: &HeapBuffer,
        dst_offset: u64,
        len: usize,
        fill: impl FnOnce(&mut [u8]),
    ) -> Result<()> {
        let (start, end) = self.region();
        if len as u64 > end - start {
            return Err(GpuError::InvalidRequest(format!(
                "an in-place upload of {len} bytes exceeds the staging ring's region of {} bytes",
                end - start
            )));
        }
        if self.cursor + len as u64 > end {
            self.flush(ctx)?;
        }
        self.staging.with_mapped_mut(self.cursor, len, fill)?;
        self.pending.push(BufferCopy {
            dst: dst.target(),
            src_offset: self.cursor,
            dst_offset,
            size_bytes: len as u64,
        });
        self.cursor = (self.cursor + len as u64).div_ceil(16) * 16;
        Ok(())
    }

    /// Queues `count` values, `value(k)` for k in `0..count`, for `dst` at `dst_offset`, each
    /// written in place in the ring a region at a time (no host array of them is built), by
    /// the rayon pool (`value` is called once per index, from any thread): a TLAS rebuild's
    /// proxy boxes and PI records, tens of thousands a piece, are on its critical path.
    pub(crate) fn upload_with<T: bytemuck::Pod + Send>(
        &mut self,
        ctx: &Context,
        dst: &HeapBuffer,
        dst_offset: u64,
        count: usize,
        value: impl Fn(usize) -> T + Sync,
    ) -> Result<()> {
        use rayon::prelude::*;
        // Values a task writes: small enough to spread a piece's few thousand boxes.
        const TASK_VALUES: usize = 1024;
        let size = std::mem::size_of::<T>();
        let per_region = (self.region_bytes() as usize / size.max(1)).max(1);
        let mut k = 0;
        while k < count {
            let n = per_region.min(count - k);
            self.upload_in_place(ctx, dst, dst_offset + (k * size) as u64, n * size, |out| {
                out.par_chunks_mut(TASK_VALUES * size.max(1))
                    .enumerate()
                    .for_each(|(task, part)| {
                        let first = k + task * TASK_VALUES;
                        for (j, slot) in part.chunks_exact_mut(size).enumerate() {
                            slot.copy_from_slice(bytemuck::bytes_of(&value(first + j)));
                        }
                    });
            })?;
            k += n;
        }
        Ok(())
    }

    /// Records the queued copies into `rec` (whose submission the caller fences before the
    /// ring region is reused, and before any queued destination is freed) and moves to the
    /// other half. Returns whether anything was recorded.
    pub(crate) fn record_pending(&mut self, rec: &mut CommandRecorder<'_>) -> Result<bool> {
        let any = !self.pending.is_empty();
        // The staging buffer outlives the submission (freed only after every build batch was
        // waited on), like the destinations.
        let recorded = rec.copy_regions(self.staging.target(), &self.pending);
        self.pending.clear();
        if self.double_buffered {
            self.half ^= 1;
        }
        self.cursor = self.region().0;
        recorded?;
        Ok(any)
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
        // The staging buffer and every queued destination are alive until this function
        // returns (callers keep them; the submission is waited on).
        let mut rec = ctx.record("upload")?;
        let r = rec.copy_regions(self.staging.target(), &self.pending);
        let t = Instant::now();
        let r = r.and_then(|()| rec.submit_and_wait());
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
pub(crate) struct MeshStager<'s, 'v> {
    pub(crate) ctx: &'s Context,
    pub(crate) up: &'s mut Uploader,
    pub(crate) source: &'s dyn MeshBlobSource,
    pub(crate) view: &'s HierarchyView<'v>,
    /// Build index → BLAS index.
    pub(crate) order: &'s [usize],
    pub(crate) meshes: &'s [Option<MeshGpu>],
    pub(crate) staged: Vec<bool>,
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

    fn record(&mut self, rec: &mut CommandRecorder<'_>) -> Result<bool> {
        // Per the trait contract; the mesh buffers live in the scene being built.
        self.up.record_pending(rec)
    }

    fn abandon(&mut self) {
        self.up.abandon();
    }
}

/// Usages of a mesh buffer: read by shaders and AS builds, written by uploads, and copied from
/// when a streamer moves it to empty a memory block.
const MESH_USAGE: BufferUsage = BufferUsage::STORAGE
    .union(BufferUsage::DEVICE_ADDRESS)
    .union(BufferUsage::TRANSFER_DST)
    .union(BufferUsage::TRANSFER_SRC)
    .union(BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT);

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

/// Where a mesh's parts lie in its buffer.
struct MeshLayout {
    /// Offset of the indices (after the positions, 16-byte aligned).
    idx_offset: u64,
    /// Bytes of positions, indices and a cluster's primitive map (16-byte aligned when
    /// attributes follow).
    geometry: u64,
    normal_bytes: u64,
    uv_bytes: u64,
    size_bytes: u64,
}

impl MeshLayout {
    fn of(rec: &MeshRecord, attributes: bool) -> MeshLayout {
        let pos_bytes = u64::from(rec.vertex_count) * 12;
        let idx_offset = pos_bytes.div_ceil(16) * 16;
        let map_bytes = if rec.flags & motu_abi::FLAG_PRIMITIVE_MAP != 0 {
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
        MeshLayout {
            idx_offset,
            geometry,
            normal_bytes,
            uv_bytes,
            size_bytes: geometry + normal_bytes + uv_bytes,
        }
    }
}

/// Bytes of the buffer [`MeshGpu::alloc_streamed`] gives mesh record `rec`.
pub(crate) fn streamed_mesh_bytes(rec: &MeshRecord) -> u64 {
    MeshLayout::of(rec, true).size_bytes
}

impl MeshGpu {
    /// Allocates the buffer of mesh record `m` (positions, then indices at a 16-byte offset,
    /// then a cluster's primitive map).
    pub(crate) fn alloc(heap: &mut GpuHeap, m: usize, rec: &MeshRecord) -> Result<MeshGpu> {
        Self::alloc_with(heap, m, rec, false, MemoryClass::DeviceLocal)
    }

    /// [`MeshGpu::alloc`] plus room for the mesh's shading attributes after its geometry (the
    /// streaming renderer: they must be resident whenever a hit on the mesh is resolved).
    /// in memory of `class` (host-visible: the streamer's meshes on a discrete GPU, read by
    /// shaders and builds over the bus and written in place, outside the VRAM budget).
    pub(crate) fn alloc_streamed(
        heap: &mut GpuHeap,
        m: usize,
        rec: &MeshRecord,
        class: MemoryClass,
    ) -> Result<MeshGpu> {
        Self::alloc_with(heap, m, rec, true, class)
    }

    fn alloc_with(
        heap: &mut GpuHeap,
        m: usize,
        rec: &MeshRecord,
        attributes: bool,
        class: MemoryClass,
    ) -> Result<MeshGpu> {
        let layout = MeshLayout::of(rec, attributes);
        let buf = heap.alloc_buffer(
            &format!("mesh-{m}"),
            layout.size_bytes,
            MESH_USAGE,
            AllocKind::Geometry,
            class,
            16,
        )?;
        let base = match buf.device_address() {
            Ok(a) => a.0,
            Err(e) => {
                heap.free(buf);
                return Err(e.into());
            }
        };
        let MeshLayout {
            idx_offset,
            geometry,
            normal_bytes,
            uv_bytes,
            ..
        } = layout;
        Ok(MeshGpu {
            buffer: buf,
            positions_address: base,
            indices_address: base + idx_offset,
            vertex_count: rec.vertex_count,
            triangle_count: rec.triangle_count,
            has_primitive_map: rec.flags & motu_abi::FLAG_PRIMITIVE_MAP != 0,
            normals_address: if normal_bytes > 0 { base + geometry } else { 0 },
            uvs_address: if uv_bytes > 0 {
                base + geometry + normal_bytes
            } else {
                0
            },
        })
    }

    /// A new buffer for this mesh's bytes (the caller copies them and swaps it in with
    /// [`MeshGpu::moved_to`]): a streamer emptying a memory block.
    pub(crate) fn alloc_move_target(&self, heap: &mut GpuHeap, m: usize) -> Result<HeapBuffer> {
        heap.alloc_buffer(
            &format!("mesh-{m}-moved"),
            self.buffer.size_bytes(),
            MESH_USAGE,
            AllocKind::Geometry,
            self.memory_class(),
            16,
        )
        .map_err(Into::into)
    }

    /// The memory its buffer lives in (host-visible ones are host-mapped).
    pub(crate) fn memory_class(&self) -> MemoryClass {
        if self.buffer.is_host_mapped() {
            MemoryClass::HostVisible
        } else {
            MemoryClass::DeviceLocal
        }
    }

    /// Writes `bytes` at `offset` of its buffer: in place when host-mapped, else through the
    /// staging ring (a fresh buffer no submission reads yet, so either order is safe).
    fn put(&self, ctx: &Context, up: &mut Uploader, offset: u64, bytes: &[u8]) -> Result<()> {
        if self.buffer.is_host_mapped() {
            self.buffer.write_bytes(offset, bytes).map_err(Into::into)
        } else {
            up.upload(ctx, &self.buffer, offset, bytes)
        }
    }

    /// This mesh in `buffer` (a copy of its bytes); returns the old buffer to free once no
    /// submission reads it.
    pub(crate) fn moved_to(&mut self, buffer: HeapBuffer) -> Result<HeapBuffer> {
        let old_base = self.positions_address;
        let new_base = buffer.device_address()?.0;
        let rebase = |a: u64| if a == 0 { 0 } else { a - old_base + new_base };
        self.indices_address = rebase(self.indices_address);
        self.normals_address = rebase(self.normals_address);
        self.uvs_address = rebase(self.uvs_address);
        self.positions_address = new_base;
        Ok(std::mem::replace(&mut self.buffer, buffer))
    }

    /// Bytes of its buffer.
    pub(crate) fn size_bytes(&self) -> u64 {
        self.buffer.size_bytes()
    }

    /// Loads mesh record `m` from `source`, checks it against the record and queues its upload
    /// (a mesh from [`MeshGpu::alloc`]: its geometry; streamed meshes go through
    /// [`upload_streamed_group`]).
    pub(crate) fn upload(
        &self,
        ctx: &Context,
        up: &mut Uploader,
        source: &dyn MeshBlobSource,
        m: usize,
    ) -> Result<u64> {
        let bytes = self.read_bytes(source, m)?;
        let mut pieces = Vec::new();
        self.pieces(&bytes, &mut pieces);
        for p in &pieces {
            self.put(ctx, up, p.dst_offset, p.src)?;
        }
        Ok(bytes.len_bytes())
    }
}

#[cfg(test)]
mod tests;
