//! motu-vk: the Vulkan device layer, and the only crate in motu that uses `ash` (and
//! `ash-window`) and holds `unsafe` Vulkan calls.
//!
//! Everything public is safe Rust: a [`Context`] (instance + device + queue, validation
//! messages collected), RAII resources ([`Buffer`], [`DeviceMemory`], [`ComputePipeline`],
//! [`BindingSet`], [`TimestampQueries`], [`AccelStruct`], [`RtPipeline`]), budgeted memory
//! ([`GpuHeap`], applying `motu-alloc`'s policy), fenced submission of typed commands
//! ([`CommandRecorder`]: copies, barriers, dispatches, ray launches, acceleration-structure
//! builds, copies and compacted-size queries; no raw command buffer leaves the crate), device
//! reports for `motu devices` ([`list_devices`]) and presentation to a window ([`Presenter`]).
//! The Vulkan structs of recorded commands are built from motu types in one place, `conv.rs`.
//! `motu-gpu` is the safe renderer layer above it and re-exports what the crates above use.
//!
//! Invariants: every Vulkan handle is owned by one RAII value that destroys it; every resource
//! holds an `Arc` to the device, so the device is destroyed last; resources recorded by
//! reference into a command buffer are borrowed until the submission's fence signalled, and
//! those named by token ([`AsTarget`], [`BufferTarget`]) are kept alive by their owner until
//! then (see [`CommandRecorder`]).
//!
//! Environment: `MOTU_DEVICE` (index), `MOTU_VALIDATION` (`1` forces the validation layer; any
//! validation error then fails [`Context::check_validation`] and the tests), `MOTU_MAX_*`
//! (lower limits for testing, see [`LimitOverrides`]), `MOTU_REQUIRE_GPU` (tests fail instead of
//! skipping without a device).
//!
//! Files, lowest first: `error`, `instance`, `limits`, `capabilities` (what a physical device
//! offers), `report`, `pipeline_stats` (the driver's statistics of compiled pipelines, kept by
//! the context), `context`, `memory`, `heap`, `query`, `pipeline`, `rt_pipeline`, `accel`
//! (AS types), `barrier`, `conv` (motu → Vulkan conversions of what is recorded),
//! `build_sizes` (AS size queries), `structure` (AS objects), `command` (typed recording),
//! `present`.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! **The device layer: the only crate that uses `ash` (and `ash-window`) and makes `unsafe` Vulkan
//! calls.** Instance, device and limits (`capabilities.rs`: what a physical device offers),
//! validation capture, RAII buffers and memory, the budgeted heap (`heap.rs`: motu-alloc's policy
//! applied to device memory), compute and ray-tracing pipelines (the SPIR-V is given by motu-gpu),
//! timestamp and compacted-size queries, acceleration-structure objects and size queries,
//! presentation (surface + swapchain via ash-window; `present/record.rs` records a frame's copy),
//! GPU-test helpers (`testutil`), and fenced submission of typed commands
//! (`CommandRecorder`: copies, barriers, dispatches, ray launches, AS builds, copies and compacted
//! sizes; no raw command buffer leaves it). The conversions of what is recorded are in `conv.rs`
//! (geometry, build flags, copy modes, barriers, instance records); a resource's creation flags
//! stay beside its type (`BufferUsage`).
//!
//! Key types: `Context`, `GpuHeap`, `Buffer`, `CommandRecorder`, `AsBuild`, `AsGeometry`,
//! `AccelStruct`, `RtPipeline`, `Presenter`, `VkError`.

mod accel;
mod barrier;
mod build_sizes;
mod capabilities;
mod command;
mod context;
mod conv;
mod error;
mod heap;
mod instance;
mod limits;
mod memory;
mod panel;
mod pipeline;
mod pipeline_stats;
mod present;
mod query;
mod report;
mod rt_pipeline;
mod serialize;
mod structure;
pub mod testutil;

#[cfg(test)]
mod tests;

pub use accel::{
    AsBuild, AsBuildFlags, AsBuildMode, AsBuildSizes, AsCopyMode, AsGeometry, AsLevel, AsTarget,
    BlasBuild, BlasGeometry, InstanceHit, TlasBuild, ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT,
    INSTANCE_RECORD_SIZE_BYTES,
};
pub use barrier::MemoryScope;
pub use capabilities::{Caps, HeapReport};
pub use command::{BufferCopy, BufferTarget, CommandRecorder, Submitted};
pub use context::{Context, ContextOptions, Requirement, ENV_DEVICE};
pub use conv::encode_instance;
pub use error::{BudgetRefusal, LoaderFault, Result, SizeParseError, VkError};
pub use heap::{BlockCounts, FitRequest, GpuHeap, HeapBuffer};
pub use instance::{ValidationRequest, ENV_VALIDATION};
pub use limits::{
    parse_size, LimitOverrides, Limits, ENV_MAX_ALLOCATIONS, ENV_MAX_ALLOCATION_SIZE,
    ENV_MAX_INSTANCE_COUNT, ENV_MAX_PRIMITIVE_COUNT, ENV_MAX_STORAGE_BUFFER_RANGE,
};
pub use memory::{
    with_mapped_ranges_mut, Buffer, BufferDesc, BufferUsage, DeviceAddress, DeviceMemory,
    MappedRange, MemoryLocation, MemoryRequirements,
};
pub use panel::PanelPaint;
pub use pipeline::{BindingSet, ComputePipeline, ComputePipelineDesc};
pub use pipeline_stats::{
    CapturedPipeline, InternalRepresentation, PipelineExecutable, PipelineExecutableStats,
    PipelineStatistic, StatisticValue,
};
pub use present::{Presented, Presenter, RawDisplayHandle, RawWindowHandle};
pub use query::TimestampQueries;
pub use report::{list_devices, DeviceReport};
pub use rt_pipeline::{RtPipeline, RtShaders, PUSH_CONSTANT_BYTES};
pub use serialize::{SerializedHeader, SERIALIZED_ALIGNMENT, SERIALIZED_HEADER_BYTES};
pub use structure::{AccelStruct, SizeQueries};
