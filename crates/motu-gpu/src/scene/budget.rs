//! The VRAM budget a build may use.

use motu_alloc::{effective_budget_bytes, SafetyMargin};

use crate::context::Context;
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
