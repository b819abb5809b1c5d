//! Incremental construction: importers add things in document order; `finish` sorts edges into
//! CSR order with a counting sort (O(n), no per-edge allocation), checks the graph and computes
//! bounds once. An import's builder spills its edges to a scratch file as they come
//! ([`SceneBuilder::spill_edges_to`]).

use crate::scene::{Edge, Prototype};
use crate::{
    Aabb, Camera, CameraId, Element, ElementId, GeometryStore, InMemoryGeometry, Light, LightId,
    Material, MaterialId, MeshData, MeshId, MeshInfo, PrototypeId, Scene, SceneError, Transform34,
};
use std::borrow::Cow;

/// Edges a spilling builder holds before writing them to its file (~3.4 MB of 52-byte edges).
pub const SPILL_CHUNK_EDGES: usize = 1 << 16;

pub struct SceneBuilder {
    prototypes: Vec<Prototype>,
    mesh_owner: Vec<PrototypeId>,
    meshes: Vec<MeshInfo>,
    root_mesh_elements: Vec<ElementId>,
    /// Whose the edges are, in import order: (parent, count) runs of consecutive edges.
    edge_runs: Vec<crate::edge_file::Run>,
    /// Every edge, or with a spill file the ones not yet written to it (under a chunk).
    edges: Vec<Edge>,
    edge_count: usize,
    spill: Option<crate::edge_file::EdgeSpill>,
    edge_elements: Vec<ElementId>,
    materials: Vec<Material>,
    cameras: Vec<Camera>,
    lights: Vec<Light>,
    textures: Vec<crate::Texture>,
    ptex_faces: Vec<(MeshId, crate::PtexFaces)>,
    elements: Vec<Element>,
    geometry: Box<dyn GeometryStore>,
}

impl std::fmt::Debug for SceneBuilder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SceneBuilder")
            .field("edges", &self.edge_count)
            .finish_non_exhaustive()
    }
}

impl Default for SceneBuilder {
    fn default() -> Self {
        Self::new(Box::new(InMemoryGeometry::new()))
    }
}

fn checked_id(len: usize, what: &'static str) -> Result<u32, SceneError> {
    u32::try_from(len).map_err(|_| SceneError::TooMany {
        what,
        count: len as u64,
    })
}

impl SceneBuilder {
    /// A builder with the root prototype (`world`), the `main` element and a default material.
    pub fn new(geometry: Box<dyn GeometryStore>) -> Self {
        Self {
            prototypes: vec![Prototype {
                name: "world".into(),
                element: Scene::MAIN_ELEMENT,
                mesh_range: (0, 0),
                edge_range: (0, 0),
            }],
            mesh_owner: Vec::new(),
            meshes: Vec::new(),
            root_mesh_elements: Vec::new(),
            edge_runs: Vec::new(),
            edges: Vec::new(),
            edge_count: 0,
            spill: None,
            edge_elements: Vec::new(),
            materials: vec![Material::default()],
            cameras: Vec::new(),
            lights: Vec::new(),
            textures: Vec::new(),
            ptex_faces: Vec::new(),
            elements: vec![Element {
                name: "main".into(),
            }],
            geometry,
        }
    }

    pub fn root(&self) -> PrototypeId {
        Scene::ROOT
    }

    /// Writes the instance edges to an unnamed scratch file in `dir` (made at the first full
    /// chunk) as they are added, [`SPILL_CHUNK_EDGES`] at a time, rather than holding them on
    /// the heap until [`SceneBuilder::finish`] (issue 48 item 1: an import's peak memory);
    /// the scene then reads them through a map ([`Scene::edges_in_file`]). A scene whose edges
    /// never fill a chunk keeps them on the heap. Call before adding edges.
    pub fn spill_edges_to(&mut self, dir: &std::path::Path) {
        debug_assert_eq!(self.edge_count, 0, "spill_edges_to after edges were added");
        self.spill = Some(crate::edge_file::EdgeSpill::new(dir.to_path_buf()));
    }

    /// The default material every builder starts with.
    pub fn default_material(&self) -> MaterialId {
        MaterialId(0)
    }

    pub fn add_material(&mut self, m: Material) -> Result<MaterialId, SceneError> {
        let id = MaterialId(checked_id(self.materials.len(), "materials")?);
        self.materials.push(m);
        Ok(id)
    }

