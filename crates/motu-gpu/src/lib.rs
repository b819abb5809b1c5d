//! motu-gpu: the Vulkan device layer, and the only crate in motu that uses `ash`.
//!
//! Everything public is safe Rust: a [`Context`] (instance + device + queue, validation
//! messages collected), RAII resources ([`Buffer`], [`DeviceMemory`], [`ComputePipeline`],
//! [`BindingSet`], [`TimestampQueries`]), fenced one-shot submission ([`CommandRecorder`]),
//! device reports for `motu devices` ([`list_devices`]) and the embedded SPIR-V ([`shaders`]).
//!
//! Invariants: every Vulkan handle is owned by one RAII value that destroys it; every resource
//! holds an `Arc` to the device, so the device is destroyed last; resources recorded into a
//! command buffer are borrowed until the submission's fence signalled.
//!
//! Environment: `MOTU_DEVICE` (index), `MOTU_VALIDATION` (`1` forces the validation layer; any
//! validation error then fails [`Context::check_validation`] and the tests), `MOTU_MAX_*`
//! (lower limits for testing, see [`LimitOverrides`]), `MOTU_REQUIRE_GPU` (tests fail instead of
//! skipping without a device).

mod accel;
mod command;
mod context;
mod error;
mod heap;
mod instance;
mod limits;
mod live;
mod lod_instances;
mod memory;
mod pipeline;
mod present;
mod probe;
mod query;
mod render;
mod report;
mod rt_pipeline;
mod scene;
pub mod shaders;
// The scene's shading tables are part of the GPU scene; `crate::shading` names them.
use scene::shading;
mod stream;
pub mod testing;

#[cfg(test)]
mod gpu_tests;
#[cfg(test)]
mod render_tests;
#[cfg(test)]
mod stream_tests;

pub use accel::{
    AsBuildFlags, AsBuildSizes, BlasBuild, BlasGeometry, ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT,
    INSTANCE_RECORD_SIZE_BYTES,
};
pub use command::CommandRecorder;
pub use context::{Context, ContextOptions, Requirement, ENV_DEVICE};
pub use error::{GpuError, Result};
pub use heap::{GpuHeap, HeapBuffer};
pub use instance::{ValidationRequest, ENV_VALIDATION};
pub use limits::{
    parse_size, LimitOverrides, Limits, ENV_MAX_ALLOCATIONS, ENV_MAX_ALLOCATION_SIZE,
    ENV_MAX_INSTANCE_COUNT, ENV_MAX_PRIMITIVE_COUNT, ENV_MAX_STORAGE_BUFFER_RANGE,
};
pub use live::LiveRenderer;
pub use memory::{
    Buffer, BufferDesc, BufferUsage, DeviceAddress, DeviceMemory, MemoryLocation,
    MemoryRequirements,
};
pub use pipeline::{BindingSet, ComputePipeline, ComputePipelineDesc};
pub use present::{Presented, Presenter, RawDisplayHandle, RawWindowHandle};
pub use probe::{Caps, HeapReport};
pub use query::TimestampQueries;

pub use render::{
    heat_colour, render, render_counted, Backend, RayCounts, RenderOptions, RenderOutput,
    RenderStats, View, MAX_STACK_SIZE,
};
pub use report::{list_devices, DeviceReport};
pub use scene::{
    full_build_overhead, BuildOptions, FullBuildOverhead, GpuScene, MeshBlobSource, ResourceReport,
};
pub use stream::{
    persistent_tlas_estimate, streamed_mesh_total_bytes, streaming_floor, streaming_floor_planned,
    FloorSizes, FrameStreamStats, MeshMemory, PassMarks, PassStats, PersistentEstimate,
    StreamFallback, StreamFloor, StreamOptions, StreamPlan, StreamTotals, StreamingRenderer,
    TlasUpdate, AUTO_PASS_FRAMES, AUTO_PASS_ROWS, PI_EMPTY_BLAS,
};
