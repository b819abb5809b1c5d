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
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! **Safe code over `motu-vk`** (no `ash`, no `unsafe`; it re-exports the device layer's API the
//! crates above use, and its `GpuError` wraps `VkError` with the message unchanged): batched AS
//! builds with compaction (only what the root reaches; BLASes built as `BlasBuild` says — fast
//! trace for a full build, small, i.e. fast build and low memory, when streaming — and sized by a
//! query with the same flags, `BuildOptions::blas_build`; TLASes fast trace; `scene/batch.rs` frees
//! the scratch pool and, through `inputs_done`, a TLAS rebuild's instance buffer once the last
//! batch is built, before the compacted copies), ray-pipeline and ray-query traversal renderers
//! sharing one GLSL core (`render.rs`: `render`; `render/` holds the options, the outputs and
//! stats words, the frame parameters, a frame's buffers and the trace pipeline), the GPU scene (`scene.rs`; `scene/` holds its uploads, batched builds,
//! structures, tables, budget, LOD pass and shading tables), and out-of-core streaming (`stream/`;
//! `StreamingRenderer`'s state lives in parts, each a struct in its own file stating its invariants
//! — `topology.rs` `Topology` (streamed BLASes, parents, proxy clusters and their GPU slots,
//! derived once with the GPU tables' records), `tables.rs` `GpuTables` (the node tables, member
//! table, boxes and stamp buffers on the GPU), `residency.rs` `Resident` (resident BLASes and
//! meshes, LRU, pins, sizes), `tlases.rs` `Tlases` (TLASes with proxies and marks, persistent mode,
//! dirty set), `frame.rs` `FrameState` (frame number, stats, stamps, probe sightings, pipeline,
//! kept buffers), `shading.rs`, `cache.rs` `Reuse`, `stats.rs` (`FrameStreamStats`,
//! `StreamTotals`), `options.rs` (`StreamOptions`) — and the constructor is in `stream.rs` over
//! `skeleton.rs` `HeapSetup`/`raise_skeleton`; a TLAS (re)build is `tlas_build.rs`'s `TlasBuild`,
//! one method per phase; no function in motu-gpu over 150 lines,
//! `no_long_functions_in_motu_gpu`: every TLAS resident but holding only resident BLASes'
//! instances plus one proxy of SAH-clustered boxes for the rest (a ray entering a box tests the
//! cluster's member instances during the hardware walk — `candidates.glsl`'s `record_proxy`, never
//! a candidate slot, so one walk meets every box — and keeps only the nearest open one, so demand
//! is per instance; a ray left open then walks again over PI and proxy boxes only up to its hit,
//! the *mark walk* of `traverse.glsl` (streamed shaders only, `MOTU_STREAMED`: `trace_stream.*`,
//! `pi_stream.rahit`), which marks the rest open: marked during the first walk, against the closest
//! hit so far, most lay behind the hit; `stream/proxy_boxes.rs`: a two-level tree of boxes around
//! each streamable BLAS's triangles, made from the meshes when the renderer starts (or read back from the structure cache, like the proxy clusters: `stream/plan_cache.rs`), that a ray must
//! also enter to open the BLAS), BLASes streamed with their meshes and the image textures those
//! meshes sample (`stream/shading.rs`: reference-counted per resident mesh; meshes in host-visible
//! memory outside the budget on a discrete GPU, `MeshMemory` and `--stream-mesh-memory`, written in
//! place through the mapping, `MeshGpu::put`, and counted by `mesh_budget_bytes` in
//! `stream/residency.rs` only where they take VRAM); per-pixel carried hits so a pass needs one
//! structure at a time (an open primary ray's secondary rays traced ahead from its hit so far,
//! `render_pixel.glsl` state 3); the floor `streaming_floor` shared with the report; TLAS rebuilds
//! (`stream/rebuild.rs`: dirty TLASes rebuilt in groups (each through `stream/tlas_build.rs`),
//! `next_rebuild_group` — the largest alone, small ones together up to a 64th of the budget — so a
//! split root's pieces, which `motu_render::stream_split` makes at load time, are rebuilt one at a
//! time and a rebuild takes one piece's room; a rebuild that cannot fit is refused up front by
//! asking the allocator, `GpuHeap::try_fit`; `stream/tlas_records.rs` counts each chunk's resident
//! instance records, then encodes whole chunks in parallel straight into the mapped staging ring,
//! and the proxies' boxes and PI records are written in place the same way,
//! `Uploader::upload_with`: no host copy of what a rebuild uploads); persistent TLASes instead of
//! rebuilds (`stream/persistent.rs`, `--stream-tlas`: built once over every instance with
//! `ALLOW_UPDATE`, a non-resident instance on its BLAS's placeholder — an AABB BLAS of one box
//! under instance mask 0, the BLAS's whole bounds for the first build (a full build's topology) and
//! a point at their centre after it — so an update changes only references and masks; records in
//! host memory patched where a BLAS's residency changed, update scratch kept; `auto` for TLASes of
//! ≥ 2^20 instances within an eighth of the budget, by `persistent_estimate`, which
//! `persistent_tlas_estimate` also gives the report (`streaming.persistent_tlas`); they give way to
//! rebuilds, `drop_persistent`, when a BLAS, the frame buffers or the pipeline would not fit next
//! to them, since the floor is sized for rebuilt TLASes); the structure cache (`stream/cache.rs`,
//! one owned part `Reuse`: every BLAS build serialised through motu-vk `serialize.rs` into a
//! `StructureCache` — motu-ascache tiers keyed by the scene identity, BLAS records, build flags and
//! driver — and a needed BLAS the cache holds deserialised by copy instead of rebuilt;
//! `restored_*`, `rebuilt_*`, `cache_*` in `--stats`); LRU eviction (`stream/residency.rs`;
//! `--stats` counts its causes per frame and pass: room for BLAS builds, up front for TLAS
//! rebuilds, after refused allocations); draining blocks (`stream/defrag.rs`, opt-in
//! `--stream-defrag`: before evicting for a TLAS rebuild's room or after a refusal, the emptiest
//! standard blocks whose every allocation is a streamed BLAS, mesh or texture are copied — AS
//! clone, buffer copy — into free space other blocks have, the emptied blocks return to the budget,
//! moved BLASes' parents are rebuilt and moved meshes' and textures' addresses rewritten with the
//! step's tables); the probe of the next frame's camera when the caller names it
//! (`stream/probe.rs`: one pass, then up to `probe_rounds` − 1 more over only the pixels the round
//! before left open (`g_probe_open` lists them) after the prefetch built what they needed, then up
//! to `probe_verify_rounds` (`--stream-probe-verify`, default 2) over every pixel again, which
//! bring back what the prefetch evicted that the next frame's rays pass through (`frame.rs`
//! `probe_again`; skipped when nothing was evicted and no pixel is left open), whose sightings the
//! next frame's first pass uses to count why it missed what it needed, `first_pass_missed_*`, and
//! whose hits and passes of resident BLASes are the next frame's need, `probe_need_*`;
//! `STREAM_PROBE_PASS`, runs every ray of its pixels against what is resident and only marks, then
//! the prefetch builds what it met, keeping only what it saw — what its open rays pass through
//! included: each streamed TLAS also holds a *marks* BLAS of its resident clusters' boxes under
//! instance mask 0x02, which only probe rays' mark walks meet, `CULL_MASK_*` in `common.glsl`,
//! `MARKS_MASK` and `TRIANGLE_MASK` in `stream.rs`; with pass marks, `PassMarks` and
//! `--stream-probe-pass-rows` — by default `auto`, every 2nd row for the probes within 4 frames of
//! one that evicted for build room while its prefetch skipped nothing — the final rays of every
//! N-th row walk the marks too and mark what they pass as *passed*, `STREAM_PASS_WALK`, an LRU
//! refresh below what the probe met instead of a keep); bounded frames: a per-frame build budget,
//! the opt-in coarse fallback (a missing structure's bounds, counted) and `render_progressive`,
//! trace with what is resident then build toward the next frame, for the viewer), instance-level
//! LOD (`lod_instances.rs` sets it up, `scene/lod_pass.rs` holds the pass the scene owns: the host
//! picks each slot's level per frame with the CPU oracle's rule, and only when one differs from
//! those the slots' TLASes hold a compute pass writes the levels' instances and the slots' TLASes
//! are rebuilt or, while the camera moves, updated in place (`PassKind`: a refittable tree keeps
//! every level's instance active, the unchosen shrunk to a point and masked; a held camera settles
//! it with one full-quality rebuild)), box lists (`scene/tables.rs` `box_list_instances`: a full
//! build leaves a TLAS's trailing AABB instances of at most 16 PIs, a split root's pieces, out of
//! the hardware TLAS; `traverse.glsl` slab-tests them on the TLAS's first walk; streamed skeletons
//! keep none), a payload sized to the scene (`scene/tables.rs` `pi_capacity`: the candidate slots a
//! TLAS's hardware walk can meet, the specialisation constant `PI_CAPACITY` of every ray-tracing
//! stage), a renderer that keeps its pipeline between frames for the viewer's window; shaders
//! compiled by `build.rs`.
//!
//! Key types: `GpuScene`, `render`, `StreamingRenderer`, `LiveRenderer`, `GpuError` (and motu-vk's
//! `Context`, `list_devices`, `Presenter`, re-exported).

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
pub use motu_vk::testutil;

#[cfg(test)]
mod tests;

pub use error::{GpuError, Result};
pub use live::LiveRenderer;
// The device layer's API as the crates above knew it.
pub use motu_vk::{
    list_devices, parse_size, AsBuildFlags, AsBuildSizes, BindingSet, BlasBuild, BlasGeometry,
    Buffer, BufferDesc, BufferUsage, Caps, CapturedPipeline, CommandRecorder, ComputePipeline,
    ComputePipelineDesc, Context, ContextOptions, DeviceAddress, DeviceMemory, DeviceReport,
    GpuHeap, HeapBuffer, HeapReport, InternalRepresentation, LimitOverrides, Limits,
    MemoryLocation, MemoryRequirements, PanelPaint, PipelineExecutable, PipelineExecutableStats,
    PipelineStatistic, Presented, Presenter, RawDisplayHandle, RawWindowHandle, Requirement,
    StatisticValue, TimestampQueries, TlasBuild, ValidationRequest, VkError,
    ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT, ENV_DEVICE, ENV_MAX_ALLOCATIONS,
    ENV_MAX_ALLOCATION_SIZE, ENV_MAX_INSTANCE_COUNT, ENV_MAX_PRIMITIVE_COUNT,
    ENV_MAX_STORAGE_BUFFER_RANGE, ENV_VALIDATION, INSTANCE_RECORD_SIZE_BYTES,
};

pub use render::{
    heat_colour, render, render_counted, Backend, RayCounts, RenderOptions, RenderOutput,
    RenderStats, View, MAX_STACK_SIZE,
};
pub use scene::{
    full_build_overhead, BuildOptions, ChunkReads, FullBuildOverhead, GpuScene, MeshBlobSource,
    MeshSourceError, ResourceReport,
};
pub use stream::{
    full_build_fits, persistent_tlas_estimate, streamed_mesh_total_bytes, streaming_floor,
    streaming_floor_planned, ClustersSource, FloorSizes, FrameCaps, FrameStreamStats, FullBuildFit,
    HostCacheMode, HostStorePolicy, MeshMemory, PassMarks, PassStats, PersistentEstimate,
    ProbeLater, ProbePaths, ProbeSettings, ProxyCalls, ProxyWork, RoomSplit, StorePolicyStats,
    StreamFallback, StreamFloor, StreamOptions, StreamPlan, StreamTotals, StreamingRenderer,
    StructureCache, TlasRecordsMode, TlasUpdate, AUTO_PASS_FRAMES, AUTO_PASS_ROWS, CLOCKED_PROBE,
    DEFAULT_TLAS_HEADROOM, MAX_TLAS_HEADROOM, PI_EMPTY_BLAS,
};
// Fixed rates for the restore and store rules (`StreamOptions::fixed_rates`, `--stream-rates`).
pub use motu_ascache::{parse_rates, DeviceRates, RatesSpecError};