    /// Returns the element with this name, creating it on first use.
    pub fn element(&mut self, name: &str) -> Result<ElementId, SceneError> {
        if let Some(i) = self.elements.iter().position(|e| e.name == name) {
            return Ok(ElementId(i as u32));
        }
        let id = ElementId(checked_id(self.elements.len(), "elements")?);
        self.elements.push(Element { name: name.into() });
        Ok(id)
    }

    pub fn add_prototype(
        &mut self,
        name: &str,
        element: ElementId,
    ) -> Result<PrototypeId, SceneError> {
        self.check(element.0, self.elements.len(), "element")?;
        let id = PrototypeId(checked_id(self.prototypes.len(), "prototypes")?);
        self.prototypes.push(Prototype {
            name: name.into(),
            element,
            mesh_range: (0, 0),
            edge_range: (0, 0),
        });
        Ok(id)
    }

    pub fn prototype_count(&self) -> usize {
        self.prototypes.len()
    }

    fn check(&self, index: u32, count: usize, what: &'static str) -> Result<(), SceneError> {
        if (index as usize) < count {
            Ok(())
        } else {
            Err(SceneError::BadId { what, index, count })
        }
    }

    /// Adds a mesh to `proto`, writing its data to the geometry store. `element` matters only for
    /// meshes of the root (other prototypes carry their own element).
    pub fn add_mesh(
        &mut self,
        proto: PrototypeId,
        name: &str,
        material: MaterialId,
        element: ElementId,
        data: &MeshData,
    ) -> Result<MeshId, SceneError> {
        self.add_mesh_cow(proto, name, material, element, Cow::Borrowed(data))
    }

    /// [`Self::add_mesh`] of data the caller gives away: the store may keep it without a copy
    /// ([`GeometryStore::store_owned`]).
    pub fn add_mesh_owned(
        &mut self,
        proto: PrototypeId,
        name: &str,
        material: MaterialId,
        element: ElementId,
        data: MeshData,
    ) -> Result<MeshId, SceneError> {
        self.add_mesh_cow(proto, name, material, element, Cow::Owned(data))
    }

    fn add_mesh_cow(
        &mut self,
        proto: PrototypeId,
        name: &str,
        material: MaterialId,
        element: ElementId,
        data: Cow<'_, MeshData>,
    ) -> Result<MeshId, SceneError> {
        data.validate().map_err(|reason| SceneError::BadMesh {
            name: name.into(),
            reason,
        })?;
        self.check(proto.0, self.prototypes.len(), "prototype")?;
        let id = MeshId(checked_id(self.meshes.len(), "meshes")?);
        let group = if proto == Scene::ROOT {
            element
        } else {
            self.prototypes[proto.index()].element
        };
        // Read before the store may take the data (checked after it, as they always were).
        let vertex_count = checked_id(data.positions.len(), "vertices");
        let triangle_count = checked_id(data.triangle_count(), "triangles");
        let (bounds, has_normals, has_uvs) =
            (data.bounds(), data.normals.is_some(), data.uvs.is_some());
        let location = match data {
            Cow::Borrowed(d) => self.geometry.store(id, group.0, d),
            Cow::Owned(d) => self.geometry.store_owned(id, group.0, d),
        }
        .map_err(SceneError::Store)?;
        self.add_stored_mesh(
            proto,
            element,
            MeshInfo {
                name: name.into(),
                prototype: proto,
                material,
                vertex_count: vertex_count?,
                triangle_count: triangle_count?,
                bounds,
                has_normals,
                has_uvs,
                location,
            },
        )
    }

    /// Adds a mesh whose data the caller already stored (streaming importers write geometry
    /// straight to package chunks). `info.prototype` is overwritten with `proto`.
    pub fn add_stored_mesh(
        &mut self,
        proto: PrototypeId,
        element: ElementId,
        mut info: MeshInfo,
    ) -> Result<MeshId, SceneError> {
        self.check(proto.0, self.prototypes.len(), "prototype")?;
        self.check(info.material.0, self.materials.len(), "material")?;
        self.check(element.0, self.elements.len(), "element")?;
        let id = MeshId(checked_id(self.meshes.len(), "meshes")?);
        info.prototype = proto;
        self.meshes.push(info);
        self.mesh_owner.push(proto);
        if proto == Scene::ROOT {
            self.root_mesh_elements.push(element);
        }
        Ok(id)
    }

    /// The next mesh id `add_mesh` will return (for stores that key data by id).
    pub fn next_mesh_id(&self) -> MeshId {
        MeshId(self.meshes.len() as u32)
    }

