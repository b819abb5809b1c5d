//! The allocator's report (per class and kind, peaks) and its consistency check.

use crate::kind::{AllocKind, MemoryClass};
use crate::stats::{AllocReport, ClassStats};

use super::Allocator;

impl Allocator {
    /// Statistics for `--stats` (O(blocks + free ranges of one lookup per class)).
    pub fn report(&self) -> AllocReport {
        let classes = MemoryClass::ALL
            .into_iter()
            .map(|class| {
                let pool = &self.pools[class.index()];
                let largest_free_range_bytes =
                    pool.free_by_size.last().map_or(0, |&(size, _, _)| size);
                // Dedicated blocks are always exactly full, so free bytes are block minus use.
                let free_bytes = pool.block_bytes - pool.in_use_bytes;
                let fragmentation = if free_bytes == 0 {
                    0.0
                } else {
                    1.0 - largest_free_range_bytes as f64 / free_bytes as f64
                };
                let stats = ClassStats {
                    counts_against_budget: self.counts_against_budget(class),
                    budget_bytes: self.budget_bytes(class),
                    standard_block_bytes: self.standard_block_bytes[class.index()],
                    block_count: pool.block_count,
                    dedicated_block_count: pool.dedicated_block_count,
                    empty_block_count: pool.empty_blocks.len() as u32,
                    block_bytes: pool.block_bytes,
                    in_use_bytes: pool.in_use_bytes,
                    free_bytes,
                    free_range_count: pool.free_by_size.len() as u64,
                    largest_free_range_bytes,
                    fragmentation,
                    peak_block_bytes: pool.peak_block_bytes,
                    peak_in_use_bytes: pool.peak_in_use_bytes,
                };
                (class, stats)
            })
            .collect();
        let kinds = AllocKind::ALL
            .into_iter()
            .map(|kind| (kind, self.kinds[kind.index()]))
            .collect();
        AllocReport {
            budget_bytes: self.limits.budget_bytes,
            max_allocation_count: self.limits.max_allocation_count,
            max_allocation_size_bytes: self.limits.max_allocation_size_bytes,
            allocation_count: self.block_count(),
            peak_allocation_count: self.peak_block_count,
            live_suballocation_count: self.live.len() as u64,
            budget_block_bytes: self.reserved_bytes(MemoryClass::DeviceLocal),
            budget_in_use_bytes: self.in_use_bytes(MemoryClass::DeviceLocal),
            peak_block_bytes: self.peak_budgeted_block_bytes,
            peak_in_use_bytes: self.peak_budgeted_in_use_bytes,
            classes,
            kinds,
        }
    }

    /// Checks every internal invariant; for tests and debug assertions in callers.
    /// O(everything).
    pub fn check_consistency(&self) -> Result<(), String> {
        let mut pool_blocks = [0u32; 2];
        let mut pool_bytes = [0u64; 2];
        let mut pool_used = [0u64; 2];
        let mut pool_free_ranges = [0usize; 2];
        for (&id, block) in &self.blocks {
            let c = block.class.index();
            pool_blocks[c] += 1;
            pool_bytes[c] += block.size_bytes;
            pool_used[c] += block.used_bytes;
            pool_free_ranges[c] += block.free_by_offset.len();
            let mut previous_end = None;
            let mut free_total = 0;
            for (&offset, &size) in &block.free_by_offset {
                if size == 0 || offset + size > block.size_bytes {
                    return Err(format!("{id}: bad free range {offset}+{size}"));
                }
                if previous_end.is_some_and(|end| end >= offset) {
                    return Err(format!(
                        "{id}: free ranges overlap or are not coalesced at {offset}"
                    ));
                }
                if !self.pools[c].free_by_size.contains(&(size, id, offset)) {
                    return Err(format!(
                        "{id}: free range {offset}+{size} missing from the size index"
                    ));
                }
                previous_end = Some(offset + size);
                free_total += size;
            }
            let expected_free = if block.dedicated {
                0
            } else {
                block.size_bytes - block.used_bytes
            };
            if free_total != expected_free {
                return Err(format!(
                    "{id}: free {free_total} != size - used {expected_free}"
                ));
            }
            let empty = self.pools[c].empty_blocks.contains(&id);
            if empty != (block.live_count == 0) {
                return Err(format!(
                    "{id}: empty-set membership {empty} with {} live",
                    block.live_count
                ));
            }
        }
        for class in MemoryClass::ALL {
            let pool = &self.pools[class.index()];
            let c = class.index();
            if pool.block_count != pool_blocks[c]
                || pool.block_bytes != pool_bytes[c]
                || pool.in_use_bytes != pool_used[c]
                || pool.free_by_size.len() != pool_free_ranges[c]
            {
                return Err(format!("{class}: pool totals disagree with blocks"));
            }
            if self.reserved_bytes(class) > self.budget_bytes(class) {
                return Err(format!("{class}: over budget"));
            }
        }
        if self.block_count() > self.limits.max_allocation_count {
            return Err("over the allocation-count cap".to_owned());
        }
        let live_bytes: u64 = self.live.values().map(|a| a.size_bytes).sum();
        let kind_bytes: u64 = self.kinds.iter().map(|k| k.bytes).sum();
        let kind_count: u64 = self.kinds.iter().map(|k| k.count).sum();
        if live_bytes != kind_bytes || self.live.len() as u64 != kind_count {
            return Err("per-kind totals disagree with live allocations".to_owned());
        }
        for (c, by_kind) in self.class_kind_bytes.iter().enumerate() {
            if by_kind.iter().sum::<u64>() != pool_used[c] {
                return Err(format!("class {c}: per-kind bytes disagree with block use"));
            }
        }
        for (k, stats) in self.kinds.iter().enumerate() {
            if self.class_kind_bytes.iter().map(|b| b[k]).sum::<u64>() != stats.bytes {
                return Err(format!("kind {k}: per-class bytes disagree with its total"));
            }
        }
        if live_bytes != pool_used.iter().sum::<u64>() {
            return Err("live allocations disagree with block use".to_owned());
        }
        Ok(())
    }
}
