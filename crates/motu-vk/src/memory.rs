//! Device memory and buffers. Creating a buffer, allocating memory and binding at an offset are
//! separate steps so a sub-allocator can place many buffers into a few large blocks.

use std::sync::atomic::Ordering;
use std::sync::{Arc, Mutex};

use ash::vk;

use crate::context::{Context, DeviceShared};
use crate::error::{Result, VkError};

/// Where memory lives, from the host's point of view.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum MemoryLocation {
    /// Device-local, not mapped: geometry, AS storage, scratch.
    DeviceLocal,
    /// Host-visible and coherent, preferably not device-local (staging, instance uploads).
    Upload,
    /// Host-visible and coherent, preferably cached (readback of results, AOVs, queries).
    Readback,
}

/// A GPU virtual address (`vkGetBufferDeviceAddress`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct DeviceAddress(pub u64);

impl DeviceAddress {
    pub fn offset(self, bytes: u64) -> DeviceAddress {
        DeviceAddress(self.0 + bytes)
    }
}

/// What a buffer will be used for (a subset of `VkBufferUsageFlags`, as plain Rust).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct BufferUsage(u32);

impl BufferUsage {
    pub const TRANSFER_SRC: Self = Self(1);
    pub const TRANSFER_DST: Self = Self(1 << 1);
    pub const STORAGE: Self = Self(1 << 2);
    pub const UNIFORM: Self = Self(1 << 3);
    pub const INDIRECT: Self = Self(1 << 4);
    /// `SHADER_DEVICE_ADDRESS`: needed for `Buffer::device_address`.
    pub const DEVICE_ADDRESS: Self = Self(1 << 5);
    /// Backing storage of acceleration structures.
    pub const ACCELERATION_STRUCTURE_STORAGE: Self = Self(1 << 6);
    /// Vertices, indices, AABBs, instances read by AS builds.
    pub const ACCELERATION_STRUCTURE_BUILD_INPUT: Self = Self(1 << 7);
    pub const SHADER_BINDING_TABLE: Self = Self(1 << 8);

    pub const fn union(self, other: Self) -> Self {
        Self(self.0 | other.0)
    }
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }

    pub(crate) fn to_vk(self) -> vk::BufferUsageFlags {
        let map = [
            (Self::TRANSFER_SRC, vk::BufferUsageFlags::TRANSFER_SRC),
            (Self::TRANSFER_DST, vk::BufferUsageFlags::TRANSFER_DST),
            (Self::STORAGE, vk::BufferUsageFlags::STORAGE_BUFFER),
            (Self::UNIFORM, vk::BufferUsageFlags::UNIFORM_BUFFER),
            (Self::INDIRECT, vk::BufferUsageFlags::INDIRECT_BUFFER),
            (
                Self::DEVICE_ADDRESS,
                vk::BufferUsageFlags::SHADER_DEVICE_ADDRESS,
            ),
            (
                Self::ACCELERATION_STRUCTURE_STORAGE,
                vk::BufferUsageFlags::ACCELERATION_STRUCTURE_STORAGE_KHR,
            ),
            (
                Self::ACCELERATION_STRUCTURE_BUILD_INPUT,
                vk::BufferUsageFlags::ACCELERATION_STRUCTURE_BUILD_INPUT_READ_ONLY_KHR,
            ),
            (
                Self::SHADER_BINDING_TABLE,
                vk::BufferUsageFlags::SHADER_BINDING_TABLE_KHR,
            ),
        ];
        map.iter()
            .filter(|(u, _)| self.contains(*u))
            .fold(vk::BufferUsageFlags::empty(), |acc, (_, f)| acc | *f)
    }
}

impl std::ops::BitOr for BufferUsage {
    type Output = Self;
    fn bitor(self, rhs: Self) -> Self {
        self.union(rhs)
    }
}

/// Size, alignment and allowed memory types for placing a buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MemoryRequirements {
    pub size_bytes: u64,
    pub alignment_bytes: u64,
    /// Bit i set: memory type i may back the resource.
    pub memory_type_bits: u32,
}

