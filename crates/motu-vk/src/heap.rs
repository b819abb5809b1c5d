//! Budgeted GPU memory: applies `motu_alloc`'s block sub-allocation policy to real
//! `VkDeviceMemory` (one allocation per block), so the budget and the allocation-count cap hold
//! by construction.

use std::collections::HashMap;
use std::sync::Arc;

use motu_alloc::{
    AllocKind, AllocLimits, AllocPolicy, AllocReport, AllocRequest, AllocationId, Allocator,
    BlockEvent, BlockId, MemoryClass,
};

use crate::context::Context;
use crate::error::{BudgetRefusal, Result, VkError};
use crate::memory::{Buffer, BufferDesc, BufferUsage, DeviceMemory, MemoryLocation};

/// A buffer placed in a heap block; give it back with [`GpuHeap::free`] (dropping it without
/// freeing only leaks its range in the policy, never device memory).
#[derive(Debug)]
pub struct HeapBuffer {
    pub buffer: Buffer,
    id: AllocationId,
    pub kind: AllocKind,
}

impl HeapBuffer {
    /// The policy's id of the allocation (what [`GpuHeap::allocations_in`] lists).
    pub fn id(&self) -> AllocationId {
        self.id
    }
}

impl std::ops::Deref for HeapBuffer {
    type Target = Buffer;
    fn deref(&self) -> &Buffer {
        &self.buffer
    }
}

/// `MOTU_SIMULATE_DISCRETE_MEMORY=1`: host-visible memory is counted apart from the budget
/// even where it is the same memory as device-local (see [`GpuHeap::with_blocks`]).
fn simulate_discrete_memory() -> bool {
    std::env::var_os("MOTU_SIMULATE_DISCRETE_MEMORY").is_some_and(|v| v == "1")
}

/// Where host-visible blocks live: a cached memory type where the device has one. The CPU
/// reads serialised structures back from them, and reads of uncached (write-combined) memory
/// crawl (H200, island 0.63: a cold structure cache stored 12 GB in 13 s, the frame's largest
/// cost), while writes to cached memory are as fast. `MOTU_HOST_MEMORY=write-combined` picks
/// the uncached type instead (for A/B measurements).
fn host_location() -> MemoryLocation {
    match std::env::var("MOTU_HOST_MEMORY").as_deref() {
        Ok("write-combined") => MemoryLocation::Upload,
        _ => MemoryLocation::Readback,
    }
}

/// Every usage a heap buffer may have: blocks get a memory type all of them accept.
const ALL_USAGES: BufferUsage = BufferUsage::TRANSFER_SRC
    .union(BufferUsage::TRANSFER_DST)
    .union(BufferUsage::STORAGE)
    .union(BufferUsage::DEVICE_ADDRESS)
    .union(BufferUsage::ACCELERATION_STRUCTURE_STORAGE)
    .union(BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT)
    .union(BufferUsage::SHADER_BINDING_TABLE);

/// Blocks a heap created ([`GpuHeap::created_blocks`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct BlockCounts {
    pub created: u64,
    pub bytes: u64,
    /// Of `created`: taken from the spare (made ahead, or a destroyed block kept).
    pub from_spare: u64,
}

/// One buffer of a [`GpuHeap::try_fit`] question.
#[derive(Clone, Copy, Debug)]
pub struct FitRequest<'l> {
    pub label: &'l str,
    pub size_bytes: u64,
    pub usage: BufferUsage,
    pub kind: AllocKind,
    pub class: MemoryClass,
    pub alignment: u64,
}

/// The policy's request for `buffer` (its memory requirements, aligned to at least
/// `alignment`).
fn alloc_request(
    buffer: &Buffer,
    kind: AllocKind,
    class: MemoryClass,
    alignment: u64,
) -> AllocRequest {
    let req = buffer.memory_requirements();
    let align = req
        .alignment_bytes
        .max(alignment)
        .max(1)
        .next_power_of_two();
    match class {
        MemoryClass::DeviceLocal => AllocRequest::device_local(kind, req.size_bytes, align),
        MemoryClass::HostVisible => AllocRequest::host_visible(kind, req.size_bytes, align),
    }
}

