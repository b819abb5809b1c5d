//! The finished, validated scene: read-only, CSR-ordered, bounds memoised.

use crate::{
    Aabb, Camera, ElementId, GeometryStore, Light, Material, MaterialId, MeshData, MeshId,
    MeshLocation, PrototypeId, Transform34,
};
use serde::{Deserialize, Serialize};
use std::ops::Range;

#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    #[error("instancing cycle: prototype '{name}' ({id}) instances itself through its children")]
    Cycle { id: PrototypeId, name: String },
    #[error("{what} {index} is out of range (only {count} exist)")]
    BadId {
        what: &'static str,
        index: u32,
        count: usize,
    },
    #[error("instance of '{child}' in '{parent}' has a non-finite transform")]
    BadTransform { parent: String, child: String },
    #[error("mesh '{name}': {reason}")]
    BadMesh { name: String, reason: String },
    #[error("geometry store: {0}")]
    Store(#[source] crate::StoreError),
    #[error("too many {what} for 32-bit ids: {count}")]
    TooMany { what: &'static str, count: u64 },
    #[error("instance edges' scratch file in {}: {source}", dir.display())]
    EdgeFile {
        dir: std::path::PathBuf,
        #[source]
        source: std::io::Error,
    },
}

/// A named instance definition.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Prototype {
    pub name: String,
    /// The element whose file defined it (the root belongs to `main`).
    pub element: ElementId,
    pub(crate) mesh_range: (u32, u32),
    pub(crate) edge_range: (u32, u32),
}

/// One instance edge: a placement of `child` inside its parent prototype.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct Edge {
    pub parent_from_child: Transform34,
    pub child: PrototypeId,
}

/// What the skeleton knows of a mesh; the data itself is in the [`GeometryStore`].
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct MeshInfo {
    pub name: String,
    pub prototype: PrototypeId,
    pub material: MaterialId,
    pub vertex_count: u32,
    pub triangle_count: u32,
    /// Bounds in the owning prototype's space.
    pub bounds: Aabb,
    pub has_normals: bool,
    pub has_uvs: bool,
    #[serde(skip)]
    pub location: MeshLocation,
}

/// A top-level part of the scene (pbrt: a file `Include`d or `Import`ed from the entry file's
/// world block, named by its path stem; everything else is `main`).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Element {
    pub name: String,
}

/// Counts that `motu info` reports.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct SceneStats {
    /// Instance edges in the graph.
    pub instances: u64,
    /// Leaf placements after full flattening: root-to-prototype paths (length ≥ 1) ending at a
    /// prototype that carries meshes. Saturates at `u64::MAX`.
    pub flattened_instances: u64,
    pub unique_triangles: u64,
    /// Triangles after full flattening, root meshes included. Saturates at `u64::MAX`.
    pub instanced_triangles: u64,
    pub meshes: u64,
    pub prototypes: u64,
    /// The longest root-to-leaf chain of instance edges.
    pub max_depth: u32,
}

/// The scene graph. Construct with [`crate::SceneBuilder`].
pub struct Scene {
    pub(crate) prototypes: Vec<Prototype>,
    pub(crate) proto_meshes: Vec<MeshId>,
    pub(crate) edges: crate::edge_file::EdgeTable<Edge>,
    pub(crate) root_edge_elements: Vec<ElementId>,
    pub(crate) root_mesh_elements: Vec<ElementId>,
    pub(crate) meshes: Vec<MeshInfo>,
    pub(crate) materials: Vec<Material>,
    pub(crate) cameras: Vec<Camera>,
    pub(crate) lights: Vec<Light>,
    pub(crate) textures: Vec<crate::Texture>,
    pub(crate) ptex_faces: Vec<(MeshId, crate::PtexFaces)>,
    pub(crate) elements: Vec<Element>,
    pub(crate) bounds: Vec<Aabb>,
    /// Children before parents.
    pub(crate) topo_order: Vec<PrototypeId>,
    pub(crate) geometry: Box<dyn GeometryStore>,
}

impl std::fmt::Debug for Scene {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Scene")
            .field("prototypes", &self.prototypes.len())
            .field("edges", &self.edges.len())
            .field("meshes", &self.meshes.len())
            .finish_non_exhaustive()
    }
}

