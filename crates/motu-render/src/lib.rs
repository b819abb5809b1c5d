//! Rendering a package, shared by `motu render`, `motu view` and `motu bench`: a package's
//! meshes for the tracers, the camera (by name, the scene's, or a view of the bounds) and
//! recorded camera paths, the LOD mode (instance or traversal, and why) and the CPU reference
//! with instance LOD, the scene's shading (lights, sky, the AO distance), the backend, and
//! [`render`]: one `motu render` (CPU, full GPU build, recorded path or the streaming frame
//! loop) with its `--stats` object, whose schema ([`stats`]: `motu render --stats` and `motu
//! view --stats`) owns the JSON keys. The CLI maps its flags onto these types and prints; no
//! Vulkan here (that is `motu-gpu`).
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! Render set-up shared by `motu render`, `view` and `bench`: a package's meshes for both tracers
//! (`meshes.rs`), the camera by name / the scene's / a view of the bounds and the image size,
//! recorded camera paths and their frame cameras, the streaming render's default sweep
//! (`camera.rs`), the LOD mode: instance-level where the rule allows it, else the traversal shader,
//! and why (`lod.rs`), the CPU reference with instance-level LOD (`cpu.rs`), the scene's shading:
//! lights, sky, the AO distance (`shading.rs`), the streaming renderer's per-frame bounds, the
//! split of large TLASes it renders (`stream_split`, which the report, bench flights and the viewer
//! also use; `package_stream_split` reads the split the import stored for the package's own view
//! instead of making it, at the cap the import recorded unless `--stream-split-instances` names
//! another: `package_split_cap`) and the streaming frame loop (`stream.rs`, with `stream.startup`, the time
//! to first pixel by phase, and `StreamPlan`: the proxy clusters made once for the floor and the
//! renderer); the structure cache's tiers from `--host-cache`/`--as-cache` and the package identity
//! its keys start from (`cache.rs`); the backend and the best one of the devices (`backend.rs`);
//! `--denoise` (`denoise.rs`: an edge-aware à-trous filter guided by the AOV's depth, the normals
//! it implies and the materials' base colours; the viewer's N key uses it too); **`render`**
//! (`session.rs`): one `motu render` from typed `RenderSettings` (`settings.rs`) — the CPU
//! reference (`cpu.rs`), a full GPU build, one frame or a recorded camera path (`gpu.rs`), or
//! streaming — reporting each streamed frame to a progress callback (`RenderEvent`) and returning
//! the image with its `--stats` object (the keys of CLI.md, assembled here). `PackageGeometry` is
//! the geometry-only mesh source (`motu report --measure`). No `ash`, no clap.
//!
//! Key types: `render`, `RenderJob`, `RenderSettings`, `RenderEvent`, `Rendered`, `Backend`,
//! `best_backend`, `PackageMeshes`, `PackageGeometry`, `camera_params`, `camera_pose`,
//! `load_camera_path`, `recorded_path_cameras`, `sweep_around_root`, `choose_lod_mode`,
//! `LodChoice`, `LodMode`, `render_cpu_instance_lod`, `scene_shading`, `ShadingOptions`,
//! `StreamBounds`, `stream_split`, `RenderError`.

mod backend;
mod cache;
mod camera;
mod cpu;
pub mod denoise;
mod gpu;
mod lod;
mod meshes;
mod session;
mod settings;
mod shading;
pub mod stats;
mod stream;

pub use backend::{best_backend, Backend};
pub use cache::{package_identity, CacheDir, CacheSettings};
pub use camera::{
    camera_params, camera_pose, load_camera_path, recorded_path_cameras, sweep_around_root,
};
pub use cpu::render_cpu_instance_lod;
pub use gpu::build_scene;
pub use lod::{choose_lod_mode, LodChoice, LodMode};
pub use meshes::{stored_proxy_clusters, PackageGeometry, PackageMeshes};
pub use motu_compile::{StreamSplit, STREAM_SPLIT_INSTANCES};
pub use session::{render, PendingCacheWrites, RenderJob, Rendered};
pub use settings::{
    CameraRequest, DeviceRequest, RenderEvent, RenderSettings, StreamSettings, TraversalLimits,
};
pub use shading::{scene_shading, ShadingOptions, AO_DISTANCE_OF_DIAGONAL};
pub use stats::StreamStartup;
pub use stream::{
    package_split_cap, package_stream_split, stored_stream_split, stored_stream_split_or_none,
    stream_split, SplitCapSource, StreamBounds, INTERACTIVE_BUILD_MS,
};

use motu_alloc::format_size;
use std::path::PathBuf;

