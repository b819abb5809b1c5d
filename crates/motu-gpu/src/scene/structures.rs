//! Acceleration-structure objects and table slots: an AS in its heap buffer, and the
//! compacted-size queries of a build batch.

use ash::vk;
use motu_alloc::{AllocKind, MemoryClass};

use crate::accel::ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT;
use crate::context::Context;
use crate::error::{GpuError, Result};
use crate::heap::{GpuHeap, HeapBuffer};
use crate::memory::BufferUsage;

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

    /// The heap allocation holding the structure.
    pub(crate) fn allocation_id(&self) -> Option<motu_alloc::AllocationId> {
        self.buffer.as_ref().map(|b| b.id)
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
pub(crate) struct SizeQueries {
    pub(crate) ctx: Context,
    pub(crate) pool: vk::QueryPool,
    pub(crate) count: u32,
}

impl SizeQueries {
    pub(crate) fn new(ctx: &Context, count: u32) -> Result<SizeQueries> {
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

    pub(crate) fn read(&self, n: u32) -> Result<Vec<u64>> {
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