    /// Places `child` inside `parent` with `parent_from_child`. `element` matters only when
    /// `parent` is the root.
    pub fn add_instance(
        &mut self,
        parent: PrototypeId,
        child: PrototypeId,
        parent_from_child: Transform34,
        element: ElementId,
    ) -> Result<(), SceneError> {
        let n = self.prototypes.len();
        self.check(parent.0, n, "prototype")?;
        self.check(child.0, n, "prototype")?;
        if !parent_from_child.is_finite() {
            return Err(SceneError::BadTransform {
                parent: self.prototypes[parent.index()].name.clone(),
                child: self.prototypes[child.index()].name.clone(),
            });
        }
        checked_id(self.edge_count + 1, "instance edges")?;
        match self.edge_runs.last_mut() {
            Some((p, n)) if *p == parent.0 => *n += 1,
            _ => self.edge_runs.push((parent.0, 1)),
        }
        self.edge_count += 1;
        self.edges.push(Edge {
            parent_from_child,
            child,
        });
        if parent == Scene::ROOT {
            self.edge_elements.push(element);
        }
        if let Some(spill) = &mut self.spill {
            if self.edges.len() >= SPILL_CHUNK_EDGES {
                spill
                    .append(&self.edges)
                    .map_err(|source| SceneError::EdgeFile {
                        dir: spill.dir().to_path_buf(),
                        source,
                    })?;
                self.edges.clear();
            }
        }
        Ok(())
    }

    pub fn add_camera(&mut self, c: Camera) -> CameraId {
        self.cameras.push(c);
        CameraId(self.cameras.len() as u32 - 1)
    }

    /// A material added so far (the default one is id 0).
    pub fn material(&self, id: MaterialId) -> &Material {
        &self.materials[(id.0 as usize).min(self.materials.len() - 1)]
    }

    /// Registers an image texture file (once per path and use) and returns its index.
    pub fn add_texture(&mut self, t: crate::Texture) -> u32 {
        if let Some(i) = self.textures.iter().position(|x| *x == t) {
            return i as u32;
        }
        self.textures.push(t);
        self.textures.len() as u32 - 1
    }

    /// Records how `mesh`'s triangles map to its Ptex faces (meshes whose material samples a
    /// Ptex texture; without an entry triangle `t` is face `t`).
    pub fn set_ptex_faces(&mut self, mesh: MeshId, faces: crate::PtexFaces) {
        self.ptex_faces.push((mesh, faces));
    }

    pub fn add_light(&mut self, l: Light) -> LightId {
        self.lights.push(l);
        LightId(self.lights.len() as u32 - 1)
    }

    pub fn cameras(&self) -> &[Camera] {
        &self.cameras
    }

    /// Validates the graph, sorts edges into CSR order and computes bounds.
    pub fn finish(self) -> Result<Scene, SceneError> {
        let n = self.prototypes.len();
        let mut prototypes = self.prototypes;

        // CSR for edges: counting sort by parent, stable, so import order is kept per parent.
        let (edges, root_edge_elements) = {
            let mut counts = vec![0u32; n + 1];
            for &(p, k) in &self.edge_runs {
                counts[p as usize + 1] += k;
            }
            for i in 0..n {
                counts[i + 1] += counts[i];
            }
            for (i, p) in prototypes.iter_mut().enumerate() {
                p.edge_range = (counts[i], counts[i + 1]);
            }
            let sorted = self.edge_runs.windows(2).all(|w| w[0].0 <= w[1].0);
            let mut edges = self.edges;
            let table = match self.spill {
                Some(mut spill) if spill.edge_count() > 0 => {
                    let dir = spill.dir().to_path_buf();
                    let err = |source| SceneError::EdgeFile {
                        dir: dir.clone(),
                        source,
                    };
                    spill.append(&edges).map_err(err)?;
                    drop(edges);
                    spill.into_table(&self.edge_runs, sorted).map_err(err)?
                }
                _ => {
                    if !sorted {
                        // Each edge's slot, then the edges permuted in place: no second edge
                        // table, which would double the import's largest table at its peak.
                        let mut cursor = counts.clone();
                        let mut slot: Vec<u32> = Vec::with_capacity(edges.len());
                        for &(p, k) in &self.edge_runs {
                            let s = &mut cursor[p as usize];
                            slot.extend(*s..*s + k);
                            *s += k;
                        }
                        permute_in_place(&mut edges, &mut slot);
                    }
                    crate::edge_file::EdgeTable::Heap(edges)
                }
            };
            (table, self.edge_elements)
        };

        // CSR for meshes (few enough that a sort of ids is fine). Root meshes keep their order so
        // `root_mesh_elements` stays parallel.
        let mut order: Vec<u32> = (0..self.meshes.len() as u32).collect();
        order.sort_by_key(|&m| self.mesh_owner[m as usize]);
        let mut proto_meshes = Vec::with_capacity(order.len());
        let mut start = 0u32;
        for (i, p) in prototypes.iter_mut().enumerate() {
            let begin = start;
            while (start as usize) < order.len()
                && self.mesh_owner[order[start as usize] as usize].index() == i
            {
                proto_meshes.push(MeshId(order[start as usize]));
                start += 1;
            }
            p.mesh_range = (begin, start);
        }

        let mut scene = Scene {
            prototypes,
            proto_meshes,
            edges,
            root_edge_elements,
            root_mesh_elements: self.root_mesh_elements,
            meshes: self.meshes,
            materials: self.materials,
            cameras: self.cameras,
            lights: self.lights,
            textures: self.textures,
            ptex_faces: self.ptex_faces,
            elements: self.elements,
            bounds: Vec::new(),
            topo_order: Vec::new(),
            geometry: self.geometry,
        };
        scene.topo_order = topo_order(&scene)?;
        scene.bounds = compute_bounds(&scene);
        Ok(scene)
    }
}