/// What went wrong setting up a render.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// `--camera NAME` names no camera of the scene.
    #[error("no camera named '{name}': the scene has {}", if known.is_empty() { "none".to_string() } else { known.join(", ") })]
    NoCamera { name: String, known: Vec<String> },
    #[error("image size {width}×{height} is out of range (1–16384 per side)")]
    ImageSize { width: u32, height: u32 },
    #[error("reading camera path {}", path.display())]
    ReadCameraPath {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("{what}")]
    Cpu {
        what: &'static str,
        #[source]
        source: motu_trace::TraceError,
    },
    #[error("no frame rendered")]
    NoFrame,
    #[error("rewriting LOD selectors as instances")]
    InstanceLod(#[source] motu_abi::HierarchyError),
    #[error("camera path {}", path.display())]
    CameraPath {
        path: PathBuf,
        #[source]
        source: motu_abi::camera::PathError,
    },
    #[error("opening a Vulkan device for ray tracing (`motu devices` lists them; `--backend cpu` needs none)")]
    Device(#[source] motu_gpu::GpuError),
    #[error(
        "--vram-budget {} is more than {device} has ({} of device-local memory): give at most {}, or omit it to use what is free",
        format_size(*budget_bytes),
        format_size(*device_bytes),
        format_size(*device_bytes)
    )]
    BudgetAboveDevice {
        budget_bytes: u64,
        device: String,
        device_bytes: u64,
    },
    #[error("building acceleration structures")]
    Build(#[source] motu_gpu::GpuError),
    /// A full build refused by the budget: what else would render.
    #[error(
        "the full build ({blas_build} BLASes) does not fit under the budget: `motu report` \
         prints what it needs; --stream renders under any budget above its floor, and \
         --blas-build small builds smaller BLASes (a fifth smaller on NVIDIA)"
    )]
    BuildOverBudget {
        blas_build: &'static str,
        #[source]
        source: motu_gpu::GpuError,
    },
    #[error("setting up instance-level LOD")]
    InstanceLodSetup(#[source] motu_gpu::GpuError),
    #[error("rendering on the GPU")]
    Gpu(#[source] motu_gpu::GpuError),
    #[error("rendering camera-path frame {frame}")]
    PathFrame {
        frame: usize,
        #[source]
        source: motu_gpu::GpuError,
    },
    #[error("empty camera path")]
    EmptyCameraPath,
    #[error("Vulkan validation reported errors")]
    Validation(#[source] motu_gpu::GpuError),
    #[error("computing the streaming floor")]
    Floor(#[source] motu_gpu::GpuError),
    /// `--vram-budget` below the streaming floor, with the floor's parts.
    #[error(
        "--vram-budget {} is below the streaming floor of {} ({} bytes) for {width}×{height}: \
         the resident skeleton ({} of tables, {} of TLASes, proxies and PI BLASes), the \
         largest BLAS build ({}), TLAS rebuilds ({}), frame buffers ({}), shading \
         tables and attributes ({}), staging and allocator slack; raise --vram-budget to at least the floor (`motu report` \
         prints it as streaming.min_resident_bytes)",
        format_size(*budget_bytes),
        format_size(floor.min_resident_bytes),
        floor.min_resident_bytes,
        format_size(floor.tables_bytes),
        format_size(floor.skeleton_structures_bytes),
        format_size(floor.largest_blas_build_bytes),
        format_size(floor.tlas_rebuild_bytes),
        format_size(floor.frame_bytes),
        format_size(
            floor.shading_tables_bytes
                + floor.shading_attributes_bytes
                + floor.shading_textures_bytes
        )
    )]
    BelowFloor {
        budget_bytes: u64,
        width: u32,
        height: u32,
        floor: Box<motu_gpu::StreamFloor>,
    },
    #[error("setting up streaming (the resident skeleton must fit the budget; the floor is {floor_bytes} bytes)")]
    StreamSetup {
        floor_bytes: u64,
        #[source]
        source: motu_gpu::GpuError,
    },
    #[error("streaming: splitting the TLASes over {cap} instances into pieces: {source}")]
    StreamSplit {
        cap: u32,
        #[source]
        source: motu_compile::CompileError,
    },
    /// The package's stored split (made at import) cannot be read or does not fit.
    #[error("streaming: splitting the TLASes over {cap} instances into pieces: {source}")]
    StoredSplitRead {
        cap: u32,
        #[source]
        source: motu_pack::PackError,
    },
    #[error(
        "streaming: splitting the TLASes over {cap} instances into pieces: {path}: the stored split: {source}"
    )]
    StoredSplit {
        cap: u32,
        path: String,
        #[source]
        source: motu_compile::CompileError,
    },
    #[error("streaming frame {frame}")]
    StreamFrame {
        frame: u32,
        #[source]
        source: motu_gpu::GpuError,
    },
    /// A streamed frame with unfinished pixels and no `allow_incomplete`.
    #[error(
        "frame {frame}: {pixels} pixels unfinished after {passes} passes ({cause}): the image would be \
         wrong; nothing written (--allow-incomplete writes it with those pixels \
         magenta; --stream-fallback coarse shows what is missing by its bounds, \
         counted)"
    )]
    IncompleteFrame {
        frame: u32,
        pixels: u64,
        passes: u32,
        cause: String,
    },
    /// Rays cut short and no `allow_truncated`.
    #[error("{what}; nothing was written. Raise --stack-size/--max-traces-per-ray, or pass --allow-truncated to write the image anyway")]
    Truncated { what: String },
    #[error(transparent)]
    Trace(#[from] motu_trace::TraceError),
    #[error(transparent)]
    Stats(#[from] serde_json::Error),
}
