//! Incremental construction: importers add things in document order; `finish` sorts edges into
//! CSR order with a counting sort (O(n), no per-edge allocation), checks the graph and computes
//! bounds once.

use crate::scene::{Edge, Prototype};
use crate::{
    Aabb, Camera, CameraId, Element, ElementId, GeometryStore, InMemoryGeometry, Light, LightId,
    Material, MaterialId, MeshData, MeshId, MeshInfo, PrototypeId, Scene, SceneError, Transform34,
};

pub struct SceneBuilder {
    prototypes: Vec<Prototype>,
    mesh_owner: Vec<PrototypeId>,
    meshes: Vec<MeshInfo>,
    root_mesh_elements: Vec<ElementId>,
    edge_parent: Vec<PrototypeId>,
    edges: Vec<Edge>,
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
            .field("edges", &self.edges.len())
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
            edge_parent: Vec::new(),
            edges: Vec::new(),
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
        let location = self
            .geometry
            .store(id, group.0, data)
            .map_err(SceneError::Store)?;
        self.add_stored_mesh(
            proto,
            element,
            MeshInfo {
                name: name.into(),
                prototype: proto,
                material,
                vertex_count: checked_id(data.positions.len(), "vertices")?,
                triangle_count: checked_id(data.triangle_count(), "triangles")?,
                bounds: data.bounds(),
                has_normals: data.normals.is_some(),
                has_uvs: data.uvs.is_some(),
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
        checked_id(self.edges.len() + 1, "instance edges")?;
        self.edge_parent.push(parent);
        self.edges.push(Edge {
            parent_from_child,
            child,
        });
        if parent == Scene::ROOT {
            self.edge_elements.push(element);
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
            for p in &self.edge_parent {
                counts[p.index() + 1] += 1;
            }
            for i in 0..n {
                counts[i + 1] += counts[i];
            }
            for (i, p) in prototypes.iter_mut().enumerate() {
                p.edge_range = (counts[i], counts[i + 1]);
            }
            let sorted = self.edge_parent.windows(2).all(|w| w[0] <= w[1]);
            let edges = if sorted {
                self.edges
            } else {
                let mut cursor = counts.clone();
                let mut out = vec![
                    Edge {
                        parent_from_child: Transform34::IDENTITY,
                        child: PrototypeId(0)
                    };
                    self.edges.len()
                ];
                for (e, p) in self.edges.into_iter().zip(&self.edge_parent) {
                    let slot = &mut cursor[p.index()];
                    out[*slot as usize] = e;
                    *slot += 1;
                }
                out
            };
            (edges, self.edge_elements)
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

/// Children before parents (Kahn's algorithm over reversed edges); a leftover means a cycle.
fn topo_order(scene: &Scene) -> Result<Vec<PrototypeId>, SceneError> {
    let n = scene.prototypes.len();
    // Distinct-child out-degree would need a set; counting multi-edges is equivalent for Kahn.
    let mut pending_children = vec![0u32; n];
    let mut parents_of: Vec<Vec<u32>> = vec![Vec::new(); n];
    for p in scene.prototype_ids() {
        for e in scene.edges(p) {
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
        for e in scene.edges(p) {
            b = b.union(&bounds[e.child.index()].transformed(&e.parent_from_child));
        }
        bounds[p.index()] = b;
    }
    bounds
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Quat, Vec3};

    fn quad() -> MeshData {
        MeshData {
            positions: vec![
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [1.0, 1.0, 0.0],
                [0.0, 1.0, 0.0],
            ],
            normals: None,
            uvs: None,
            indices: vec![0, 1, 2, 0, 2, 3],
        }
    }

    #[test]
    fn dag_sharing_counts_paths_not_copies() {
        let mut b = SceneBuilder::default();
        let mat = b.default_material();
        let main = Scene::MAIN_ELEMENT;
        let leaf = b.add_prototype("leaf", main).unwrap();
        b.add_mesh(leaf, "quad", mat, main, &quad()).unwrap();
        let tree = b.add_prototype("tree", main).unwrap();
        for i in 0..3 {
            b.add_instance(
                tree,
                leaf,
                Transform34::from_translation(Vec3::X * i as f32),
                main,
            )
            .unwrap();
        }
        for i in 0..4 {
            b.add_instance(
                b.root(),
                tree,
                Transform34::from_translation(Vec3::Y * i as f32),
                main,
            )
            .unwrap();
        }
        // The root also places a leaf directly: the leaf prototype is shared by two parents.
        b.add_instance(b.root(), leaf, Transform34::IDENTITY, main)
            .unwrap();
        let s = b.finish().unwrap();
        let st = s.stats();
        assert_eq!(st.instances, 3 + 4 + 1);
        assert_eq!(st.flattened_instances, 4 * 3 + 1);
        assert_eq!(st.unique_triangles, 2);
        assert_eq!(st.instanced_triangles, (4 * 3 + 1) * 2);
        assert_eq!(st.max_depth, 2);
        let wb = s.world_bounds();
        assert_eq!(wb.min, [0.0, 0.0, 0.0]);
        assert_eq!(wb.max, [3.0, 4.0, 0.0]);
        assert_eq!(s.mesh_data(MeshId(0)).unwrap(), quad());
    }

    #[test]
    fn interleaved_edges_are_sorted_into_csr_in_import_order() {
        let mut b = SceneBuilder::default();
        let main = Scene::MAIN_ELEMENT;
        let a = b.add_prototype("a", main).unwrap();
        let c = b.add_prototype("c", main).unwrap();
        let t = |x: f32| Transform34::from_translation(Vec3::X * x);
        b.add_instance(b.root(), a, t(1.0), main).unwrap();
        b.add_instance(a, c, t(2.0), main).unwrap();
        b.add_instance(b.root(), c, t(3.0), main).unwrap();
        b.add_instance(a, c, t(4.0), main).unwrap();
        let s = b.finish().unwrap();
        let xs = |p| {
            s.edges(p)
                .iter()
                .map(|e| e.parent_from_child.rows[0][3])
                .collect::<Vec<_>>()
        };
        assert_eq!(xs(s.root()), vec![1.0, 3.0]);
        assert_eq!(xs(a), vec![2.0, 4.0]);
        assert!(xs(c).is_empty());
        assert_eq!(s.root_edge_elements().len(), 2);
    }

    #[test]
    fn cycles_are_rejected() {
        let mut b = SceneBuilder::default();
        let main = Scene::MAIN_ELEMENT;
        let a = b.add_prototype("a", main).unwrap();
        let c = b.add_prototype("c", main).unwrap();
        b.add_instance(a, c, Transform34::IDENTITY, main).unwrap();
        b.add_instance(c, a, Transform34::IDENTITY, main).unwrap();
        b.add_instance(b.root(), a, Transform34::IDENTITY, main)
            .unwrap();
        let err = b.finish().unwrap_err();
        assert!(matches!(err, SceneError::Cycle { .. }), "{err}");
    }

    #[test]
    fn bounds_through_rotated_instances_use_all_corners() {
        let mut b = SceneBuilder::default();
        let main = Scene::MAIN_ELEMENT;
        let m = b.default_material();
        let p = b.add_prototype("unit", main).unwrap();
        let cube = MeshData {
            positions: vec![[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], [1.0, -1.0, 1.0]],
            normals: None,
            uvs: None,
            indices: vec![0, 1, 2],
        };
        b.add_mesh(p, "tri", m, main, &cube).unwrap();
        let rot = Transform34::from_mat4(Mat4::from_quat(Quat::from_rotation_y(0.7)));
        b.add_instance(b.root(), p, rot, main).unwrap();
        let s = b.finish().unwrap();
        let expect = s.mesh(MeshId(0)).bounds.transformed(&rot);
        assert_eq!(s.world_bounds(), expect);
        // Conservative: every transformed vertex is inside.
        for v in &cube.positions {
            let q = rot.transform_point(Vec3::from_array(*v));
            assert!(s.world_bounds().contains(&Aabb::from_min_max(q, q), 1e-5));
        }
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let mut b = SceneBuilder::default();
        let main = Scene::MAIN_ELEMENT;
        let m = b.default_material();
        let bad = MeshData {
            positions: vec![[0.0; 3]],
            indices: vec![0, 1, 2],
            ..Default::default()
        };
        assert!(b.add_mesh(b.root(), "bad", m, main, &bad).is_err());
        assert!(b
            .add_instance(b.root(), PrototypeId(99), Transform34::IDENTITY, main)
            .is_err());
        let mut nan = Transform34::IDENTITY;
        nan.rows[0][0] = f32::NAN;
        let p = b.add_prototype("p", main).unwrap();
        assert!(b.add_instance(b.root(), p, nan, main).is_err());
    }
}
