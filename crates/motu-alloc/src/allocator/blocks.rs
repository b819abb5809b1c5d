//! Blocks and ranges: finding a fit in a pool's free ranges, taking and releasing a range, and
//! creating, inserting and destroying blocks.

use std::collections::BTreeMap;

use crate::error::AllocError;
use crate::kind::{BlockId, MemoryClass};
use crate::limits::MIB;

use super::{align_up, AllocRequest, Allocation, Allocator, Block, BlockEvent, Fit, PADDED_PROBES};

impl Allocator {
    /// Returns an allocation's range to its block (coalescing) and updates the accounting.
    pub(super) fn release_range(&mut self, allocation: &Allocation) {
        let class = allocation.class;
        self.kinds[allocation.kind.index()].remove(allocation.size_bytes);
        self.class_kind_bytes[class.index()][allocation.kind.index()] -= allocation.size_bytes;
        let pool = &mut self.pools[class.index()];
        pool.in_use_bytes -= allocation.size_bytes;
        let Some(block) = self.blocks.get_mut(&allocation.block) else {
            return;
        };
        block.used_bytes -= allocation.size_bytes;
        block.live_count -= 1;
        if block.dedicated {
            return;
        }
        let mut start = allocation.offset_bytes;
        let mut end = allocation.offset_bytes + allocation.size_bytes;
        if let Some((&prev_offset, &prev_size)) = block.free_by_offset.range(..start).next_back() {
            if prev_offset + prev_size == start {
                block.free_by_offset.remove(&prev_offset);
                pool.free_by_size
                    .remove(&(prev_size, allocation.block, prev_offset));
                start = prev_offset;
            }
        }
        if let Some(next_size) = block.free_by_offset.remove(&end) {
            pool.free_by_size
                .remove(&(next_size, allocation.block, end));
            end += next_size;
        }
        block.free_by_offset.insert(start, end - start);
        pool.free_by_size
            .insert((end - start, allocation.block, start));
    }

    /// Best fit in the class's free ranges, honouring alignment.
    pub(super) fn find_fit(
        &self,
        class: MemoryClass,
        size_bytes: u64,
        alignment_bytes: u64,
    ) -> Option<Fit> {
        let free = &self.pools[class.index()].free_by_size;
        let fit_in = |&(range_size, block, range_offset): &(u64, BlockId, u64)| {
            let offset = align_up(range_offset, alignment_bytes)?;
            let end = offset.checked_add(size_bytes)?;
            (end <= range_offset + range_size).then_some(Fit {
                block,
                range_offset,
                range_size,
                offset,
            })
        };
        let open = |e: &&(u64, BlockId, u64)| !self.draining.contains(&e.1);
        let start = (size_bytes, BlockId(0), 0);
        if let Some(fit) = free
            .range(start..)
            .filter(open)
            .take(PADDED_PROBES)
            .find_map(fit_in)
        {
            return Some(fit);
        }
        // Any range at least size + alignment - 1 long fits whatever its offset.
        let padded = size_bytes.checked_add(alignment_bytes - 1)?;
        free.range((padded, BlockId(0), 0)..)
            .find(open)
            .and_then(fit_in)
    }

    pub(super) fn take_range(&mut self, class: MemoryClass, fit: Fit, size_bytes: u64) {
        let pool = &mut self.pools[class.index()];
        let Some(block) = self.blocks.get_mut(&fit.block) else {
            return;
        };
        if !block.dedicated {
            pool.free_by_size
                .remove(&(fit.range_size, fit.block, fit.range_offset));
            block.free_by_offset.remove(&fit.range_offset);
            if fit.offset > fit.range_offset {
                let pad = fit.offset - fit.range_offset;
                block.free_by_offset.insert(fit.range_offset, pad);
                pool.free_by_size.insert((pad, fit.block, fit.range_offset));
            }
            let end = fit.offset + size_bytes;
            let range_end = fit.range_offset + fit.range_size;
            if range_end > end {
                block.free_by_offset.insert(end, range_end - end);
                pool.free_by_size.insert((range_end - end, fit.block, end));
            }
        }
        if block.live_count == 0 {
            pool.empty_blocks.remove(&fit.block);
        }
        block.used_bytes += size_bytes;
        block.live_count += 1;
    }

