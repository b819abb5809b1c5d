//! The budgeted block sub-allocator.

use std::collections::{BTreeMap, BTreeSet, HashMap};

use crate::error::{AllocError, LimitsError};
use crate::kind::{AllocKind, AllocationId, BlockId, MemoryClass};
use crate::limits::{standard_block_size_bytes, AllocLimits, AllocPolicy};
use crate::stats::KindStats;

mod blocks;
mod report;

/// Free ranges tried in best-fit order before jumping to one that fits whatever its padding:
/// bounds the work per allocation when many ranges are just too small once aligned.
const PADDED_PROBES: usize = 8;

/// What the caller wants.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AllocRequest {
    /// Bytes (the `VkMemoryRequirements::size` of the buffer).
    pub size_bytes: u64,
    /// Offset alignment: a non-zero power of two (`VkMemoryRequirements::alignment`, raised to
    /// 256 for AS storage and to `minAccelerationStructureScratchOffsetAlignment` for scratch).
    pub alignment_bytes: u64,
    /// What it is for (accounting only).
    pub kind: AllocKind,
    /// Which pool it comes from.
    pub class: MemoryClass,
}

impl AllocRequest {
    /// A device-local request.
    pub fn device_local(kind: AllocKind, size_bytes: u64, alignment_bytes: u64) -> Self {
        AllocRequest {
            size_bytes,
            alignment_bytes,
            kind,
            class: MemoryClass::DeviceLocal,
        }
    }

    /// A host-visible request.
    pub fn host_visible(kind: AllocKind, size_bytes: u64, alignment_bytes: u64) -> Self {
        AllocRequest {
            size_bytes,
            alignment_bytes,
            kind,
            class: MemoryClass::HostVisible,
        }
    }
}

/// A live sub-allocation: bind the buffer to `block`'s memory at `offset_bytes`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Allocation {
    /// Handle for [`Allocator::free`].
    pub id: AllocationId,
    /// The block (one `VkDeviceMemory`).
    pub block: BlockId,
    /// Offset inside the block, a multiple of the requested alignment.
    pub offset_bytes: u64,
    /// Bytes, as requested.
    pub size_bytes: u64,
    /// What it is for.
    pub kind: AllocKind,
    /// Which pool it came from.
    pub class: MemoryClass,
}

/// What the GPU layer must do to the real memory, in order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BlockEvent {
    /// Call `vkAllocateMemory` of `size_bytes` in a memory type of `class` for `block`.
    Created {
        /// The new block.
        block: BlockId,
        /// Its size.
        size_bytes: u64,
        /// Which memory type class.
        class: MemoryClass,
        /// Whether it holds exactly one allocation larger than the standard block.
        dedicated: bool,
    },
    /// Call `vkFreeMemory` on `block`'s memory: nothing lives in it any more.
    Destroyed {
        /// The block.
        block: BlockId,
        /// Its size.
        size_bytes: u64,
        /// Which memory type class.
        class: MemoryClass,
    },
}

#[derive(Debug, Clone)]
struct Block {
    class: MemoryClass,
    size_bytes: u64,
    /// Holds exactly one allocation at offset 0 and is destroyed when it is freed.
    dedicated: bool,
    /// Free ranges: offset -> size; adjacent ranges are always coalesced.
    free_by_offset: BTreeMap<u64, u64>,
    used_bytes: u64,
    live_count: u32,
}

#[derive(Debug, Clone, Default)]
struct Pool {
    /// Every free range of every non-dedicated block of the pool, for best fit across blocks
    /// in O(log n): (size, block, offset).
    free_by_size: BTreeSet<(u64, BlockId, u64)>,
    block_count: u32,
    dedicated_block_count: u32,
    block_bytes: u64,
    in_use_bytes: u64,
    /// Non-dedicated blocks without live allocations (kept to avoid churn).
    empty_blocks: BTreeSet<BlockId>,
    peak_block_bytes: u64,
    peak_in_use_bytes: u64,
}