/// Moves `items[i]` to `items[slot[i]]` for every `i` (`slot` a permutation), in place: each
/// swap puts one item where it belongs. `slot` ends as the identity.
fn permute_in_place<T>(items: &mut [T], slot: &mut [u32]) {
    debug_assert_eq!(items.len(), slot.len());
    for i in 0..items.len() {
        while slot[i] as usize != i {
            let to = slot[i] as usize;
            items.swap(i, to);
            slot.swap(i, to);
        }
    }
}

/// Children before parents (Kahn's algorithm over reversed edges); a leftover means a cycle.
fn topo_order(scene: &Scene) -> Result<Vec<PrototypeId>, SceneError> {
    let n = scene.prototypes.len();
    // Distinct-child out-degree would need a set; counting multi-edges is equivalent for Kahn.
    let mut pending_children = vec![0u32; n];
    let mut parents_of: Vec<Vec<u32>> = vec![Vec::new(); n];
    for p in scene.prototype_ids() {
        for e in scene.walk_edges(p) {
            pending_children[p.index()] += 1;
            // One entry per edge would be 30M+ small pushes for Moana; dedupe consecutive ones.
            let list = &mut parents_of[e.child.index()];
            if list.last() != Some(&p.0) {
                list.push(p.0);
            }
        }
    }
    // Recount with the deduped lists so decrements match.
    pending_children.iter_mut().for_each(|c| *c = 0);
    for list in &parents_of {
        for &p in list {
            pending_children[p as usize] += 1;
        }
    }
    let mut order = Vec::with_capacity(n);
    let mut ready: Vec<u32> = (0..n as u32)
        .filter(|&p| pending_children[p as usize] == 0)
        .collect();
    while let Some(p) = ready.pop() {
        order.push(PrototypeId(p));
        for &parent in &parents_of[p as usize] {
            let c = &mut pending_children[parent as usize];
            *c -= 1;
            if *c == 0 {
                ready.push(parent);
            }
        }
    }
    if order.len() != n {
        let stuck = (0..n).find(|&p| pending_children[p] > 0).unwrap_or(0);
        return Err(SceneError::Cycle {
            id: PrototypeId(stuck as u32),
            name: scene.prototypes[stuck].name.clone(),
        });
    }
    Ok(order)
}

fn compute_bounds(scene: &Scene) -> Vec<Aabb> {
    let mut bounds = vec![Aabb::EMPTY; scene.prototypes.len()];
    for &p in &scene.topo_order {
        let mut b = Aabb::EMPTY;
        for &m in scene.meshes_of(p) {
            b = b.union(&scene.mesh(m).bounds);
        }
        for e in scene.walk_edges(p) {
            b = b.union(&bounds[e.child.index()].transformed(&e.parent_from_child));
        }
        bounds[p.index()] = b;
    }
    bounds
}

#[cfg(test)]
mod tests;
