//! The compiled traversal hierarchy as flat, `Pod`, `#[repr(C)]` tables: what the compiler
//! writes, the package stores, the CPU oracle walks and the GPU shaders read. This crate is the
//! one source of truth for those layouts: `shaders/generated/abi.glsl` is generated from
//! [`glsl::abi_glsl`] and a test fails if the committed file differs (set
//! `MOTU_UPDATE_GLSL=1` to rewrite it).
//!
//! # The hierarchy
//! - A **TLAS** ([`TlasRecord`], even level) holds instances ([`InstanceRecord`]), each a BLAS
//!   with a `tlas_from_blas` transform. A TLAS's instances are the contiguous range
//!   `instance_base .. instance_base + instance_count` of the instance table; on the GPU the
//!   instance index within the TLAS (the instance's custom index, < 2^24: a streamed TLAS
//!   holds only its resident instances) is added to `instance_base`
//!   (a 32-bit per-TLAS record table: node ids never travel in 24-bit fields).
//! - A **BLAS** ([`BlasRecord`], odd level) holds either triangles (one geometry per compiled
//!   mesh, [`GeometryRecord`]) or AABBs: **programmable instances** ([`PiRecord`]), each
//!   continuing traversal in another TLAS (multi-level instancing) or in a LOD selector.
//!   Vulkan forbids both kinds in one BLAS, so they never mix. An AABB BLAS is always
//!   instanced with the identity ([`HierarchyView::check_references`] rejects anything else):
//!   a PI's `child_from_parent` is then the whole step, and the GPU never inverts an instance
//!   transform per candidate.
//! - A **LOD selector** ([`LodSelectorRecord`]) picks one of `level_count` TLASes (finest
//!   first) by projected size ([`lod::select_lod`]).
//! - **Meshes** ([`MeshRecord`]) are compiled meshes: every source mesh (LOD 0) and its
//!   simplified levels; the hit identity is `(source_mesh, primitive)` plus the LOD.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! **One source of truth** for everything shared with GLSL: the hierarchy records, camera model,
//! LOD rule (per ray, and per instance from the camera: `lod_instance` rewrites camera-only LOD
//! selectors as TLAS instance slots), AOV file, the shading rules (`shade`: lights, textures,
//! RGB9E5 and auto exposure; `env`: an environment map's importance-sampling tables, which the GPU
//! reads after the frame parameters; `sampling`: every pixel's sample sequence, Owen-scrambled
//! Sobol pairs mirrored bit for bit by `shaders/sampling.glsl`, a GPU test compares the two;
//! `ptex`: a Ptex texture's words in the texel store — per-mesh triangle → face tables, face table,
//! texels — and its sampling by face id and face uv, which `texture.glsl` mirrors). Generates
//! `shaders/generated/abi.glsl`; a test proves std430 offsets equal Rust offsets and that the
//! committed file is current.
//!
//! Key types: `HierarchyView`, `TlasRecord`, `PiRecord`, `CameraParams`, `select_lod`,
//! `InstanceLod`, `Aov`, `shade::Shading`, `env::Environment`.

pub mod aov;
pub mod blob;
pub mod camera;
pub mod env;
pub mod glsl;
pub mod lod;
pub mod lod_instance;
pub mod ptex;
mod records;
pub mod sampling;
pub mod shade;
pub mod tlas_compact;

pub use records::*;

/// TLAS walks one ray may make before its traversal is cut short (every backend): bounds a
/// frame's work on exponentially deep instancing. Real scenes spend tens of walks per ray;
/// cut rays are counted (`truncated_rays`) and a render with any fails unless allowed.
pub const DEFAULT_MAX_TRACES_PER_RAY: u32 = 4096;
pub use shade::{LightRecord, TextureRecord};