mod ranges;
pub use ranges::{with_mapped_ranges_mut, MappedRange};

struct Mapping(*mut u8);
// SAFETY: the pointer is into a persistently mapped VkDeviceMemory owned by the same
// DeviceMemory; all host access goes through the Mutex around it.
unsafe impl Send for Mapping {}

/// One `vkAllocateMemory` allocation. Counted against `max_memory_allocation_count`; host-visible
/// locations are mapped persistently.
pub struct DeviceMemory {
    shared: Arc<DeviceShared>,
    handle: vk::DeviceMemory,
    size_bytes: u64,
    memory_type_index: u32,
    location: MemoryLocation,
    mapping: Option<Mutex<Mapping>>,
}

impl std::fmt::Debug for DeviceMemory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DeviceMemory")
            .field("size_bytes", &self.size_bytes)
            .field("memory_type_index", &self.memory_type_index)
            .field("location", &self.location)
            .finish()
    }
}

impl Context {
    /// The memory type for `location` among `type_bits`, preferring the ideal flags.
    pub fn memory_type_index(&self, location: MemoryLocation, type_bits: u32) -> Result<u32> {
        let mp = &self.shared.info.memory;
        let (required, preferred, avoided) = match location {
            MemoryLocation::DeviceLocal => (
                vk::MemoryPropertyFlags::DEVICE_LOCAL,
                vk::MemoryPropertyFlags::empty(),
                vk::MemoryPropertyFlags::empty(),
            ),
            MemoryLocation::Upload => (
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                vk::MemoryPropertyFlags::empty(),
                vk::MemoryPropertyFlags::DEVICE_LOCAL,
            ),
            MemoryLocation::Readback => (
                vk::MemoryPropertyFlags::HOST_VISIBLE | vk::MemoryPropertyFlags::HOST_COHERENT,
                vk::MemoryPropertyFlags::HOST_CACHED,
                vk::MemoryPropertyFlags::empty(),
            ),
        };
        let count = (mp.memory_type_count as usize).min(vk::MAX_MEMORY_TYPES);
        let candidates = (0..count as u32).filter(|&i| {
            type_bits & (1 << i) != 0
                && mp.memory_types[i as usize]
                    .property_flags
                    .contains(required)
        });
        candidates
            .max_by_key(|&i| {
                let f = mp.memory_types[i as usize].property_flags;
                // Higher is better; ties keep the lowest index (the driver's preferred order).
                (
                    f.contains(preferred) as u8 * 2 + !f.intersects(avoided) as u8,
                    std::cmp::Reverse(i),
                )
            })
            .ok_or(VkError::NoMemoryType {
                location,
                type_bits,
            })
    }
}

