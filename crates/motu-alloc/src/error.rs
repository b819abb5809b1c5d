//! Errors of the block sub-allocator.

use crate::kind::{AllocKind, AllocationId, BlockId, ByteSize, MemoryClass};

/// Why an allocation or free failed. Messages carry every number a user needs to pick a
/// larger budget or find the leak.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AllocError {
    /// A new block would push the blocks counted against the budget over it.
    #[error(
        "{kind} allocation of {} ({class}) exceeds the budget: {} in use, {} in memory blocks, \
         budget {}",
        ByteSize(*requested_bytes),
        ByteSize(*in_use_bytes),
        ByteSize(*reserved_bytes),
        ByteSize(*budget_bytes)
    )]
    OverBudget {
        /// Bytes asked for.
        requested_bytes: u64,
        /// Bytes of live allocations counted against this budget.
        in_use_bytes: u64,
        /// Bytes of blocks counted against this budget (in use plus free space inside blocks).
        reserved_bytes: u64,
        /// The budget.
        budget_bytes: u64,
        /// What the allocation was for.
        kind: AllocKind,
        /// Which memory it was asked in.
        class: MemoryClass,
    },
    /// A new block would exceed the allocation-count cap.
    #[error(
        "{kind} allocation of {} ({class}) needs a new memory block, but {block_count} of the \
         {limit} allowed memory allocations exist ({} in use)",
        ByteSize(*requested_bytes),
        ByteSize(*in_use_bytes)
    )]
    TooManyAllocations {
        /// The cap (`max_allocation_count`).
        limit: u32,
        /// Blocks that exist now.
        block_count: u32,
        /// Bytes asked for.
        requested_bytes: u64,
        /// Bytes of live allocations, all classes.
        in_use_bytes: u64,
        /// What the allocation was for.
        kind: AllocKind,
        /// Which memory it was asked in.
        class: MemoryClass,
    },
    /// One allocation larger than the device's largest allocation (or the budget).
    #[error(
        "{kind} allocation of {} exceeds the largest possible allocation of {}",
        ByteSize(*requested),
        ByteSize(*max_allocation_size)
    )]
    TooLarge {
        /// Bytes asked for.
        requested: u64,
        /// The largest single block: `maxMemoryAllocationSize`, or the budget if smaller.
        max_allocation_size: u64,
        /// What the allocation was for.
        kind: AllocKind,
    },
    /// Zero-sized allocations are invalid in Vulkan.
    #[error("{kind} allocation of 0 bytes")]
    ZeroSize {
        /// What the allocation was for.
        kind: AllocKind,
    },
    /// Alignments must be non-zero powers of two.
    #[error("{kind} allocation asks for alignment {alignment_bytes}, which is not a power of two")]
    BadAlignment {
        /// The alignment asked for.
        alignment_bytes: u64,
        /// What the allocation was for.
        kind: AllocKind,
    },
    /// Freed twice or never allocated here.
    #[error("{0} is not live in this allocator")]
    UnknownAllocation(AllocationId),
    /// Not a block of this allocator.
    #[error("{0} does not exist in this allocator")]
    UnknownBlock(BlockId),
    /// The 32-bit block id space is used up (four billion block creations).
    #[error("block ids exhausted")]
    BlockIdsExhausted,
}

/// Limits that make an allocator unusable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum LimitsError {
    /// A limit is zero.
    #[error("allocator limit {name} is zero")]
    Zero {
        /// The limit's field name.
        name: &'static str,
    },
}
