//! Allocation statistics for `--stats` JSON and the resource report.

use std::collections::BTreeMap;

use crate::kind::{AllocKind, MemoryClass};

/// Accounting of one [`AllocKind`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct KindStats {
    /// Bytes of live allocations.
    pub bytes: u64,
    /// Live allocations.
    pub count: u64,
    /// Highest `bytes` seen.
    pub peak_bytes: u64,
    /// Highest `count` seen.
    pub peak_count: u64,
    /// Allocations made so far (including freed ones).
    pub total_allocations: u64,
    /// Bytes allocated so far (including freed ones).
    pub total_bytes: u64,
}

impl KindStats {
    pub(crate) fn add(&mut self, size_bytes: u64) {
        self.bytes += size_bytes;
        self.count += 1;
        self.peak_bytes = self.peak_bytes.max(self.bytes);
        self.peak_count = self.peak_count.max(self.count);
        self.total_allocations += 1;
        self.total_bytes += size_bytes;
    }

    pub(crate) fn remove(&mut self, size_bytes: u64) {
        self.bytes -= size_bytes;
        self.count -= 1;
    }
}

/// Blocks and free space of one [`MemoryClass`] pool.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClassStats {
    /// Whether these blocks count against the VRAM budget.
    pub counts_against_budget: bool,
    /// The budget these blocks count against.
    pub budget_bytes: u64,
    /// Standard block size.
    pub standard_block_bytes: u64,
    /// Blocks (`VkDeviceMemory` objects).
    pub block_count: u32,
    /// Of which hold a single allocation larger than the standard block.
    pub dedicated_block_count: u32,
    /// Of which are empty and kept for reuse.
    pub empty_block_count: u32,
    /// Bytes of all blocks.
    pub block_bytes: u64,
    /// Bytes of live allocations.
    pub in_use_bytes: u64,
    /// `block_bytes - in_use_bytes`: free space inside blocks, alignment padding included.
    pub free_bytes: u64,
    /// Free ranges.
    pub free_range_count: u64,
    /// Largest free range: the largest request that fits without a new block.
    pub largest_free_range_bytes: u64,
    /// `1 - largest_free_range / free_bytes`: 0 when all free space is one range.
    pub fragmentation: f64,
    /// Highest `block_bytes` seen.
    pub peak_block_bytes: u64,
    /// Highest `in_use_bytes` seen.
    pub peak_in_use_bytes: u64,
}

/// Everything the allocator knows about its use, serialisable for `--stats`.
///
/// "Allocation" in the top-level counts means a `VkDeviceMemory` (a block), as in
/// `maxMemoryAllocationCount`; sub-allocations are counted per kind.
#[derive(Debug, Clone, PartialEq)]
pub struct AllocReport {
    /// VRAM budget.
    pub budget_bytes: u64,
    /// The block-count cap.
    pub max_allocation_count: u32,
    /// The largest single block allowed.
    pub max_allocation_size_bytes: u64,
    /// Blocks now, all classes.
    pub allocation_count: u32,
    /// Highest block count seen; never above `max_allocation_count`.
    pub peak_allocation_count: u32,
    /// Live sub-allocations, all classes.
    pub live_suballocation_count: u64,
    /// Bytes of blocks counted against the VRAM budget now.
    pub budget_block_bytes: u64,
    /// Bytes of live allocations counted against the VRAM budget now.
    pub budget_in_use_bytes: u64,
    /// Highest `budget_block_bytes` seen (the VRAM peak); never above `budget_bytes`.
    pub peak_block_bytes: u64,
    /// Highest `budget_in_use_bytes` seen.
    pub peak_in_use_bytes: u64,
    /// Per memory class.
    pub classes: BTreeMap<MemoryClass, ClassStats>,
    /// Per allocation kind.
    pub kinds: BTreeMap<AllocKind, KindStats>,
}