impl DeviceMemory {
    /// Allocates `size_bytes` of memory type `memory_type_index` (see
    /// [`Context::memory_type_index`]). Enforces the allocation count and size limits in force.
    /// With buffer device address enabled, the memory is allocated with `DEVICE_ADDRESS`.
    pub fn allocate(
        ctx: &Context,
        size_bytes: u64,
        memory_type_index: u32,
        location: MemoryLocation,
    ) -> Result<Arc<DeviceMemory>> {
        let shared = &ctx.shared;
        if size_bytes == 0 {
            return Err(VkError::InvalidRequest(
                "zero-sized memory allocation".into(),
            ));
        }
        let limit_bytes = shared.limits.max_memory_allocation_size;
        if size_bytes > limit_bytes {
            return Err(VkError::AllocationTooLarge {
                size_bytes,
                limit_bytes,
            });
        }
        // Reserve a slot in the count first, so concurrent allocations cannot overshoot.
        let limit = shared.limits.max_memory_allocation_count;
        let reserved =
            shared
                .live_allocations
                .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                    (n < limit).then_some(n + 1)
                });
        let live = match reserved {
            Ok(prev) => prev + 1,
            Err(prev) => {
                return Err(VkError::AllocationCountExceeded {
                    requested: prev.saturating_add(1),
                    limit,
                })
            }
        };
        let release_slot = || {
            shared.live_allocations.fetch_sub(1, Ordering::AcqRel);
        };

        let mut flags_info =
            vk::MemoryAllocateFlagsInfo::default().flags(vk::MemoryAllocateFlags::DEVICE_ADDRESS);
        let mut info = vk::MemoryAllocateInfo::default()
            .allocation_size(size_bytes)
            .memory_type_index(memory_type_index);
        if shared.info.caps.buffer_device_address {
            info = info.push_next(&mut flags_info);
        }
        // SAFETY: valid allocate info for this device; the count limit was checked above.
        let handle = match unsafe { shared.device.allocate_memory(&info, None) } {
            Ok(h) => h,
            Err(e) => {
                release_slot();
                return Err(VkError::Vulkan {
                    call: "vkAllocateMemory",
                    result: e,
                });
            }
        };
        let host_visible = shared.info.memory.memory_types[memory_type_index as usize]
            .property_flags
            .contains(vk::MemoryPropertyFlags::HOST_VISIBLE);
        let mapping = if host_visible && location != MemoryLocation::DeviceLocal {
            // SAFETY: the memory is host-visible, not yet mapped, and the range is its whole size.
            match unsafe {
                shared
                    .device
                    .map_memory(handle, 0, vk::WHOLE_SIZE, vk::MemoryMapFlags::empty())
            } {
                Ok(p) => Some(Mutex::new(Mapping(p.cast()))),
                Err(e) => {
                    // SAFETY: allocated above and not used by anything.
                    unsafe { shared.device.free_memory(handle, None) };
                    release_slot();
                    return Err(VkError::Vulkan {
                        call: "vkMapMemory",
                        result: e,
                    });
                }
            }
        } else {
            None
        };
        shared.peak_allocations.fetch_max(live, Ordering::Relaxed);
        shared
            .allocated_bytes
            .fetch_add(size_bytes, Ordering::Relaxed);
        tracing::trace!(size_bytes, memory_type_index, live, "vkAllocateMemory");
        Ok(Arc::new(DeviceMemory {
            shared: Arc::clone(shared),
            handle,
            size_bytes,
            memory_type_index,
            location,
            mapping,
        }))
    }

    pub fn size_bytes(&self) -> u64 {
        self.size_bytes
    }
    pub fn memory_type_index(&self) -> u32 {
        self.memory_type_index
    }
    pub fn location(&self) -> MemoryLocation {
        self.location
    }
    pub fn is_mapped(&self) -> bool {
        self.mapping.is_some()
    }

    fn check_range(&self, offset: u64, len: usize) -> Result<()> {
        let end = offset.checked_add(len as u64);
        if end.is_none_or(|e| e > self.size_bytes) {
            return Err(VkError::InvalidRequest(format!(
                "host access of {len} bytes at offset {offset} exceeds the {}-byte allocation",
                self.size_bytes
            )));
        }
        Ok(())
    }

    fn mapping(&self) -> Result<std::sync::MutexGuard<'_, Mapping>> {
        let m = self.mapping.as_ref().ok_or_else(|| {
            VkError::InvalidRequest(format!("memory at {:?} is not host-mapped", self.location))
        })?;
        Ok(m.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// Copies `data` into the mapping at `offset` (coherent memory: no flush needed). The GPU
    /// must not be using the range (all motu submissions are fenced before returning).
    pub fn write_bytes(&self, offset: u64, data: &[u8]) -> Result<()> {
        self.with_mapped_mut(offset, data.len(), |bytes| bytes.copy_from_slice(data))
    }

    /// Lends the mapping's bytes `offset..offset + len` to `fill`, which writes them in place
    /// (same conditions as `write_bytes`; the lock is held while `fill` runs).
    pub fn with_mapped_mut<R>(
        &self,
        offset: u64,
        len: usize,
        fill: impl FnOnce(&mut [u8]) -> R,
    ) -> Result<R> {
        self.check_range(offset, len)?;
        let map = self.mapping()?;
        // SAFETY: the range is inside the persistently mapped allocation (checked above); the
        // mapping lock, held until `fill` returns, keeps every other host access out, so the
        // slice is the only reference to these bytes while it lives.
        let bytes = unsafe { std::slice::from_raw_parts_mut(map.0.add(offset as usize), len) };
        Ok(fill(bytes))
    }

    /// Copies from the mapping at `offset` into `out` (same conditions as `write_bytes`).
    pub fn read_bytes(&self, offset: u64, out: &mut [u8]) -> Result<()> {
        self.check_range(offset, out.len())?;
        let map = self.mapping()?;
        // SAFETY: as for write_bytes.
        unsafe {
            std::ptr::copy_nonoverlapping(map.0.add(offset as usize), out.as_mut_ptr(), out.len())
        };
        Ok(())
    }
}