impl Scene {
    pub const ROOT: PrototypeId = PrototypeId(0);
    pub const MAIN_ELEMENT: ElementId = ElementId(0);

    pub fn root(&self) -> PrototypeId {
        Self::ROOT
    }

    pub fn prototypes(&self) -> &[Prototype] {
        &self.prototypes
    }

    pub fn prototype(&self, id: PrototypeId) -> &Prototype {
        &self.prototypes[id.index()]
    }

    pub fn prototype_ids(&self) -> impl ExactSizeIterator<Item = PrototypeId> + '_ {
        (0..self.prototypes.len() as u32).map(PrototypeId)
    }

    /// Children before parents: the order for bottom-up passes.
    pub fn topo_order(&self) -> &[PrototypeId] {
        &self.topo_order
    }

    fn range(r: (u32, u32)) -> Range<usize> {
        r.0 as usize..r.1 as usize
    }

    /// The instance edges of `id`, in import order.
    pub fn edges(&self, id: PrototypeId) -> &[Edge] {
        &self.edges[Self::range(self.prototype(id).edge_range)]
    }

    /// The global index of `id`'s first edge (edges of one prototype are contiguous).
    pub fn edge_base(&self, id: PrototypeId) -> u32 {
        self.prototype(id).edge_range.0
    }

    /// [`Scene::edges`] for walks over every edge: with file-held edges, the pages the walk
    /// has passed are dropped from the resident set every few hundred thousand edges, so a
    /// walk over a Moana-sized skeleton keeps only a window of it resident (issue 48 item 1).
    /// The same edges in the same order.
    pub fn walk_edges(&self, id: PrototypeId) -> WalkEdges<'_> {
        let (begin, end) = self.prototype(id).edge_range;
        WalkEdges {
            table: &self.edges,
            edges: self.edges[begin as usize..end as usize].iter(),
            next: begin as usize,
            released: begin as usize,
            mapped: self.edges.is_mapped(),
        }
    }

    pub fn all_edges(&self) -> &[Edge] {
        &self.edges
    }

    /// Moves the instance edges out of the heap into an unnamed file in `dir` (created there,
    /// never named, so nothing is left behind whatever ends the process), read back through a
    /// read-only map: what an import does once parsing is done, so the edges need not sit in
    /// memory beside the compiled instance table (issue 48 item 1). The edges read the same;
    /// [`Scene::release_edge_pages`] then drops the pages read so far from the resident set.
    /// On error the edges stay on the heap.
    pub fn move_edges_to_file(&mut self, dir: &std::path::Path) -> std::io::Result<()> {
        self.edges.move_to_file(dir)
    }

    /// Whether the edges are in a file ([`Scene::move_edges_to_file`]).
    pub fn edges_in_file(&self) -> bool {
        self.edges.is_mapped()
    }

    /// Drops the pages of file-held edges from this process's resident memory (a no-op for
    /// heap edges): they fault back in, unchanged, when read again. Walks over every edge call
    /// it as they go so that only the edges being walked stay resident.
    pub fn release_edge_pages(&self) -> std::io::Result<()> {
        self.edges.release_pages()
    }

    pub fn meshes_of(&self, id: PrototypeId) -> &[MeshId] {
        &self.proto_meshes[Self::range(self.prototype(id).mesh_range)]
    }

    /// Element of each root edge (parallel to `edges(root)`).
    pub fn root_edge_elements(&self) -> &[ElementId] {
        &self.root_edge_elements
    }

    /// Element of each root mesh (parallel to `meshes_of(root)`).
    pub fn root_mesh_elements(&self) -> &[ElementId] {
        &self.root_mesh_elements
    }

    pub fn meshes(&self) -> &[MeshInfo] {
        &self.meshes
    }

    pub fn mesh(&self, id: MeshId) -> &MeshInfo {
        &self.meshes[id.index()]
    }

    /// Reads a mesh's data from the geometry store.
    pub fn mesh_data(&self, id: MeshId) -> Result<MeshData, SceneError> {
        let info = self.mesh(id);
        self.geometry
            .load(id, info.location)
            .map_err(SceneError::Store)
    }

    pub fn geometry(&self) -> &dyn GeometryStore {
        self.geometry.as_ref()
    }

    pub fn materials(&self) -> &[Material] {
        &self.materials
    }

    pub fn cameras(&self) -> &[Camera] {
        &self.cameras
    }

    pub fn camera_by_name(&self, name: &str) -> Option<&Camera> {
        self.cameras.iter().find(|c| c.name == name)
    }

    pub fn lights(&self) -> &[Light] {
        &self.lights
    }

    /// Image texture files materials refer to by index.
    /// Meshes whose triangles are not one Ptex face each, and how they map ([`crate::PtexFaces`]).
    pub fn ptex_faces(&self) -> &[(MeshId, crate::PtexFaces)] {
        &self.ptex_faces
    }

    pub fn textures(&self) -> &[crate::Texture] {
        &self.textures
    }

    pub fn elements(&self) -> &[Element] {
        &self.elements
    }

    pub fn element_by_name(&self, name: &str) -> Option<ElementId> {
        self.elements
            .iter()
            .position(|e| e.name == name)
            .map(|i| ElementId(i as u32))
    }

    /// Bounds of a prototype in its own space (memoised at build time).
    pub fn bounds(&self, id: PrototypeId) -> Aabb {
        self.bounds[id.index()]
    }

    pub fn world_bounds(&self) -> Aabb {
        self.bounds(Self::ROOT)
    }

    /// Number of root-to-`p` paths for every prototype (root = 1), saturating.
    pub fn path_counts(&self) -> Vec<u64> {
        let mut paths = vec![0u64; self.prototypes.len()];
        paths[Self::ROOT.index()] = 1;
        for &p in self.topo_order.iter().rev() {
            let n = paths[p.index()];
            if n == 0 {
                continue;
            }
            for e in self.walk_edges(p) {
                let c = &mut paths[e.child.index()];
                *c = c.saturating_add(n);
            }
        }
        paths
    }

    pub fn stats(&self) -> SceneStats {
        let paths = self.path_counts();
        let mut s = SceneStats {
            instances: self.edges.len() as u64,
            meshes: self.meshes.len() as u64,
            prototypes: self.prototypes.len() as u64,
            unique_triangles: self.meshes.iter().map(|m| m.triangle_count as u64).sum(),
            ..Default::default()
        };
        for p in self.prototype_ids() {
            let tris: u64 = self
                .meshes_of(p)
                .iter()
                .map(|&m| self.mesh(m).triangle_count as u64)
                .sum();
            let n = paths[p.index()];
            if p != Self::ROOT && tris > 0 {
                s.flattened_instances = s.flattened_instances.saturating_add(n);
            }
            s.instanced_triangles = s.instanced_triangles.saturating_add(n.saturating_mul(tris));
        }
        let mut depth = vec![0u32; self.prototypes.len()];
        for &p in &self.topo_order {
            depth[p.index()] = self
                .walk_edges(p)
                .map(|e| depth[e.child.index()] + 1)
                .max()
                .unwrap_or(0);
        }
        s.max_depth = depth[Self::ROOT.index()];
        s
    }
}

/// The edges of one prototype in order ([`Scene::walk_edges`]), dropping file-held pages as
/// they are passed.
pub struct WalkEdges<'a> {
    table: &'a crate::edge_file::EdgeTable<Edge>,
    edges: std::slice::Iter<'a, Edge>,
    /// The table index of the next edge and of the first whose pages were not dropped.
    next: usize,
    released: usize,
    mapped: bool,
}

impl<'a> Iterator for WalkEdges<'a> {
    type Item = &'a Edge;

    fn next(&mut self) -> Option<&'a Edge> {
        if self.mapped && self.next - self.released >= crate::edge_file::RELEASE_EVERY_EDGES {
            // A failed drop leaves pages resident; the walk reads the same edges either way.
            let _ = self.table.release_range(self.released, self.next);
            self.released = self.next;
        }
        let e = self.edges.next()?;
        self.next += 1;
        Some(e)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        self.edges.size_hint()
    }
}

impl ExactSizeIterator for WalkEdges<'_> {}

impl Drop for WalkEdges<'_> {
    fn drop(&mut self) {
        if self.mapped {
            // Short walks add up (many small prototypes): the table drops every page once
            // enough edges were walked since it last did.
            self.table.note_walked(self.next - self.released);
        }
    }
}
