//! GPU memory allocation **policy** for motu: plain Rust, no Vulkan, testable without a GPU.
//!
//! `motu-gpu` applies these decisions to real `VkDeviceMemory`; this crate only decides
//! ranges, alignment, budget, block lifetimes, eviction order and build batches.
//!
//! # Pieces
//! - [`effective_budget_bytes`]: the budget is the smaller of the user's `--vram-budget` and
//!   what `VK_EXT_memory_budget` reports available minus a [`SafetyMargin`].
//! - [`Allocator`]: a block sub-allocator that never exceeds [`AllocLimits`]: the sum of block
//!   sizes counted against the budget stays `<= budget_bytes`, and the number of blocks stays
//!   `<= max_allocation_count`, *by construction* (both are checked before a block is created).
//! - [`Residency`]: least-recently-visible eviction order for streaming, with per-pass pins.
//! - [`plan_build_batches`]: acceleration-structure builds grouped under a scratch budget.
//! - [`AllocReport`]: statistics (`serde::Serialize`) for `--stats`.
//!
//! # Allocator design
//! - **Blocks.** Each block is one future `VkDeviceMemory`. Standard blocks have the size
//!   given by [`standard_block_size_bytes`] (`max(clamp(budget/16, 1 MiB, 256 MiB),
//!   budget/max_allocation_count)`, capped by `maxMemoryAllocationSize` and the budget) and are
//!   sub-allocated. A request larger than the standard block gets a *dedicated* block of
//!   exactly its size (offset 0), destroyed as soon as it is freed. When the budget left is
//!   smaller than a standard block but the request fits, a smaller *tail* block of the
//!   remaining whole MiBs is created, so small budgets can be filled completely.
//! - **Events.** Block creation and destruction are queued as [`BlockEvent`]s; the GPU layer
//!   takes them with [`Allocator::drain_events`] after each call and runs `vkAllocateMemory`
//!   / `vkFreeMemory` in order. If `vkAllocateMemory` fails, [`Allocator::forget_block`] rolls
//!   the block back.
//! - **Pools.** [`MemoryClass::DeviceLocal`] and [`MemoryClass::HostVisible`] are separate
//!   pools sharing the count cap. Device-local blocks always count against the VRAM budget;
//!   host-visible blocks do if [`AllocPolicy::host_visible_counts_against_budget`] (integrated
//!   GPUs, lavapipe), else against their own `host_visible_budget_bytes`.
//! - **Ranges.** Each block keeps its free ranges in a `BTreeMap` by offset (coalesced on
//!   free); each pool indexes every free range of every block in a `BTreeSet` by
//!   `(size, block, offset)`. An allocation takes the best fit across all blocks in
//!   O(log n): the smallest ranges of at least the size are probed (up to 8) for one that still
//!   fits after aligning its start, otherwise the smallest range of at least
//!   `size + alignment - 1`, which always fits. Alignment padding stays a free range, so no
//!   byte is lost except to fragmentation. Frees coalesce with both neighbours in O(log n).
//! - **Empty blocks.** A standard block that becomes empty is kept if fewer than
//!   [`AllocPolicy::keep_empty_blocks_per_class`] (default 1) are kept in its pool, else
//!   destroyed. Kept blocks are destroyed first whenever a new block would exceed the budget or
//!   the count cap, so caching never causes a failure; [`Allocator::trim`] drops them all.
//! - **Errors.** A request that cannot be satisfied without breaking a limit fails with
//!   [`AllocError::OverBudget`], [`AllocError::TooManyAllocations`] or
//!   [`AllocError::TooLarge`], each message stating what was asked and what is in use. Nothing
//!   changes on failure except that kept empty blocks may have been released. A streaming
//!   caller evicts (see [`Residency`]) and retries.
//!
//! # Use from the GPU layer
//! ```
//! use motu_alloc::*;
//!
//! let budget = effective_budget_bytes(Some(64 * MIB), Some(8 * GIB), SafetyMargin::default());
//! let limits = AllocLimits {
//!     max_allocation_count: 8,
//!     ..AllocLimits::with_budget(budget.unwrap_or(64 * MIB))
//! };
//! let mut allocator = Allocator::new(limits, AllocPolicy::default())?;
//! let blas = allocator.alloc(AllocRequest::device_local(AllocKind::BlasStorage, 300_000, 256))?;
//! for event in allocator.drain_events() {
//!     match event {
//!         BlockEvent::Created { block, size_bytes, .. } => { /* vkAllocateMemory */ }
//!         BlockEvent::Destroyed { block, .. } => { /* vkFreeMemory */ }
//!     }
//! }
//! // bind the buffer to blas.block's memory at blas.offset_bytes ...
//! assert_eq!(blas.offset_bytes % 256, 0);
//! allocator.free(blas.id)?;
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Alignments come from the caller: 256 for acceleration-structure storage,
//! `minAccelerationStructureScratchOffsetAlignment` for scratch, and the buffer's
//! `VkMemoryRequirements::alignment` otherwise (use the largest that applies).
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! GPU memory **policy** in plain Rust: budget, block sub-allocator with alignment and
//! allocation-count cap (dedicated blocks above a threshold: streaming's half block), `try_fit`
//! (whether requests held together would be allocated: the policy run on a copy, no memory; the
//! streamed TLAS rebuild's room probe asks it), draining (`block_fills`, `allocations_in`,
//! `set_draining`, `set_fit_only`: what a streamer moving allocations to free whole blocks asks and
//! sets), per-kind stats, LRU residency for streaming, build batching.
//!
//! Key types: `Allocator`, `Residency`, `plan_build_batches`.

mod allocator;
mod batch;
mod error;
mod kind;
mod limits;
mod residency;
mod stats;

pub use allocator::{AllocRequest, Allocation, Allocator, BlockEvent, BlockFill};
pub use batch::{plan_build_batches, BatchError, BatchLimits, BatchPlan, BuildBatch, BuildSize};
pub use error::{AllocError, LimitsError};
pub use kind::{
    binary_scale, format_size, AllocKind, AllocationId, BlockId, ByteSize, MemoryClass,
    BINARY_UNITS,
};
pub use limits::{
    effective_budget_bytes, standard_block_size_bytes, AllocLimits, AllocPolicy, SafetyMargin, GIB,
    MAX_STANDARD_BLOCK_BYTES, MIB, MIN_STANDARD_BLOCK_BYTES,
};
pub use residency::{ItemId, NotEnough, Residency, ResidencyError};
pub use stats::{AllocReport, ClassStats, KindStats};