impl Drop for DeviceMemory {
    fn drop(&mut self) {
        // SAFETY: every buffer bound to this memory holds an Arc to it, so none is alive; GPU
        // work using it was fenced before the owning buffers were dropped. Freeing unmaps.
        unsafe { self.shared.device.free_memory(self.handle, None) };
        self.shared.live_allocations.fetch_sub(1, Ordering::AcqRel);
        self.shared
            .allocated_bytes
            .fetch_sub(self.size_bytes, Ordering::Relaxed);
    }
}

/// What `Buffer::new` creates.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BufferDesc {
    pub size_bytes: u64,
    pub usage: BufferUsage,
}

/// A `VkBuffer`, optionally bound to (a range of) a [`DeviceMemory`] it keeps alive.
pub struct Buffer {
    shared: Arc<DeviceShared>,
    handle: vk::Buffer,
    size_bytes: u64,
    usage: BufferUsage,
    requirements: MemoryRequirements,
    binding: Option<(Arc<DeviceMemory>, u64)>,
    label: String,
}

impl std::fmt::Debug for Buffer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Buffer")
            .field("label", &self.label)
            .field("size_bytes", &self.size_bytes)
            .field("usage", &self.usage)
            .field("bound_offset", &self.binding.as_ref().map(|b| b.1))
            .finish()
    }
}

impl Buffer {
    /// Creates an unbound buffer. Respects `max_buffer_size`; acceleration-structure usages get
    /// `DEVICE_ADDRESS` added because builds address them.
    pub fn new(ctx: &Context, label: &str, desc: &BufferDesc) -> Result<Buffer> {
        let shared = &ctx.shared;
        if desc.size_bytes == 0 {
            return Err(VkError::InvalidRequest(format!(
                "buffer {label:?} has size 0"
            )));
        }
        if let Some(max) = shared.info.limits.max_buffer_size {
            if desc.size_bytes > max {
                return Err(VkError::InvalidRequest(format!(
                    "buffer {label:?} of {} bytes exceeds maxBufferSize {max}",
                    desc.size_bytes
                )));
            }
        }
        let mut usage = desc.usage;
        if usage.contains(BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT)
            || usage.contains(BufferUsage::ACCELERATION_STRUCTURE_STORAGE)
            || usage.contains(BufferUsage::SHADER_BINDING_TABLE)
        {
            usage = usage | BufferUsage::DEVICE_ADDRESS;
        }
        if usage.contains(BufferUsage::DEVICE_ADDRESS) && !shared.info.caps.buffer_device_address {
            return Err(VkError::MissingFeature {
                what: "bufferDeviceAddress".into(),
                details: format!(
                    "buffer {label:?} needs it; device {} lacks it",
                    shared.info.name
                ),
            });
        }
        let info = vk::BufferCreateInfo::default()
            .size(desc.size_bytes)
            .usage(usage.to_vk())
            .sharing_mode(vk::SharingMode::EXCLUSIVE);
        // SAFETY: valid create info; usage bits map to enabled features (checked above).
        let handle = unsafe { shared.device.create_buffer(&info, None) }
            .map_err(VkError::vk("vkCreateBuffer"))?;
        shared.set_name(handle, label);
        // SAFETY: the buffer was just created from this device.
        let req = unsafe { shared.device.get_buffer_memory_requirements(handle) };
        Ok(Buffer {
            shared: Arc::clone(shared),
            handle,
            size_bytes: desc.size_bytes,
            usage,
            requirements: MemoryRequirements {
                size_bytes: req.size,
                alignment_bytes: req.alignment,
                memory_type_bits: req.memory_type_bits,
            },
            binding: None,
            label: label.to_string(),
        })
    }

