//! One host-visible block ready before the policy asks for it ([`GpuHeap::set_host_blocks_ahead`]):
//! allocated, mapped and its pages touched on a thread of its own, or a standard block the
//! policy destroyed, kept instead of freed. A streamer with its meshes in host memory makes a
//! new block every few build groups (or frees one and makes another), and each
//! `vkAllocateMemory` of host memory (pinned, zeroed, mapped) and each first touch of a page
//! came in the frame's mesh upload.

use std::sync::Arc;
use std::thread::JoinHandle;

use crate::context::Context;
use crate::memory::{DeviceMemory, MemoryLocation};

/// Allocation slots a spare block leaves free below the device's cap.
const SPARE_SLOT_MARGIN: u32 = 16;

/// Bytes between the touches of a new block's pages (the smallest page size).
const PAGE_BYTES: usize = 4096;

pub(super) enum Spare {
    /// Being allocated and touched (`None` from the thread: the allocation failed).
    Pending {
        size_bytes: u64,
        thread: JoinHandle<Option<Arc<DeviceMemory>>>,
    },
    /// Ready: a block made ahead, or a destroyed block kept.
    Ready(Arc<DeviceMemory>),
}

impl Spare {
    /// Starts allocating a block of `size_bytes` of memory type `type_index` on a thread of
    /// its own (mapped, one byte a page written); `None` where the device's allocation count
    /// is near its cap or no thread can be started.
    pub(super) fn allocate(
        ctx: &Context,
        size_bytes: u64,
        type_index: u32,
        location: MemoryLocation,
    ) -> Option<Spare> {
        if !room(ctx) {
            return None;
        }
        let ctx = ctx.clone();
        let thread = std::thread::Builder::new()
            .name("motu-host-block".into())
            .spawn(move || {
                let memory = DeviceMemory::allocate(&ctx, size_bytes, type_index, location).ok()?;
                touch_pages(&memory);
                Some(memory)
            })
            .ok()?;
        Some(Spare::Pending { size_bytes, thread })
    }

    /// `memory` (a standard block the policy destroyed) kept as the next block; `None` (it is
    /// freed) where the device's allocation count is near its cap.
    pub(super) fn kept(ctx: &Context, memory: Arc<DeviceMemory>) -> Option<Spare> {
        room(ctx).then_some(Spare::Ready(memory))
    }

    /// Whether [`Spare::take`] would not wait (a block made ahead is still being made while
    /// its thread runs: the caller allocates its own then, and this one waits for the next).
    pub(super) fn ready(&self) -> bool {
        match self {
            Spare::Pending { thread, .. } => thread.is_finished(),
            Spare::Ready(_) => true,
        }
    }

    /// The block, once ready, if it has `size_bytes` (a spare of another size is freed).
    pub(super) fn take(self, size_bytes: u64) -> Option<Arc<DeviceMemory>> {
        let memory = match self {
            Spare::Pending {
                size_bytes: s,
                thread,
            } if s == size_bytes => thread.join().ok().flatten()?,
            Spare::Pending { thread, .. } => {
                let _ = thread.join();
                return None;
            }
            Spare::Ready(memory) => memory,
        };
        (memory.size_bytes() == size_bytes).then_some(memory)
    }

    /// Waits for a pending allocation (the heap is going away; the block is freed).
    pub(super) fn finish(self) {
        if let Spare::Pending { thread, .. } = self {
            let _ = thread.join();
        }
    }
}

/// Whether one allocation more leaves [`SPARE_SLOT_MARGIN`] below the device's cap.
fn room(ctx: &Context) -> bool {
    let cap = ctx.limits().max_memory_allocation_count;
    ctx.allocation_count().saturating_add(SPARE_SLOT_MARGIN) < cap
}

/// Writes one byte of each page of `memory`'s mapping (nothing is bound to it yet), so the
/// page faults of first touches happen here and not in a frame's copies.
fn touch_pages(memory: &DeviceMemory) {
    let len = memory.size_bytes() as usize;
    let _ = memory.with_mapped_mut(0, len, |bytes| {
        for b in bytes.iter_mut().step_by(PAGE_BYTES) {
            *b = 0;
        }
    });
}