/// Budgeted block sub-allocator (see the crate docs for the design).
#[derive(Debug, Clone)]
pub struct Allocator {
    limits: AllocLimits,
    policy: AllocPolicy,
    standard_block_bytes: [u64; 2],
    blocks: HashMap<BlockId, Block>,
    pools: [Pool; 2],
    live: HashMap<AllocationId, Allocation>,
    next_block: u32,
    next_allocation: u64,
    events: Vec<BlockEvent>,
    kinds: [KindStats; 9],
    /// Live bytes per class and kind (`[class][kind]`): what each kind holds of a budget.
    class_kind_bytes: [[u64; 9]; 2],
    peak_block_count: u32,
    peak_budgeted_block_bytes: u64,
    peak_budgeted_in_use_bytes: u64,
    /// Blocks being emptied ([`Allocator::set_draining`]): no allocation is placed in them,
    /// and they are destroyed, not kept, once empty.
    draining: BTreeSet<BlockId>,
    /// No new block is created ([`Allocator::set_fit_only`]).
    fit_only: bool,
}

/// How full one standard block is ([`Allocator::block_fills`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BlockFill {
    pub block: BlockId,
    pub size_bytes: u64,
    pub used_bytes: u64,
    pub live_count: u32,
}

impl Allocator {
    /// An empty allocator; no block exists until the first allocation.
    pub fn new(limits: AllocLimits, policy: AllocPolicy) -> Result<Self, LimitsError> {
        for (name, value) in [
            (
                "max_allocation_count",
                u64::from(limits.max_allocation_count),
            ),
            (
                "max_allocation_size_bytes",
                limits.max_allocation_size_bytes,
            ),
            ("budget_bytes", limits.budget_bytes),
        ] {
            if value == 0 {
                return Err(LimitsError::Zero { name });
            }
        }
        if policy.block_size_bytes == Some(0) {
            return Err(LimitsError::Zero {
                name: "block_size_bytes",
            });
        }
        let mut allocator = Allocator {
            limits,
            policy,
            standard_block_bytes: [0; 2],
            blocks: HashMap::new(),
            pools: Default::default(),
            live: HashMap::new(),
            next_block: 0,
            next_allocation: 0,
            events: Vec::new(),
            kinds: Default::default(),
            class_kind_bytes: Default::default(),
            peak_block_count: 0,
            peak_budgeted_block_bytes: 0,
            peak_budgeted_in_use_bytes: 0,
            draining: BTreeSet::new(),
            fit_only: false,
        };
        for class in MemoryClass::ALL {
            let budget = allocator.budget_bytes(class);
            let max_block = limits.max_allocation_size_bytes.min(budget).max(1);
            allocator.standard_block_bytes[class.index()] = match policy.block_size_bytes {
                Some(size) => size.min(max_block),
                None => standard_block_size_bytes(
                    budget,
                    limits.max_allocation_count,
                    limits.max_allocation_size_bytes,
                ),
            };
        }
        tracing::debug!(
            budget_bytes = limits.budget_bytes,
            max_allocation_count = limits.max_allocation_count,
            device_block_bytes = allocator.standard_block_bytes[0],
            host_block_bytes = allocator.standard_block_bytes[1],
            "allocator created"
        );
        Ok(allocator)
    }

    /// The limits in force.
    pub fn limits(&self) -> AllocLimits {
        self.limits
    }

    /// The policy in force.
    pub fn policy(&self) -> AllocPolicy {
        self.policy
    }

    /// The standard block size of a class.
    pub fn standard_block_bytes(&self, class: MemoryClass) -> u64 {
        self.standard_block_bytes[class.index()]
    }

    /// Whether the class's blocks count against `budget_bytes`.
    pub fn counts_against_budget(&self, class: MemoryClass) -> bool {
        class == MemoryClass::DeviceLocal || self.policy.host_visible_counts_against_budget
    }

    /// The budget that the class's blocks count against.
    pub fn budget_bytes(&self, class: MemoryClass) -> u64 {
        if self.counts_against_budget(class) {
            self.limits.budget_bytes
        } else {
            self.limits.host_visible_budget_bytes
        }
    }

