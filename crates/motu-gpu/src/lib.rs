//! motu-gpu: the GPU scene, the renderers and out-of-core streaming, in safe Rust over the
//! device layer `motu-vk` (the only crate that uses `ash` or makes `unsafe` Vulkan calls).
//!
//! A [`GpuScene`] is a compiled hierarchy built on the device under a VRAM budget; [`render`]
//! traces it once, [`LiveRenderer`] frame after frame, [`StreamingRenderer`] out of core (see
//! `stream/`). Commands are recorded through motu-vk's typed [`CommandRecorder`] (copies,
//! barriers, dispatches, ray launches, acceleration-structure builds and copies): no raw
//! Vulkan here. The SPIR-V of `shaders/` is compiled by `build.rs` and embedded ([`shaders`]).
//!
//! The device layer's public API is re-exported (the crates above use `motu_gpu::Context`,
//! `motu_gpu::list_devices`, `motu_gpu::Presenter`, …), so nothing above this crate depends on
//! motu-vk. [`GpuError`] wraps motu-vk's [`VkError`] with its message unchanged.

mod error;
mod live;
mod lod_instances;
mod render;
mod scene;
pub mod shaders;
// The scene's shading tables are part of the GPU scene; `crate::shading` names them.
use scene::shading;
mod stream;
/// Helpers for GPU tests in this and other crates (motu-vk's).
pub use motu_vk::testing;

#[cfg(test)]
mod gpu_tests;
#[cfg(test)]
mod render_tests;
#[cfg(test)]
mod sampling_tests;
#[cfg(test)]
mod stream_tests;

pub use error::{GpuError, Result};
pub use live::LiveRenderer;
// The device layer's API as the crates above knew it.
pub use motu_vk::{
    list_devices, parse_size, AsBuildFlags, AsBuildSizes, BindingSet, BlasBuild, BlasGeometry,
    Buffer, BufferDesc, BufferUsage, Caps, CommandRecorder, ComputePipeline, ComputePipelineDesc,
    Context, ContextOptions, DeviceAddress, DeviceMemory, DeviceReport, GpuHeap, HeapBuffer,
    HeapReport, LimitOverrides, Limits, MemoryLocation, MemoryRequirements, PanelPaint, Presented,
    Presenter, RawDisplayHandle, RawWindowHandle, Requirement, TimestampQueries, ValidationRequest,
    VkError, ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT, ENV_DEVICE, ENV_MAX_ALLOCATIONS,
    ENV_MAX_ALLOCATION_SIZE, ENV_MAX_INSTANCE_COUNT, ENV_MAX_PRIMITIVE_COUNT,
    ENV_MAX_STORAGE_BUFFER_RANGE, ENV_VALIDATION, INSTANCE_RECORD_SIZE_BYTES,
};

pub use render::{
    heat_colour, render, render_counted, Backend, RayCounts, RenderOptions, RenderOutput,
    RenderStats, View, MAX_STACK_SIZE,
};
pub use scene::{
    full_build_overhead, BuildOptions, FullBuildOverhead, GpuScene, MeshBlobSource, ResourceReport,
};
pub use stream::{
    persistent_tlas_estimate, streamed_mesh_total_bytes, streaming_floor, streaming_floor_planned,
    FloorSizes, FrameStreamStats, MeshMemory, PassMarks, PassStats, PersistentEstimate,
    StreamFallback, StreamFloor, StreamOptions, StreamPlan, StreamTotals, StreamingRenderer,
    StructureCache, TlasUpdate, AUTO_PASS_FRAMES, AUTO_PASS_ROWS, PI_EMPTY_BLAS,
};
