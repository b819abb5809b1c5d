//! Acceleration-structure objects: an AS in its heap buffer, and the compacted-size queries of
//! a build batch.

use ash::vk;
use motu_alloc::{AllocKind, MemoryClass};

use crate::accel::{AsLevel, AsTarget, ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT};
use crate::context::Context;
use crate::error::{Result, VkError};
use crate::heap::{GpuHeap, HeapBuffer};
use crate::memory::BufferUsage;

/// An acceleration structure in a heap buffer. Destroyed before its buffer (Drop order).
pub struct AccelStruct {
    ctx: Context,
    handle: vk::AccelerationStructureKHR,
    /// Its device address (what TLAS instance records and the shaders' tables hold).
    pub address: u64,
    /// The bytes it takes in its buffer.
    pub size_bytes: u64,
    buffer: Option<HeapBuffer>,
}

impl AccelStruct {
    /// A structure of `level` taking `size_bytes` of a new heap buffer (accounted as TLAS or
    /// BLAS storage).
    pub fn new(
        ctx: &Context,
        heap: &mut GpuHeap,
        label: &str,
        size_bytes: u64,
        level: AsLevel,
    ) -> Result<AccelStruct> {
        Self::new_in(
            ctx,
            heap,
            label,
            size_bytes,
            level,
            MemoryClass::DeviceLocal,
        )
    }

    /// [`new`](Self::new) in `class` memory: `HostVisible` keeps a structure in host memory,
    /// outside a discrete GPU's VRAM budget (a copy to restore from by a device-side clone,
    /// never traced there).
    pub fn new_in(
        ctx: &Context,
        heap: &mut GpuHeap,
        label: &str,
        size_bytes: u64,
        level: AsLevel,
        class: MemoryClass,
    ) -> Result<AccelStruct> {
        let kind = match level {
            AsLevel::Top => AllocKind::TlasStorage,
            AsLevel::Bottom => AllocKind::BlasStorage,
        };
        let buffer = heap.alloc_buffer(
            label,
            size_bytes,
            BufferUsage::ACCELERATION_STRUCTURE_STORAGE,
            kind,
            class,
            ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT,
        )?;
        let accel = ctx.accel_device()?;
        let info = vk::AccelerationStructureCreateInfoKHR::default()
            .buffer(buffer.handle())
            .offset(0)
            .size(size_bytes)
            .ty(crate::conv::as_level(level));
        // SAFETY: the buffer is bound, has AS-storage usage and holds `size_bytes`.
        let handle = match unsafe { accel.create_acceleration_structure(&info, None) } {
            Ok(h) => h,
            Err(e) => {
                heap.free(buffer);
                return Err(VkError::Vulkan {
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

    /// The structure as recorded commands name it (builds, copies, compacted-size queries).
    pub fn target(&self) -> AsTarget {
        AsTarget(self.handle)
    }

    /// The heap allocation holding the structure.
    pub fn allocation_id(&self) -> Option<motu_alloc::AllocationId> {
        self.buffer.as_ref().map(|b| b.id())
    }

    /// Destroys the structure and returns its memory to the heap.
    pub fn release(mut self, heap: &mut GpuHeap) {
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

/// A pool of acceleration-structure size queries: compacted sizes, or serialised sizes.
pub struct SizeQueries {
    ctx: Context,
    pub(crate) pool: vk::QueryPool,
    pub(crate) count: u32,
    pub(crate) kind: vk::QueryType,
}

impl SizeQueries {
    /// A pool of `count` (at least one) compacted-size queries.
    pub fn new(ctx: &Context, count: u32) -> Result<SizeQueries> {
        Self::of_kind(
            ctx,
            count,
            vk::QueryType::ACCELERATION_STRUCTURE_COMPACTED_SIZE_KHR,
        )
    }

    /// A pool of `count` (at least one) serialised-size queries (`crate::serialize`).
    pub fn serialization(ctx: &Context, count: u32) -> Result<SizeQueries> {
        Self::of_kind(
            ctx,
            count,
            vk::QueryType::ACCELERATION_STRUCTURE_SERIALIZATION_SIZE_KHR,
        )
    }

    fn of_kind(ctx: &Context, count: u32, kind: vk::QueryType) -> Result<SizeQueries> {
        let info = vk::QueryPoolCreateInfo::default()
            .query_type(kind)
            .query_count(count.max(1));
        // SAFETY: valid create info; the AS extension is enabled (caller checked).
        let pool = unsafe { ctx.shared.device.create_query_pool(&info, None) }
            .map_err(VkError::vk("vkCreateQueryPool"))?;
        Ok(SizeQueries {
            ctx: ctx.clone(),
            pool,
            count: count.max(1),
            kind,
        })
    }

    /// The first `n` sizes, waiting for them (after the submission that wrote them).
    pub fn read(&self, n: u32) -> Result<Vec<u64>> {
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
        .map_err(VkError::vk("vkGetQueryPoolResults"))?;
        Ok(out)
    }
}

impl Drop for SizeQueries {
    fn drop(&mut self) {
        // SAFETY: no pending submission uses the pool (all are fenced).
        unsafe { self.ctx.shared.device.destroy_query_pool(self.pool, None) };
    }
}
