//! The VRAM budget a build may use.

use motu_alloc::{effective_budget_bytes, SafetyMargin, MIB};
use motu_vk::Context;

use crate::error::{GpuError, Result};

/// The budget a build may use: the user's, lowered to what `VK_EXT_memory_budget` says is
/// available on the device-local heaps minus a safety margin. Errors when the device lacks
/// what every build needs.
pub(crate) fn usable_budget_bytes(ctx: &Context, user_budget_bytes: u64) -> Result<u64> {
    if !ctx.caps().acceleration_structure || !ctx.caps().buffer_device_address {
        return Err(GpuError::MissingFeature {
            what: "acceleration structures with buffer device address".into(),
            details: ctx.device_name().to_string(),
        });
    }
    let device_available = ctx
        .heaps()
        .iter()
        .filter(|h| h.device_local)
        .filter_map(|h| {
            h.budget_bytes
                .map(|b| b.saturating_sub(h.usage_bytes.unwrap_or(0)))
        })
        .max();
    Ok(effective_budget_bytes(
        Some(user_budget_bytes),
        device_available,
        SafetyMargin::default(),
    )
    .unwrap_or(user_budget_bytes))
}

/// Standard allocator blocks under a user budget are this fraction of it: a partly used block
/// counts against the budget, so blocks stay small next to it.
pub(crate) const BLOCKS_PER_BUDGET: u64 = 64;
/// The staging ring is at most this fraction of the budget: it counts against the budget on
/// unified-memory devices (lavapipe, integrated GPUs), and uploads stream through it in
/// ring-sized pieces, so a smaller ring costs submissions, not correctness.
pub(crate) const STAGING_PER_BUDGET: u64 = 32;
/// The least staging ring.
pub(crate) const MIN_STAGING_BYTES: u64 = 64 * 1024;
/// The full build's staging ring without a budget (or under a large one).
pub(crate) const FULL_BUILD_STAGING_CAP_BYTES: u64 = 64 * MIB;

/// Standard allocator block size under `budget_bytes` (full builds under a user budget and
/// every streaming heap).
pub(crate) fn block_bytes_for_budget(budget_bytes: u64) -> u64 {
    (budget_bytes / BLOCKS_PER_BUDGET).clamp(256 * 1024, 256 * MIB)
}

/// Allocator blocks a budget must leave partly used: two per memory class.
pub(crate) fn allocator_slack_bytes(budget_bytes: u64) -> u64 {
    4 * block_bytes_for_budget(budget_bytes)
}

/// The staging ring under `budget_bytes`, at most `cap_bytes`.
pub(crate) fn staging_bytes_for_budget(budget_bytes: u64, cap_bytes: u64) -> u64 {
    (budget_bytes / STAGING_PER_BUDGET).clamp(MIN_STAGING_BYTES, cap_bytes.max(MIN_STAGING_BYTES))
}

/// What a full build and render needs besides its structures, geometry, tables and build
/// transients (what `motu report` counts per node): see [`full_build_overhead`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FullBuildOverhead {
    /// Frame buffers at the image size (parameters, AOV, colour, counters, readback).
    pub frame_bytes: u64,
    /// The staging ring under the resulting budget (it counts on unified memory; counted
    /// everywhere, so the figure holds on every device).
    pub staging_bytes: u64,
    /// Partly used allocator blocks under the resulting budget.
    pub allocator_slack_bytes: u64,
    /// The sum: `structures_bytes + total_bytes` is the least budget the full build needs.
    pub total_bytes: u64,
}

/// The overhead of building `structures_bytes` (resident bytes plus the largest build
/// transient) in full and rendering `width × height`, under the budget it leads to: the
/// staging ring and block size scale with the budget, so this is the fixed point of
/// `budget = structures + frame + staging(budget) + slack(budget)`, the same policy
/// [`GpuScene::build`](crate::GpuScene::build) follows under `--vram-budget` (with the default
/// `--max-allocations`; a cap under 2,048 means fewer, larger blocks and more slack).
pub fn full_build_overhead(structures_bytes: u64, width: u32, height: u32) -> FullBuildOverhead {
    let pixels = u64::from(width) * u64::from(height);
    let frame = crate::render::frame_bytes(pixels);
    let mut budget = structures_bytes + frame;
    let mut parts = (0, 0);
    for _ in 0..64 {
        let staging = staging_bytes_for_budget(budget, FULL_BUILD_STAGING_CAP_BYTES);
        let slack = allocator_slack_bytes(budget);
        let next = structures_bytes + frame + staging + slack;
        parts = (staging, slack);
        if next <= budget {
            break;
        }
        budget = next;
    }
    FullBuildOverhead {
        frame_bytes: frame,
        staging_bytes: parts.0,
        allocator_slack_bytes: parts.1,
        total_bytes: frame + parts.0 + parts.1,
    }
}
