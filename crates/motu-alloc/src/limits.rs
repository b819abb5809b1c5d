//! Device limits, the effective VRAM budget and the block-size rule.

/// One mebibyte in bytes.
pub const MIB: u64 = 1 << 20;
/// One gibibyte in bytes.
pub const GIB: u64 = 1 << 30;

/// Smallest standard block the rule in [`standard_block_size_bytes`] picks.
pub const MIN_STANDARD_BLOCK_BYTES: u64 = MIB;
/// Largest standard block the rule picks unless the allocation-count cap forces bigger blocks
/// (VMA uses the same 256 MiB default for large heaps).
pub const MAX_STANDARD_BLOCK_BYTES: u64 = 256 * MIB;

/// Hard limits the allocator never exceeds.
///
/// Fill them from the device (`maxMemoryAllocationCount`, `maxMemoryAllocationSize`) and from
/// [`effective_budget_bytes`]; lower them freely for testing (`--max-allocations N`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AllocLimits {
    /// Most memory blocks (`VkDeviceMemory` objects) this allocator holds at once, all memory
    /// classes together. Subtract allocations made outside the allocator from the device limit.
    pub max_allocation_count: u32,
    /// Largest single block (`maxMemoryAllocationSize`).
    pub max_allocation_size_bytes: u64,
    /// VRAM budget: the sum of the sizes of all blocks that count against it never exceeds this.
    pub budget_bytes: u64,
    /// Budget of host-visible blocks when they do not count against `budget_bytes`
    /// (see [`AllocPolicy::host_visible_counts_against_budget`]).
    pub host_visible_budget_bytes: u64,
}

impl AllocLimits {
    /// Limits with the given VRAM budget and conservative defaults elsewhere: 4096 allocations
    /// (the common Windows driver limit), 2 GiB largest allocation (lavapipe's limit) and a
    /// 256 MiB host-visible (staging) budget.
    pub fn with_budget(budget_bytes: u64) -> Self {
        AllocLimits {
            max_allocation_count: 4096,
            max_allocation_size_bytes: 2 * GIB,
            budget_bytes,
            host_visible_budget_bytes: 256 * MIB,
        }
    }

    /// Each limit lowered to `other`'s where `other` is smaller (test overrides never raise a
    /// device limit).
    pub fn lowered_to(self, other: AllocLimits) -> Self {
        AllocLimits {
            max_allocation_count: self.max_allocation_count.min(other.max_allocation_count),
            max_allocation_size_bytes: self
                .max_allocation_size_bytes
                .min(other.max_allocation_size_bytes),
            budget_bytes: self.budget_bytes.min(other.budget_bytes),
            host_visible_budget_bytes: self
                .host_visible_budget_bytes
                .min(other.host_visible_budget_bytes),
        }
    }
}

/// Policy knobs that are choices, not device facts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AllocPolicy {
    /// Standard block size per memory class; `None` applies [`standard_block_size_bytes`].
    pub block_size_bytes: Option<u64>,
    /// Whether host-visible (staging) blocks count against the VRAM budget. True on
    /// integrated GPUs and lavapipe where both live in one heap; false (default) on discrete
    /// GPUs, where host-visible memory is system RAM and has its own budget.
    pub host_visible_counts_against_budget: bool,
    /// Empty standard blocks kept per memory class instead of being destroyed, to avoid
    /// `vkAllocateMemory`/`vkFreeMemory` churn when one allocation comes and goes. Kept blocks
    /// are released on demand when a new block would exceed the budget or the count cap.
    pub keep_empty_blocks_per_class: u32,
    /// Requests larger than this get a dedicated block of exactly their size; `None`: only
    /// those larger than the standard block. A pool whose requests come within a factor of
    /// the block size and come and go (streamed structures) strands free space inside blocks
    /// that no later request fits; dedicated blocks return exactly what they held.
    pub dedicated_above_bytes: Option<u64>,
}

impl Default for AllocPolicy {
    fn default() -> Self {
        AllocPolicy {
            block_size_bytes: None,
            host_visible_counts_against_budget: false,
            keep_empty_blocks_per_class: 1,
            dedicated_above_bytes: None,
        }
    }
}

/// The standard block size for a pool with budget `budget_bytes`.
///
/// Rule: `max(clamp(budget / 16, 1 MiB, 256 MiB), ceil(budget / max_allocation_count))`,
/// rounded up to a whole MiB, then capped by `max_allocation_size_bytes` and by the budget.
///
/// Why: sixteen blocks per budget keep the waste of a half-empty last block small; the 256 MiB
/// ceiling keeps single `vkAllocateMemory` calls reasonable; and a block of at least
/// `budget / count` guarantees that the budget can actually be filled without hitting the
/// allocation-count cap (64 MiB with `--max-allocations 8` gives 8 MiB blocks). Requests larger
/// than the standard block get a dedicated block of their own size.
pub fn standard_block_size_bytes(
    budget_bytes: u64,
    max_allocation_count: u32,
    max_allocation_size_bytes: u64,
) -> u64 {
    let per_sixteenth =
        (budget_bytes / 16).clamp(MIN_STANDARD_BLOCK_BYTES, MAX_STANDARD_BLOCK_BYTES);
    let per_count = budget_bytes.div_ceil(u64::from(max_allocation_count.max(1)));
    let target = per_sixteenth.max(per_count);
    let rounded = target.div_ceil(MIB).saturating_mul(MIB);
    rounded
        .min(max_allocation_size_bytes)
        .min(budget_bytes)
        .max(1)
}

/// Headroom left for other processes, the driver and allocations outside the allocator.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SafetyMargin {
    /// Share of the device-reported available bytes kept free, in percent.
    pub percent: u8,
    /// Least bytes kept free.
    pub min_bytes: u64,
}

impl Default for SafetyMargin {
    /// 5 % of what the device reports, at least 64 MiB.
    fn default() -> Self {
        SafetyMargin {
            percent: 5,
            min_bytes: 64 * MIB,
        }
    }
}

impl SafetyMargin {
    /// Bytes kept free out of `available_bytes` (never more than `available_bytes`).
    pub fn margin_bytes(self, available_bytes: u64) -> u64 {
        let share = (u128::from(available_bytes) * u128::from(self.percent.min(100)) / 100) as u64;
        share.max(self.min_bytes).min(available_bytes)
    }
}

/// The budget the allocator should enforce: the smaller of the user's budget
/// (`--vram-budget`) and what the device says is available minus a safety margin.
///
/// `device_available_bytes` is, for the device-local heap(s), `heapBudget - heapUsage` from
/// `VK_EXT_memory_budget` taken before the allocator creates anything (or the heap size when the
/// extension is missing). Returns `None` when neither bound is known.
pub fn effective_budget_bytes(
    user_budget_bytes: Option<u64>,
    device_available_bytes: Option<u64>,
    margin: SafetyMargin,
) -> Option<u64> {
    let device = device_available_bytes.map(|available| available - margin.margin_bytes(available));
    match (user_budget_bytes, device) {
        (Some(user), Some(device)) => Some(user.min(device)),
        (Some(user), None) => Some(user),
        (None, device) => device,
    }
}

#[cfg(test)]
mod tests;