    /// Bytes of blocks that count against the same budget as `class`.
    pub fn reserved_bytes(&self, class: MemoryClass) -> u64 {
        self.budget_group(class)
            .map(|c| self.pools[c.index()].block_bytes)
            .sum()
    }

    /// Bytes of live allocations that count against the same budget as `class`.
    pub fn in_use_bytes(&self, class: MemoryClass) -> u64 {
        self.budget_group(class)
            .map(|c| self.pools[c.index()].in_use_bytes)
            .sum()
    }

    /// Bytes of live allocations that count against the same budget as `class`, per kind
    /// (in [`AllocKind::ALL`]'s order): they sum to [`in_use_bytes`](Self::in_use_bytes).
    pub fn in_use_bytes_by_kind(&self, class: MemoryClass) -> [u64; 9] {
        let mut by_kind = [0u64; 9];
        for c in self.budget_group(class) {
            for (sum, bytes) in by_kind.iter_mut().zip(self.class_kind_bytes[c.index()]) {
                *sum += bytes;
            }
        }
        by_kind
    }

    /// The standard (shared) blocks of `class`, emptiest first: what a caller that moves
    /// allocations to free whole blocks drains first.
    pub fn block_fills(&self, class: MemoryClass) -> Vec<BlockFill> {
        let mut v: Vec<BlockFill> = self
            .blocks
            .iter()
            .filter(|(_, b)| b.class == class && !b.dedicated)
            .map(|(&block, b)| BlockFill {
                block,
                size_bytes: b.size_bytes,
                used_bytes: b.used_bytes,
                live_count: b.live_count,
            })
            .collect();
        v.sort_by_key(|f| (f.used_bytes, f.block));
        v
    }

    /// The live allocations in `block` (O(live allocations)).
    pub fn allocations_in(&self, block: BlockId) -> Vec<Allocation> {
        let mut v: Vec<Allocation> = self
            .live
            .values()
            .filter(|a| a.block == block)
            .copied()
            .collect();
        v.sort_by_key(|a| a.offset_bytes);
        v
    }

    /// Marks `blocks` as being emptied (replacing any earlier set): no allocation is placed
    /// in them, and each is destroyed as soon as its last allocation is freed. A caller moves
    /// their allocations elsewhere (with [`Self::set_fit_only`], into free space other blocks
    /// already have), frees the originals, then clears the set; a block not emptied by then
    /// takes allocations again.
    pub fn set_draining(&mut self, blocks: &[BlockId]) {
        self.draining = blocks.iter().copied().collect();
    }

    /// While set, an allocation that fits no free range fails instead of creating a block.
    pub fn set_fit_only(&mut self, fit_only: bool) {
        self.fit_only = fit_only;
    }

    /// Blocks that exist now, all classes.
    pub fn block_count(&self) -> u32 {
        self.pools.iter().map(|pool| pool.block_count).sum()
    }

    /// Live allocations, all classes.
    pub fn live_allocation_count(&self) -> usize {
        self.live.len()
    }

    /// A live allocation.
    pub fn allocation(&self, id: AllocationId) -> Option<&Allocation> {
        self.live.get(&id)
    }

    /// Size of a block that exists.
    pub fn block_size_bytes(&self, block: BlockId) -> Option<u64> {
        self.blocks.get(&block).map(|b| b.size_bytes)
    }

