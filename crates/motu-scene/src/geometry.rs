//! Mesh data and where it lives. The skeleton never holds vertex arrays: a [`GeometryStore`]
//! does (memory for tests and small scenes; package chunks for real imports, so that an import
//! streams geometry to disk as it is parsed).

use crate::{Aabb, MeshId};
use glam::Vec3;

/// One triangle mesh in object space. Quads and polygons are split to triangles on import.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshData {
    pub positions: Vec<[f32; 3]>,
    pub normals: Option<Vec<[f32; 3]>>,
    pub uvs: Option<Vec<[f32; 2]>>,
    /// Three vertex indices per triangle.
    pub indices: Vec<u32>,
}

impl MeshData {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    pub fn bounds(&self) -> Aabb {
        let mut b = Aabb::EMPTY;
        for p in &self.positions {
            b.grow_point(Vec3::from_array(*p));
        }
        b
    }

    /// Checks the invariants every consumer relies on: whole triangles, indices in range,
    /// attribute arrays as long as the positions, finite positions.
    pub fn validate(&self) -> Result<(), String> {
        if self.indices.len() % 3 != 0 {
            return Err(format!(
                "{} indices is not a multiple of 3",
                self.indices.len()
            ));
        }
        let n = self.positions.len();
        if let Some(bad) = self.indices.iter().find(|&&i| i as usize >= n) {
            return Err(format!("index {bad} out of range for {n} vertices"));
        }
        if self.normals.as_ref().is_some_and(|v| v.len() != n) {
            return Err(format!("normal count differs from vertex count {n}"));
        }
        if self.uvs.as_ref().is_some_and(|v| v.len() != n) {
            return Err(format!("uv count differs from vertex count {n}"));
        }
        if self.positions.iter().flatten().any(|v| !v.is_finite()) {
            return Err("non-finite vertex position".into());
        }
        Ok(())
    }

    /// Approximate heap bytes, for budgets and progress.
    pub fn size_bytes(&self) -> u64 {
        (self.positions.len() * 12
            + self.normals.as_ref().map_or(0, |v| v.len() * 12)
            + self.uvs.as_ref().map_or(0, |v| v.len() * 8)
            + self.indices.len() * 4) as u64
    }
}

/// Where a mesh's data is, as the store that wrote it understands it (for the package store:
/// chunk and byte offsets). Opaque to the skeleton.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
pub struct MeshLocation {
    pub a: u64,
    pub b: u64,
}

/// Why a [`GeometryStore`] could not store or load a mesh: the store's own error, kept as the
/// cause (a package store's I/O error, say), not flattened to text.
pub type StoreError = Box<dyn std::error::Error + Send + Sync>;

/// Holds mesh data outside the skeleton.
pub trait GeometryStore: Send + Sync {
    /// Stores a mesh's data and returns where it went. `group` is a locality hint (the mesh's
    /// element): stores keep a group's data together so subsets read only their own chunks.
    fn store(
        &mut self,
        id: MeshId,
        group: u32,
        data: &MeshData,
    ) -> Result<MeshLocation, StoreError>;
    /// [`Self::store`] of data the caller gives away: a store that keeps or forwards whole
    /// meshes (the import's cutting thread, [`InMemoryGeometry`]) takes them without a copy
    /// (a Moana-scale parse's meshes are gigabytes of fresh pages when copied).
    fn store_owned(
        &mut self,
        id: MeshId,
        group: u32,
        data: MeshData,
    ) -> Result<MeshLocation, StoreError> {
        self.store(id, group, &data)
    }
    /// Reads a mesh back.
    fn load(&self, id: MeshId, at: MeshLocation) -> Result<MeshData, StoreError>;
}

/// Keeps everything in memory: tests, generated scenes, OBJ files.
#[derive(Default, Debug)]
pub struct InMemoryGeometry {
    meshes: Vec<MeshData>,
}

impl InMemoryGeometry {
    pub fn new() -> Self {
        Self::default()
    }
}

impl GeometryStore for InMemoryGeometry {
    fn store(
        &mut self,
        id: MeshId,
        group: u32,
        data: &MeshData,
    ) -> Result<MeshLocation, StoreError> {
        self.store_owned(id, group, data.clone())
    }

    fn store_owned(
        &mut self,
        _id: MeshId,
        _group: u32,
        data: MeshData,
    ) -> Result<MeshLocation, StoreError> {
        self.meshes.push(data);
        Ok(MeshLocation {
            a: (self.meshes.len() - 1) as u64,
            b: 0,
        })
    }

    fn load(&self, id: MeshId, at: MeshLocation) -> Result<MeshData, StoreError> {
        self.meshes
            .get(at.a as usize)
            .cloned()
            .ok_or_else(|| format!("{id} not in the in-memory store").into())
    }
}