/// The allocator policy plus the memory blocks it decided to create.
pub struct GpuHeap {
    ctx: Context,
    allocator: Allocator,
    blocks: HashMap<BlockId, Arc<DeviceMemory>>,
    type_index: [u32; 2],
    /// The memory location of host-visible blocks ([`host_location`]).
    host_location: MemoryLocation,
    /// Blocks created (each a `vkAllocateMemory`, mapped where host-visible) and their bytes,
    /// per class: what a streamer's uploads paid for fresh memory ([`GpuHeap::created_blocks`]).
    created: [(u64, u64); 2],
    /// Host-visible standard blocks made ahead or kept ([`GpuHeap::set_host_blocks_ahead`]):
    /// whether on, the block in waiting, and the blocks taken from it.
    ahead: bool,
    spare: Option<spare::Spare>,
    spares_taken: u64,
}

mod spare;

impl std::fmt::Debug for GpuHeap {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuHeap")
            .field("blocks", &self.blocks.len())
            .field("limits", &self.allocator.limits())
            .finish()
    }
}

impl GpuHeap {
    /// A heap under `limits` (already combined with the device's limits by the caller).
    pub fn new(ctx: &Context, limits: AllocLimits) -> Result<GpuHeap> {
        Self::with_blocks(ctx, limits, None, None)
    }

    /// [`new`](Self::new) with standard blocks of `block_size_bytes` (`None`: the allocator's
    /// default, a 16th of the budget) and dedicated blocks for requests above
    /// `dedicated_above_bytes` (`None`: above the standard block; see
    /// [`AllocPolicy::dedicated_above_bytes`]). Streaming uses smaller blocks (partly used
    /// blocks count against its floor) and dedicated ones from half a block.
    pub fn with_blocks(
        ctx: &Context,
        limits: AllocLimits,
        block_size_bytes: Option<u64>,
        dedicated_above_bytes: Option<u64>,
    ) -> Result<GpuHeap> {
        let probe = Buffer::new(
            ctx,
            "heap-probe",
            &BufferDesc {
                size_bytes: 256,
                usage: ALL_USAGES,
            },
        )?;
        let bits = probe.memory_requirements().memory_type_bits;
        let device_local = ctx.memory_type_index(MemoryLocation::DeviceLocal, bits)?;
        let host_location = host_location();
        let upload = ctx.memory_type_index(host_location, bits)?;
        // Unified memory (lavapipe, integrated GPUs): host-visible blocks use the same heap.
        // MOTU_SIMULATE_DISCRETE_MEMORY=1 counts them apart as a discrete GPU does, so tests on
        // lavapipe can check what host memory outside the budget does (the counts only: the
        // memory is the same).
        let unified = device_local == upload && !simulate_discrete_memory();
        let policy = AllocPolicy {
            host_visible_counts_against_budget: unified,
            block_size_bytes,
            dedicated_above_bytes,
            ..AllocPolicy::default()
        };
        let allocator = Allocator::new(limits, policy).map_err(VkError::AllocatorLimits)?;
        Ok(GpuHeap {
            ctx: ctx.clone(),
            allocator,
            blocks: HashMap::new(),
            type_index: [device_local, upload],
            host_location,
            created: [(0, 0); 2],
            ahead: false,
            spare: None,
            spares_taken: 0,
        })
    }