    /// Block events not yet taken, oldest first. Apply them in order after every
    /// [`alloc`](Self::alloc), [`free`](Self::free) or [`trim`](Self::trim): a `Created` block
    /// must exist before the allocation returned with it is bound.
    pub fn drain_events(&mut self) -> std::vec::Drain<'_, BlockEvent> {
        self.events.drain(..)
    }

    /// Whether events are waiting.
    pub fn has_pending_events(&self) -> bool {
        !self.events.is_empty()
    }

    fn budget_group(&self, class: MemoryClass) -> impl Iterator<Item = MemoryClass> + '_ {
        let counted = self.counts_against_budget(class);
        MemoryClass::ALL
            .into_iter()
            .filter(move |&c| self.counts_against_budget(c) == counted)
    }

    /// Whether `requests`, allocated in order and all held at once, would succeed now: the
    /// same policy run on a copy (nothing changes here, no block event is emitted). Returns
    /// the index of the first refused request and the error it would meet. A caller that
    /// only needs to know whether a large transient fits asks this instead of allocating and
    /// freeing real memory (a dedicated `VkDeviceMemory` of a gigabyte costs tens of
    /// milliseconds).
    pub fn try_fit(&self, requests: &[AllocRequest]) -> Result<(), (usize, AllocError)> {
        let mut copy = self.shadow();
        // Silent: the copy's block events never happen, and its log lines read as if they
        // did (a "memory block destroyed" for each rebuild's room probe).
        tracing::dispatcher::with_default(&tracing::Dispatch::none(), || {
            for (i, &r) in requests.iter().enumerate() {
                copy.alloc(r).map_err(|e| (i, e))?;
            }
            Ok(())
        })
    }

    /// A copy to try requests on: everything but the live-allocation table (which only
    /// frees read; cloning it cost more than the rest at thousands of resident structures)
    /// and the pending events.
    fn shadow(&self) -> Allocator {
        Allocator {
            limits: self.limits,
            policy: self.policy,
            standard_block_bytes: self.standard_block_bytes,
            blocks: self.blocks.clone(),
            pools: self.pools.clone(),
            live: HashMap::new(),
            next_block: self.next_block,
            next_allocation: self.next_allocation,
            events: Vec::new(),
            kinds: self.kinds,
            class_kind_bytes: self.class_kind_bytes,
            peak_block_count: self.peak_block_count,
            peak_budgeted_block_bytes: self.peak_budgeted_block_bytes,
            peak_budgeted_in_use_bytes: self.peak_budgeted_in_use_bytes,
            draining: self.draining.clone(),
            fit_only: self.fit_only,
        }
    }

    /// Allocates `request.size_bytes` at an offset aligned to `request.alignment_bytes`.
    ///
    /// Best fit over the free ranges of the class's blocks; if none fits, a new block
    /// (standard size, or a dedicated block of exactly the request's size when it is larger
    /// than the standard block or [`AllocPolicy::dedicated_above_bytes`]) after releasing
    /// kept empty blocks if the budget or the count cap requires it. Never exceeds the budget
    /// or the count cap.
    pub fn alloc(&mut self, request: AllocRequest) -> Result<Allocation, AllocError> {
        let AllocRequest {
            size_bytes,
            alignment_bytes,
            kind,
            class,
        } = request;
        if size_bytes == 0 {
            return Err(AllocError::ZeroSize { kind });
        }
        if !alignment_bytes.is_power_of_two() {
            return Err(AllocError::BadAlignment {
                alignment_bytes,
                kind,
            });
        }
        let max_allocation_size = self
            .limits
            .max_allocation_size_bytes
            .min(self.budget_bytes(class));
        if size_bytes > max_allocation_size {
            return Err(AllocError::TooLarge {
                requested: size_bytes,
                max_allocation_size,
                kind,
            });
        }
        let standard = self.standard_block_bytes[class.index()];
        let shared_up_to = self
            .policy
            .dedicated_above_bytes
            .map_or(standard, |b| b.min(standard));
        let placed = if size_bytes <= shared_up_to {
            match self.find_fit(class, size_bytes, alignment_bytes) {
                Some(fit) => fit,
                None => {
                    let block = self.create_block(request, standard, false)?;
                    let size = self.blocks.get(&block).map_or(0, |b| b.size_bytes);
                    // A fresh block is one free range at offset 0, which fits any alignment.
                    Fit {
                        block,
                        range_offset: 0,
                        range_size: size,
                        offset: 0,
                    }
                }
            }
        } else {
            let block = self.create_block(request, size_bytes, true)?;
            Fit {
                block,
                range_offset: 0,
                range_size: size_bytes,
                offset: 0,
            }
        };
        self.take_range(class, placed, size_bytes);

        let id = AllocationId(self.next_allocation);
        self.next_allocation += 1;
        let allocation = Allocation {
            id,
            block: placed.block,
            offset_bytes: placed.offset,
            size_bytes,
            kind,
            class,
        };
        self.live.insert(id, allocation);
        self.kinds[kind.index()].add(size_bytes);
        self.class_kind_bytes[class.index()][kind.index()] += size_bytes;
        let pool = &mut self.pools[class.index()];
        pool.in_use_bytes += size_bytes;
        pool.peak_in_use_bytes = pool.peak_in_use_bytes.max(pool.in_use_bytes);
        self.update_peaks();
        tracing::trace!(
            id = id.0,
            block = placed.block.0,
            offset_bytes = placed.offset,
            size_bytes,
            kind = kind.name(),
            "alloc"
        );
        Ok(allocation)
    }

    /// Frees a live allocation. Its block is destroyed (a `Destroyed` event) when it becomes
    /// empty, unless it is a standard block and fewer than
    /// [`AllocPolicy::keep_empty_blocks_per_class`] empty blocks are kept.
    pub fn free(&mut self, id: AllocationId) -> Result<(), AllocError> {
        let allocation = self
            .live
            .remove(&id)
            .ok_or(AllocError::UnknownAllocation(id))?;
        self.release_range(&allocation);
        let class = allocation.class;
        let Some(block) = self.blocks.get(&allocation.block) else {
            return Ok(());
        };
        if block.live_count == 0 {
            let keep = !block.dedicated
                && !self.draining.contains(&allocation.block)
                && self.pools[class.index()].empty_blocks.len()
                    < self.policy.keep_empty_blocks_per_class as usize;
            if keep {
                self.pools[class.index()]
                    .empty_blocks
                    .insert(allocation.block);
            } else {
                self.destroy_block(allocation.block, true);
            }
        }
        Ok(())
    }

    /// Destroys every kept empty block (e.g. before a phase that needs dedicated blocks, or at
    /// the end of a frame under memory pressure).
    pub fn trim(&mut self) {
        for class in MemoryClass::ALL {
            let empty: Vec<BlockId> = self.pools[class.index()]
                .empty_blocks
                .iter()
                .copied()
                .collect();
            for block in empty {
                self.destroy_block(block, true);
            }
        }
    }

    /// Rolls back a block the GPU layer failed to create (`vkAllocateMemory` failed after a
    /// `Created` event): the block and every allocation in it are dropped without a
    /// `Destroyed` event. Returns the dropped allocations, whose buffers the caller must not
    /// bind. O(live allocations); meant for the failure path only.
    pub fn forget_block(&mut self, block: BlockId) -> Result<Vec<Allocation>, AllocError> {
        if !self.blocks.contains_key(&block) {
            return Err(AllocError::UnknownBlock(block));
        }
        let dropped: Vec<Allocation> = self
            .live
            .values()
            .filter(|a| a.block == block)
            .copied()
            .collect();
        for allocation in &dropped {
            self.live.remove(&allocation.id);
            self.release_range(allocation);
        }
        self.destroy_block(block, false);
        Ok(dropped)
    }

    fn update_peaks(&mut self) {
        self.peak_block_count = self.peak_block_count.max(self.block_count());
        self.peak_budgeted_block_bytes = self
            .peak_budgeted_block_bytes
            .max(self.reserved_bytes(MemoryClass::DeviceLocal));
        self.peak_budgeted_in_use_bytes = self
            .peak_budgeted_in_use_bytes
            .max(self.in_use_bytes(MemoryClass::DeviceLocal));
    }
}

#[derive(Debug, Clone, Copy)]
struct Fit {
    block: BlockId,
    range_offset: u64,
    range_size: u64,
    offset: u64,
}

/// `value` rounded up to a multiple of the power of two `alignment`; `None` on overflow.
pub(crate) fn align_up(value: u64, alignment: u64) -> Option<u64> {
    let mask = alignment - 1;
    value.checked_add(mask).map(|v| v & !mask)
}

#[cfg(test)]
mod tests;
