//! Acceleration-structure build batching under a scratch budget.

use std::ops::Range;

use crate::allocator::align_up;
use crate::kind::ByteSize;

/// Sizes of one build, from `vkGetAccelerationStructureBuildSizesKHR`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BuildSize {
    /// `accelerationStructureSize`.
    pub result_bytes: u64,
    /// `buildScratchSize`.
    pub scratch_bytes: u64,
}

/// Limits of one batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct BatchLimits {
    /// Summed aligned scratch of a batch stays at or below this (the shared scratch pool size).
    pub scratch_budget_bytes: u64,
    /// `minAccelerationStructureScratchOffsetAlignment` (a power of two).
    pub scratch_alignment_bytes: u64,
    /// Largest scratch a single build may use: a build above the budget but at or below this
    /// gets a batch of its own (with a larger scratch pool); above this it is an error.
    /// Typically the largest allocation the memory budget allows.
    pub scratch_pool_max_bytes: u64,
    /// Optional cap on summed result bytes per batch (bounds the memory in flight before
    /// compaction; nvpro samples use 256-512 MiB). `None`: no cap.
    pub max_batch_result_bytes: Option<u64>,
}

/// Consecutive builds that run together, each with its own slice of the scratch pool.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BuildBatch {
    /// Indices into the input list.
    pub builds: Range<usize>,
    /// Summed aligned scratch: the scratch pool bytes this batch needs.
    pub scratch_bytes: u64,
    /// Summed result bytes.
    pub result_bytes: u64,
    /// A single build whose scratch alone exceeds the scratch budget.
    pub oversized: bool,
}

/// The batches, in input order.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct BatchPlan {
    /// Batches covering every build once, in order.
    pub batches: Vec<BuildBatch>,
    /// Per build (input index): its scratch offset from the pool start, aligned.
    pub scratch_offsets_bytes: Vec<u64>,
    /// Scratch pool size that runs every batch: the largest batch scratch.
    pub scratch_pool_bytes: u64,
    /// Builds whose scratch alone exceeds the scratch budget (each in its own batch).
    pub oversized_builds: Vec<usize>,
}

/// Why no plan exists.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum BatchError {
    /// One build needs more scratch than the scratch pool may ever have.
    #[error(
        "build {build_index} needs {} of scratch, more than the scratch pool maximum of {}",
        ByteSize(*scratch_bytes),
        ByteSize(*scratch_pool_max_bytes)
    )]
    ScratchTooLarge {
        /// Index of the build in the input.
        build_index: usize,
        /// Its scratch, aligned.
        scratch_bytes: u64,
        /// The maximum.
        scratch_pool_max_bytes: u64,
    },
    /// The scratch alignment is not a power of two.
    #[error("scratch alignment {0} is not a power of two")]
    BadAlignment(u64),
    /// Sizes so large that their sum does not fit 64 bits.
    #[error("build {0}'s sizes overflow 64 bits")]
    Overflow(usize),
}

/// Groups builds, in order, into batches whose summed aligned scratch is at most the budget.
///
/// Greedy next-fit: order is kept because callers list children before parents (BLAS before
/// the TLAS that instances them), and a batch is a contiguous run so one barrier between
/// batches is enough. Each build's scratch is rounded up to the alignment so consecutive
/// slices stay aligned when the pool base is. A build whose aligned scratch exceeds the budget
/// runs alone (`oversized`, listed in `oversized_builds`) if it is within
/// `scratch_pool_max_bytes`, else the plan fails with [`BatchError::ScratchTooLarge`].
/// `max_batch_result_bytes` closes a batch early but never rejects a build.
pub fn plan_build_batches(
    builds: &[BuildSize],
    limits: BatchLimits,
) -> Result<BatchPlan, BatchError> {
    let alignment = limits.scratch_alignment_bytes;
    if !alignment.is_power_of_two() {
        return Err(BatchError::BadAlignment(alignment));
    }
    let mut plan = BatchPlan {
        batches: Vec::new(),
        scratch_offsets_bytes: Vec::with_capacity(builds.len()),
        scratch_pool_bytes: 0,
        oversized_builds: Vec::new(),
    };
    let mut current: Option<BuildBatch> = None;
    for (index, build) in builds.iter().enumerate() {
        let scratch =
            align_up(build.scratch_bytes, alignment).ok_or(BatchError::Overflow(index))?;
        if scratch > limits.scratch_budget_bytes {
            if scratch > limits.scratch_pool_max_bytes {
                return Err(BatchError::ScratchTooLarge {
                    build_index: index,
                    scratch_bytes: scratch,
                    scratch_pool_max_bytes: limits.scratch_pool_max_bytes,
                });
            }
            plan.batches.extend(current.take());
            plan.batches.push(BuildBatch {
                builds: index..index + 1,
                scratch_bytes: scratch,
                result_bytes: build.result_bytes,
                oversized: true,
            });
            plan.oversized_builds.push(index);
            plan.scratch_offsets_bytes.push(0);
            continue;
        }
        let fits = current.as_ref().is_some_and(|batch| {
            let scratch_ok = batch.scratch_bytes + scratch <= limits.scratch_budget_bytes;
            let result_ok = limits.max_batch_result_bytes.is_none_or(|cap| {
                batch
                    .result_bytes
                    .checked_add(build.result_bytes)
                    .is_some_and(|sum| sum <= cap)
            });
            scratch_ok && result_ok
        });
        if !fits {
            plan.batches.extend(current.take());
        }
        let batch = current.get_or_insert(BuildBatch {
            builds: index..index,
            scratch_bytes: 0,
            result_bytes: 0,
            oversized: false,
        });
        plan.scratch_offsets_bytes.push(batch.scratch_bytes);
        batch.builds.end = index + 1;
        batch.scratch_bytes += scratch;
        batch.result_bytes = batch
            .result_bytes
            .checked_add(build.result_bytes)
            .ok_or(BatchError::Overflow(index))?;
    }
    plan.batches.extend(current);
    plan.scratch_pool_bytes = plan
        .batches
        .iter()
        .map(|b| b.scratch_bytes)
        .max()
        .unwrap_or(0);
    Ok(plan)
}

#[cfg(test)]
mod tests;