    /// Creates a buffer of `size_bytes` in `class` memory, aligned to at least `alignment`.
    pub fn alloc_buffer(
        &mut self,
        label: &str,
        size_bytes: u64,
        usage: BufferUsage,
        kind: AllocKind,
        class: MemoryClass,
        alignment: u64,
    ) -> Result<HeapBuffer> {
        let mut buffer = Buffer::new(
            &self.ctx,
            label,
            &BufferDesc {
                size_bytes: size_bytes.max(4),
                usage,
            },
        )?;
        let request = alloc_request(&buffer, kind, class, alignment);
        let alloc = self
            .allocator
            .alloc(request)
            .map_err(|e| VkError::Budget(BudgetRefusal::caused(label, e)))?;
        if let Err(e) = self.apply_events() {
            let _ = self.allocator.free(alloc.id);
            return Err(e);
        }
        tracing::debug!(
            label,
            size_bytes = request.size_bytes,
            ?class,
            in_use_bytes = self.allocator.in_use_bytes(class),
            "heap alloc"
        );
        let Some(memory) = self.blocks.get(&alloc.block) else {
            let _ = self.allocator.free(alloc.id);
            return Err(VkError::InvalidRequest(format!(
                "{label}: block {} has no memory",
                alloc.block.0
            )));
        };
        if let Err(e) = buffer.bind(memory, alloc.offset_bytes) {
            let _ = self.allocator.free(alloc.id);
            let _ = self.apply_events();
            return Err(e);
        }
        Ok(HeapBuffer {
            buffer,
            id: alloc.id,
            kind,
        })
    }