    /// Creates a block for `request`: `preferred_bytes` if the budget allows, else (for a
    /// standard block) a smaller tail block of what is left of the budget if the request fits.
    pub(super) fn create_block(
        &mut self,
        request: AllocRequest,
        preferred_bytes: u64,
        dedicated: bool,
    ) -> Result<BlockId, AllocError> {
        let class = request.class;
        if self.fit_only {
            return Err(AllocError::OverBudget {
                requested_bytes: request.size_bytes,
                in_use_bytes: self.in_use_bytes(class),
                reserved_bytes: self.reserved_bytes(class),
                budget_bytes: self.budget_bytes(class),
                kind: request.kind,
                class,
            });
        }
        loop {
            let count_ok = self.block_count() < self.limits.max_allocation_count;
            let budget = self.budget_bytes(class);
            let remaining = budget.saturating_sub(self.reserved_bytes(class));
            let size = if preferred_bytes <= remaining {
                Some(preferred_bytes)
            } else if !dedicated && request.size_bytes <= remaining {
                // Tail block: whole MiBs of what is left, at least the request.
                Some((remaining / MIB * MIB).max(request.size_bytes))
            } else {
                None
            };
            if let (true, Some(size_bytes)) = (count_ok, size) {
                return self.insert_block(class, size_bytes, dedicated);
            }
            // Kept empty blocks give way before we fail.
            if let Some(victim) = self.empty_block_to_release(class, !count_ok) {
                self.destroy_block(victim, true);
                continue;
            }
            return Err(if count_ok {
                AllocError::OverBudget {
                    requested_bytes: request.size_bytes,
                    in_use_bytes: self.in_use_bytes(class),
                    reserved_bytes: self.reserved_bytes(class),
                    budget_bytes: budget,
                    kind: request.kind,
                    class,
                }
            } else {
                AllocError::TooManyAllocations {
                    limit: self.limits.max_allocation_count,
                    block_count: self.block_count(),
                    requested_bytes: request.size_bytes,
                    in_use_bytes: self.pools.iter().map(|p| p.in_use_bytes).sum(),
                    kind: request.kind,
                    class,
                }
            });
        }
    }

    /// An empty kept block whose release helps: any class when the count cap is the problem,
    /// else one counted against the same budget.
    pub(super) fn empty_block_to_release(
        &self,
        class: MemoryClass,
        count_bound: bool,
    ) -> Option<BlockId> {
        let counted = self.counts_against_budget(class);
        MemoryClass::ALL
            .into_iter()
            .filter(|&c| count_bound || self.counts_against_budget(c) == counted)
            .find_map(|c| self.pools[c.index()].empty_blocks.iter().next().copied())
    }

    pub(super) fn insert_block(
        &mut self,
        class: MemoryClass,
        size_bytes: u64,
        dedicated: bool,
    ) -> Result<BlockId, AllocError> {
        let block = BlockId(self.next_block);
        self.next_block = self
            .next_block
            .checked_add(1)
            .ok_or(AllocError::BlockIdsExhausted)?;
        let mut free_by_offset = BTreeMap::new();
        let pool = &mut self.pools[class.index()];
        if !dedicated {
            free_by_offset.insert(0, size_bytes);
            pool.free_by_size.insert((size_bytes, block, 0));
        }
        pool.block_count += 1;
        pool.block_bytes += size_bytes;
        if dedicated {
            pool.dedicated_block_count += 1;
        }
        pool.peak_block_bytes = pool.peak_block_bytes.max(pool.block_bytes);
        self.blocks.insert(
            block,
            Block {
                class,
                size_bytes,
                dedicated,
                free_by_offset,
                used_bytes: 0,
                live_count: 0,
            },
        );
        self.events.push(BlockEvent::Created {
            block,
            size_bytes,
            class,
            dedicated,
        });
        tracing::debug!(
            block = block.0,
            size_bytes,
            class = class.name(),
            dedicated,
            block_count = self.block_count(),
            "memory block created"
        );
        self.update_peaks();
        Ok(block)
    }

    pub(super) fn destroy_block(&mut self, block_id: BlockId, emit: bool) {
        let Some(block) = self.blocks.remove(&block_id) else {
            return;
        };
        self.draining.remove(&block_id);
        let pool = &mut self.pools[block.class.index()];
        for (&offset, &size) in &block.free_by_offset {
            pool.free_by_size.remove(&(size, block_id, offset));
        }
        pool.empty_blocks.remove(&block_id);
        pool.block_count -= 1;
        pool.block_bytes -= block.size_bytes;
        if block.dedicated {
            pool.dedicated_block_count -= 1;
        }
        if emit {
            self.events.push(BlockEvent::Destroyed {
                block: block_id,
                size_bytes: block.size_bytes,
                class: block.class,
            });
        }
        tracing::debug!(
            block = block_id.0,
            size_bytes = block.size_bytes,
            class = block.class.name(),
            "memory block destroyed"
        );
    }
}