    /// Binds the buffer at `offset` in `memory`. Checks alignment, type and range.
    pub fn bind(&mut self, memory: &Arc<DeviceMemory>, offset: u64) -> Result<()> {
        let req = self.requirements;
        if self.binding.is_some() {
            return Err(VkError::InvalidRequest(format!(
                "buffer {:?} is already bound",
                self.label
            )));
        }
        if !Arc::ptr_eq(&memory.shared, &self.shared) {
            return Err(VkError::InvalidRequest(
                "memory belongs to another device".into(),
            ));
        }
        if offset % req.alignment_bytes != 0 {
            return Err(VkError::InvalidRequest(format!(
                "buffer {:?}: offset {offset} is not a multiple of its alignment {}",
                self.label, req.alignment_bytes
            )));
        }
        if req.memory_type_bits & (1 << memory.memory_type_index) == 0 {
            return Err(VkError::InvalidRequest(format!(
                "buffer {:?} cannot live in memory type {} (allowed bits {:#b})",
                self.label, memory.memory_type_index, req.memory_type_bits
            )));
        }
        if offset
            .checked_add(req.size_bytes)
            .is_none_or(|end| end > memory.size_bytes)
        {
            return Err(VkError::InvalidRequest(format!(
                "buffer {:?} needs {} bytes at offset {offset}; the memory holds {}",
                self.label, req.size_bytes, memory.size_bytes
            )));
        }
        // SAFETY: buffer and memory belong to this device, the buffer is unbound, and offset,
        // alignment and memory type satisfy its requirements (checked above).
        unsafe {
            self.shared
                .device
                .bind_buffer_memory(self.handle, memory.handle, offset)
        }
        .map_err(VkError::vk("vkBindBufferMemory"))?;
        self.binding = Some((Arc::clone(memory), offset));
        Ok(())
    }

    /// Creates a buffer with its own (dedicated) allocation. Fine for small/test resources; bulk
    /// data should be sub-allocated to stay under `max_memory_allocation_count`.
    pub fn new_dedicated(
        ctx: &Context,
        label: &str,
        desc: &BufferDesc,
        location: MemoryLocation,
    ) -> Result<Buffer> {
        let mut buffer = Buffer::new(ctx, label, desc)?;
        let req = buffer.requirements;
        let type_index = ctx.memory_type_index(location, req.memory_type_bits)?;
        let memory = DeviceMemory::allocate(ctx, req.size_bytes, type_index, location)?;
        buffer.bind(&memory, 0)?;
        Ok(buffer)
    }

    pub fn label(&self) -> &str {
        &self.label
    }
    pub fn size_bytes(&self) -> u64 {
        self.size_bytes
    }
    pub fn usage(&self) -> BufferUsage {
        self.usage
    }
    pub fn memory_requirements(&self) -> MemoryRequirements {
        self.requirements
    }
    /// The memory and offset the buffer is bound at.
    pub fn binding(&self) -> Option<(&Arc<DeviceMemory>, u64)> {
        self.binding.as_ref().map(|(m, o)| (m, *o))
    }

    pub(crate) fn handle(&self) -> vk::Buffer {
        self.handle
    }

    pub(crate) fn check_bound(&self) -> Result<()> {
        if self.binding.is_none() {
            return Err(VkError::InvalidRequest(format!(
                "buffer {:?} is used before being bound to memory",
                self.label
            )));
        }
        Ok(())
    }

