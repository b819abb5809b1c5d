//! The scene model: the in-memory scene graph every motu stage speaks.
//!
//! A scene is a DAG of **prototypes** (named instance definitions). A prototype owns meshes and
//! **instance edges** to child prototypes, each with an affine `parent_from_child` transform; the
//! **root** prototype is the world. Edges are stored once, structure-of-arrays, in CSR order
//! (children of one prototype contiguous), so a Moana-scale skeleton (30M+ edges) costs 52 bytes
//! per edge and no per-edge heap allocation.
//!
//! Mesh *data* (vertices, indices) is not part of the skeleton: it lives in a [`GeometryStore`]
//! (in memory for small scenes and tests, package chunks for real imports) and the scene keeps
//! only a [`MeshInfo`] per mesh (counts, bounds, material, where the data is).
//!
//! Build a scene with [`SceneBuilder`]; [`SceneBuilder::finish`] validates the graph (no cycles,
//! ids in range) and computes per-prototype bounds once.
//!
//! # Map
//!
//! (The crate's code map; ARCHITECTURE.md keeps a summary.)
//! The scene graph every stage speaks: prototypes (a DAG), CSR instance edges (`parent_from_child`,
//! 52 B/edge, no per-edge heap), meshes as `MeshInfo` + a `GeometryStore` holding the data,
//! materials, cameras, lights, elements, memoised bounds.
//!
//! Key types: `Scene`, `SceneBuilder`, `Transform34`, `Aabb`, `MeshId`….

mod builder;
mod camera;
mod edge_file;
mod geometry;
mod ids;
mod look;
mod math;
mod scene;

pub use builder::SceneBuilder;
pub use camera::Camera;
pub use geometry::{GeometryStore, InMemoryGeometry, MeshData, MeshLocation, StoreError};
pub use ids::{CameraId, EdgeIndex, ElementId, LightId, MaterialId, MeshId, PrototypeId};
pub use look::{EnvironmentMap, Light, LightKind, Material, PtexFaces, Texture};
pub use math::{Aabb, Transform34};
pub use scene::{Element, MeshInfo, Prototype, Scene, SceneError, SceneStats};
