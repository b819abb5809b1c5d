//! Helpers for GPU tests in this and other crates: open a validated context or say loudly why not.

use crate::context::{Context, ContextOptions, Requirement};
use crate::error::VkError;
use crate::instance::ValidationRequest;

/// Set by CI: a missing device fails GPU tests instead of skipping them.
pub const ENV_REQUIRE_GPU: &str = "MOTU_REQUIRE_GPU";

fn require_gpu() -> bool {
    std::env::var(ENV_REQUIRE_GPU).is_ok_and(|v| v.trim() == "1")
}

/// Opens the default device (meeting `require`) with validation on for a test named `test`.
/// Validation is required when `MOTU_VALIDATION=1` or `MOTU_REQUIRE_GPU=1`, else preferred.
/// Returns `None` after printing `SKIPPED: no Vulkan device: …` when no suitable device exists;
/// panics instead when `MOTU_REQUIRE_GPU=1`.
pub fn context_or_skip(test: &str, require: Requirement) -> Option<Context> {
    let strict = require_gpu()
        || std::env::var(crate::instance::ENV_VALIDATION).is_ok_and(|v| v.trim() == "1");
    let options = ContextOptions {
        validation: if strict {
            ValidationRequest::Required
        } else {
            ValidationRequest::Preferred
        },
        require,
        ..Default::default()
    };
    match Context::new(&options) {
        Ok(ctx) => {
            if !ctx.validation_enabled() {
                eprintln!(
                    "WARNING: {test}: running WITHOUT Vulkan validation (layer not installed)"
                );
            }
            Some(ctx)
        }
        Err(
            e @ (VkError::LoaderMissing { .. }
            | VkError::NoDevice
            | VkError::MissingFeature { .. }
            | VkError::NoSurface { .. }),
        ) => {
            if require_gpu() {
                panic!("{test}: {ENV_REQUIRE_GPU}=1 but no usable Vulkan device: {e}");
            }
            eprintln!("SKIPPED: no Vulkan device: {test}: {e}");
            None
        }
        Err(e) => panic!("{test}: cannot open the Vulkan device: {e}"),
    }
}

/// Panics with every message if the context collected validation errors.
pub fn assert_no_validation_errors(ctx: &Context) {
    let errors = ctx.validation_errors();
    assert!(
        errors.is_empty(),
        "{} Vulkan validation error(s):\n{}",
        errors.len(),
        errors.join("\n")
    );
}

/// A heap for a GPU unit test: `budget_bytes` of device-local and of host-visible memory, at
/// most 64 blocks, each up to the device's largest allocation.
pub fn test_heap(ctx: &Context, budget_bytes: u64) -> crate::heap::GpuHeap {
    crate::heap::GpuHeap::new(
        ctx,
        motu_alloc::AllocLimits {
            max_allocation_count: 64,
            max_allocation_size_bytes: ctx.limits().max_memory_allocation_size,
            budget_bytes,
            host_visible_budget_bytes: budget_bytes,
        },
    )
    .expect("test heap")
}