    /// Whether buffers `wanted` (label, size, usage, kind, class, alignment as
    /// [`alloc_buffer`](Self::alloc_buffer) takes them), all held at once, would be allocated
    /// now; the budget's refusal of the first that would not. Creates buffer objects for
    /// their memory requirements but allocates no memory.
    pub fn try_fit(&self, wanted: &[FitRequest<'_>]) -> Result<()> {
        let mut requests = Vec::with_capacity(wanted.len());
        for w in wanted {
            let buffer = Buffer::new(
                &self.ctx,
                w.label,
                &BufferDesc {
                    size_bytes: w.size_bytes.max(4),
                    usage: w.usage,
                },
            )?;
            requests.push(alloc_request(&buffer, w.kind, w.class, w.alignment));
        }
        self.allocator
            .try_fit(&requests)
            .map_err(|(i, e)| VkError::Budget(BudgetRefusal::caused(wanted[i].label, e)))
    }

    /// Whether host-visible blocks count against the VRAM budget (unified memory: lavapipe,
    /// integrated GPUs); where they do not, host-visible buffers leave the budget alone.
    pub fn host_visible_counts_against_budget(&self) -> bool {
        self.allocator.policy().host_visible_counts_against_budget
    }

    /// Destroys the buffer and returns its range (and maybe its block) to the policy.
    pub fn free(&mut self, buffer: HeapBuffer) {
        let id = buffer.id;
        drop(buffer.buffer);
        if let Err(e) = self.allocator.free(id) {
            tracing::warn!(%e, "heap free");
        }
        if let Err(e) = self.apply_events() {
            tracing::warn!(%e, "heap free events");
        }
    }

    fn apply_events(&mut self) -> Result<()> {
        let events: Vec<BlockEvent> = self.allocator.drain_events().collect();
        for event in events {
            match event {
                BlockEvent::Created {
                    block,
                    size_bytes,
                    class,
                    dedicated,
                } => {
                    let location = match class {
                        MemoryClass::DeviceLocal => MemoryLocation::DeviceLocal,
                        MemoryClass::HostVisible => self.host_location,
                    };
                    let type_index = self.type_index[class as usize];
                    let made_ahead = match class {
                        MemoryClass::HostVisible if !dedicated => self.take_spare(size_bytes),
                        _ => None,
                    };
                    let made = match made_ahead {
                        Some(memory) => Ok(memory),
                        None => DeviceMemory::allocate(&self.ctx, size_bytes, type_index, location),
                    };
                    match made {
                        Ok(memory) => {
                            self.blocks.insert(block, memory);
                            let c = &mut self.created[class as usize];
                            *c = (c.0 + 1, c.1 + size_bytes);
                            let more = self.ahead && self.spare.is_none() && !dedicated;
                            if class == MemoryClass::HostVisible && more {
                                self.spare = spare::Spare::allocate(
                                    &self.ctx, size_bytes, type_index, location,
                                );
                            }
                        }
                        Err(e) => {
                            let _ = self.allocator.forget_block(block);
                            let _ = self.allocator.drain_events().count();
                            return Err(e);
                        }
                    }
                }
                BlockEvent::Destroyed { block, class, .. } => {
                    // Buffers bound to it hold their own Arc; none is live (policy invariant).
                    let memory = self.blocks.remove(&block);
                    // A host block destroyed while none waits is kept as the next one (its
                    // pages pinned, mapped and touched); dedicated ones differ in size and
                    // are dropped when taken.
                    let keep = self.ahead && class == MemoryClass::HostVisible;
                    if let (Some(m), true, None) = (memory, keep, &self.spare) {
                        self.spare = spare::Spare::kept(&self.ctx, m);
                    }
                }
            }
        }
        Ok(())
    }

    /// Device-local standard blocks, emptiest first ([`Allocator::block_fills`]).
    pub fn block_fills(&self) -> Vec<motu_alloc::BlockFill> {
        self.allocator.block_fills(MemoryClass::DeviceLocal)
    }

    /// The live allocations in `block`.
    pub fn allocations_in(&self, block: BlockId) -> Vec<AllocationId> {
        self.allocator
            .allocations_in(block)
            .into_iter()
            .map(|a| a.id)
            .collect()
    }

    /// Blocks being emptied ([`Allocator::set_draining`]) and whether new blocks may be made
    /// ([`Allocator::set_fit_only`]); `(&[], false)` ends a move.
    pub fn set_draining(&mut self, blocks: &[BlockId], fit_only: bool) {
        self.allocator.set_draining(blocks);
        self.allocator.set_fit_only(fit_only);
    }

    /// Bytes of live allocations counted against the VRAM budget, per kind (in
    /// [`AllocKind::ALL`](motu_alloc::AllocKind::ALL)'s order); they sum to the report's
    /// `budget_in_use_bytes`.
    pub fn budget_in_use_by_kind(&self) -> [u64; 9] {
        self.allocator
            .in_use_bytes_by_kind(MemoryClass::DeviceLocal)
    }

    /// The policy's statistics (per kind, peaks, budget).
    pub fn report(&self) -> AllocReport {
        self.allocator.report()
    }

    pub fn limits(&self) -> AllocLimits {
        self.allocator.limits()
    }

    /// Blocks of `class` the policy created so far, their bytes, and of them those that came
    /// from the spare ([`GpuHeap::set_host_blocks_ahead`]); the others were each a
    /// `vkAllocateMemory` in the caller's time.
    pub fn created_blocks(&self, class: MemoryClass) -> BlockCounts {
        let (created, bytes) = self.created[class as usize];
        BlockCounts {
            created,
            bytes,
            from_spare: match class {
                MemoryClass::HostVisible => self.spares_taken,
                MemoryClass::DeviceLocal => 0,
            },
        }
    }

    /// Makes each host-visible standard block ahead (on a thread of its own, pages touched)
    /// after the policy makes one, and keeps a destroyed one for the next instead of freeing
    /// it (`spare.rs`): for a streamer whose meshes live in host memory. Off: drops the spare.
    pub fn set_host_blocks_ahead(&mut self, on: bool) {
        self.ahead = on;
        if !on {
            if let Some(s) = self.spare.take() {
                s.finish();
            }
        }
    }

    fn take_spare(&mut self, size_bytes: u64) -> Option<Arc<DeviceMemory>> {
        if !self.spare.as_ref()?.ready() {
            return None;
        }
        let memory = self.spare.take()?.take(size_bytes)?;
        self.spares_taken += 1;
        Some(memory)
    }

    /// Live `VkDeviceMemory` blocks of this heap.
    pub fn block_count(&self) -> usize {
        self.blocks.len()
    }
}

impl Drop for GpuHeap {
    fn drop(&mut self) {
        // A block still being made ahead is waited for (and freed with its thread's Arc).
        if let Some(s) = self.spare.take() {
            s.finish();
        }
    }
}

#[cfg(test)]
mod tests;