    pub(crate) fn same_device(&self, ctx: &Arc<DeviceShared>) -> bool {
        Arc::ptr_eq(&self.shared, ctx)
    }

    /// The buffer's GPU address (needs `BufferUsage::DEVICE_ADDRESS` and a binding).
    pub fn device_address(&self) -> Result<DeviceAddress> {
        if !self.usage.contains(BufferUsage::DEVICE_ADDRESS) {
            return Err(VkError::InvalidRequest(format!(
                "buffer {:?} was created without DEVICE_ADDRESS usage",
                self.label
            )));
        }
        self.check_bound()?;
        let info = vk::BufferDeviceAddressInfo::default().buffer(self.handle);
        // SAFETY: the buffer is bound and has SHADER_DEVICE_ADDRESS usage; the feature is on.
        Ok(DeviceAddress(unsafe {
            self.shared.device.get_buffer_device_address(&info)
        }))
    }

    /// Whether the buffer is bound to host-mapped memory (writable with
    /// [`Buffer::write_bytes`] without a staging copy).
    pub fn is_host_mapped(&self) -> bool {
        self.binding
            .as_ref()
            .is_some_and(|(mem, _)| mem.is_mapped())
    }

    fn mapped(&self) -> Result<(&Arc<DeviceMemory>, u64)> {
        let (mem, base) = self.binding.as_ref().ok_or_else(|| {
            VkError::InvalidRequest(format!("buffer {:?} is not bound", self.label))
        })?;
        Ok((mem, *base))
    }

    fn check_range(&self, offset: u64, len: usize) -> Result<()> {
        if offset
            .checked_add(len as u64)
            .is_none_or(|e| e > self.size_bytes)
        {
            return Err(VkError::InvalidRequest(format!(
                "access of {len} bytes at offset {offset} exceeds buffer {:?} ({} bytes)",
                self.label, self.size_bytes
            )));
        }
        Ok(())
    }

    /// Writes bytes at `offset` (host-mapped memory only).
    pub fn write_bytes(&self, offset: u64, data: &[u8]) -> Result<()> {
        self.check_range(offset, data.len())?;
        let (mem, base) = self.mapped()?;
        mem.write_bytes(base + offset, data)
    }

    /// Lends bytes `offset..offset + len` to `fill` to write in place (host-mapped memory only).
    pub fn with_mapped_mut<R>(
        &self,
        offset: u64,
        len: usize,
        fill: impl FnOnce(&mut [u8]) -> R,
    ) -> Result<R> {
        self.check_range(offset, len)?;
        let (mem, base) = self.mapped()?;
        mem.with_mapped_mut(base + offset, len, fill)
    }

    /// Writes plain-old-data values at `offset` (host-mapped memory only).
    pub fn write<T: bytemuck::Pod>(&self, offset: u64, values: &[T]) -> Result<()> {
        self.write_bytes(offset, bytemuck::cast_slice(values))
    }

    /// Reads bytes at `offset` (host-mapped memory only).
    pub fn read_bytes(&self, offset: u64, out: &mut [u8]) -> Result<()> {
        self.check_range(offset, out.len())?;
        let (mem, base) = self.mapped()?;
        mem.read_bytes(base + offset, out)
    }

    /// Reads `count` values of `T` starting at `offset` (host-mapped memory only).
    pub fn read_vec<T: bytemuck::Pod>(&self, offset: u64, count: usize) -> Result<Vec<T>> {
        let mut out = vec![T::zeroed(); count];
        self.read_bytes(offset, bytemuck::cast_slice_mut(&mut out))?;
        Ok(out)
    }
}

impl Drop for Buffer {
    fn drop(&mut self) {
        // SAFETY: the buffer belongs to this device; every submission using it was waited on
        // before the borrow that recorded it ended (see `CommandRecorder`).
        unsafe { self.shared.device.destroy_buffer(self.handle, None) };
    }
}
