//! Emission: one walk per TLAS, depth-first from the root, writing straight into the output
//! tables (the instance table is the only large allocation; the walk itself keeps one frame per
//! graph level). Levels and exact bounds are filled in by `finalize`.

use crate::analyze::{edge_ref, Plan};
use crate::partition::{group_by_location, partition_mesh, Cluster, Item};
use crate::split::median_partition;
use crate::tables::{next_id, set_bounds};
use crate::{
    lod, tlas_split, xform, CompileError, CompiledScene, MeshLoader, MeshSink, StoredClusters,
};
use motu_abi::{
    BlasRecord, GeometryRecord, InstanceRecord, LodSelectorRecord, MaterialRecord, MeshRecord,
    PiRecord, TlasRecord, BLAS_TRIANGLES, FLAG_HAS_NORMALS, FLAG_HAS_UVS, FLAG_NEEDS_ANY_HIT,
    FLAG_PRIMITIVE_MAP, NONE_U32, NONE_U64, PI_LOD_SELECTOR, PI_TLAS,
};
use motu_scene::{Aabb, MeshData, MeshId, PrototypeId, Scene, Transform34};

/// What a TLAS holds, decided when it is first referenced and emitted later (depth-first).
#[derive(Clone, Copy, Debug)]
pub(crate) enum Job {
    /// `TLAS(P)`: the walk from prototype `P`.
    Proto(PrototypeId),
    /// One LOD level: mesh records `first..first + count` (one, or the level's clusters), an
    /// instance of a one-mesh triangle BLAS each.
    Lod(u32, u32),
}

struct Frame {
    proto: PrototypeId,
    next_edge: usize,
    end_edge: usize,
    tlas_from_proto: Transform34,
    /// In the root TLAS: the element of the root edge this walk came through.
    element: u32,
}

pub(crate) struct Emitter<'p, 's, 'k, 'f> {
    plan: &'p Plan<'s>,
    load: &'k MeshLoader<'f>,
    stored: &'k mut StoredClusters<'f>,
    sink: &'k mut MeshSink<'f>,
    pub out: CompiledScene,
    tlas_of_proto: Vec<u32>,
    /// `G(P)` as a range of BLAS ids (several when the triangle cap splits it); count 0 = none.
    g_of_proto: Vec<(u32, u32)>,
    /// A baked prototype's BLASes (`Plan::bakes`), as a range; count 0 = not made yet.
    bake_of_proto: Vec<(u32, u32)>,
    record_of_mesh: Vec<u32>,
    selector_of_mesh: Vec<u32>,
    /// Instance flags per BLAS.
    blas_flags: Vec<u32>,
    /// Element of each BLAS made for root content (`G(root)` groups), else `NONE_U32`.
    blas_element: Vec<u32>,
    /// Emitting the root TLAS: its instances and PIs carry elements (`--subset` at run time).
    in_root: bool,
    /// Element of each PI pushed while `in_root`, parallel to `pis[root_pi_base..]`.
    pi_elements: Vec<u32>,
    new_children: Vec<(u32, Job)>,
    frames: Vec<Frame>,
    root_element: u32,
    instance_cap: usize,
}

impl<'p, 's, 'k, 'f> Emitter<'p, 's, 'k, 'f> {
    pub fn new(
        plan: &'p Plan<'s>,
        load: &'k MeshLoader<'f>,
        stored: &'k mut StoredClusters<'f>,
        sink: &'k mut MeshSink<'f>,
    ) -> Self {
        let scene = plan.scene;
        let n = scene.prototypes().len();
        let out = CompiledScene {
            materials: scene
                .materials()
                .iter()
                .map(|m| MaterialRecord {
                    base_color: m.base_color,
                    opacity: m.opacity,
                    emission: m.emission,
                    roughness: m.roughness,
                    metallic: m.metallic,
                    base_color_texture: m.base_color_texture.unwrap_or(NONE_U32),
                    alpha_texture: m.alpha_texture.unwrap_or(NONE_U32),
                    _pad: 0,
                })
                .collect(),
            ..Default::default()
        };
        Self {
            plan,
            load,
            stored,
            sink,
            out,
            tlas_of_proto: vec![NONE_U32; n],
            g_of_proto: vec![(NONE_U32, 0); n],
            bake_of_proto: vec![(NONE_U32, 0); n],
            record_of_mesh: vec![NONE_U32; scene.meshes().len()],
            selector_of_mesh: vec![NONE_U32; scene.meshes().len()],
            blas_flags: Vec::new(),
            blas_element: Vec::new(),
            in_root: false,
            pi_elements: Vec::new(),
            new_children: Vec::new(),
            frames: Vec::new(),
            root_element: root_element(plan),
            instance_cap: usize::try_from(plan.opts.effective_instance_cap()).unwrap_or(usize::MAX),
        }
    }

    pub fn run(mut self) -> Result<CompiledScene, CompileError> {
        let _span = tracing::info_span!("emit").entered();
        // The instance table is the one large allocation: reserve it once (splits add a few
        // AABB-BLAS instances per cap-sized piece), and fail cleanly if it cannot be had.
        let estimate = self.plan.instance_estimate;
        let reserve =
            estimate + estimate / (self.plan.opts.effective_instance_cap().max(4) / 4) + 64;
        let reserve = reserve.min(u64::from(u32::MAX)) as usize;
        self.out
            .instances
            .try_reserve_exact(reserve)
            .map_err(|_| CompileError::OutOfMemory {
                what: "instances",
                bytes: reserve as u64 * std::mem::size_of::<InstanceRecord>() as u64,
            })?;
        let root = self.tlas_for_proto(Scene::ROOT)?;
        self.out.root_tlas = root;
        let mut jobs = std::mem::take(&mut self.new_children);
        while let Some((tlas, job)) = jobs.pop() {
            self.emit_tlas(tlas, job)?;
            // Children got consecutive ids; push reversed so the first is emitted next.
            jobs.extend(self.new_children.drain(..).rev());
        }
        let bound = self.bound();
        let r = &mut self.out.report;
        r.dropped_degenerate_instances += self.plan.dropped_degenerate;
        r.collapsed_prototypes = self.plan.collapsed_prototypes;
        r.inlined_prototypes = self.plan.auto_inlined_prototypes;
        r.flattened_instances = self.plan.flattened_instances;
        r.levels = format!("{:?}", self.plan.opts.levels).to_lowercase();
        r.max_blas_triangles = u64::from(bound);
        Ok(self.out)
    }

    fn new_tlas(&mut self, job: Job, element: u32) -> Result<u32, CompileError> {
        let id = next_id(self.out.tlases.len(), "TLASes")?;
        self.out.tlases.push(TlasRecord {
            element,
            ..Default::default()
        });
        self.new_children.push((id, job));
        Ok(id)
    }

    fn tlas_for_proto(&mut self, p: PrototypeId) -> Result<u32, CompileError> {
        let t = self.tlas_of_proto[p.index()];
        if t != NONE_U32 {
            return Ok(t);
        }
        let element = if p == Scene::ROOT {
            self.root_element
        } else {
            self.plan.scene.prototype(p).element.0
        };
        let t = self.new_tlas(Job::Proto(p), element)?;
        self.tlas_of_proto[p.index()] = t;
        Ok(t)
    }

    /// `element` is the placement's element in the root TLAS (`NONE_U32`: the BLAS's own).
    fn push_instance(
        &mut self,
        blas: u32,
        tlas_from_blas: &Transform34,
        element: u32,
    ) -> Result<(), CompileError> {
        next_id(self.out.instances.len(), "instances")?;
        let element = match (self.in_root, element) {
            (false, _) => NONE_U32,
            (true, NONE_U32) => self.blas_element[blas as usize],
            (true, e) => e,
        };
        self.out.instances.push(InstanceRecord {
            tlas_from_blas: xform::to_array(tlas_from_blas),
            blas,
            flags: self.blas_flags[blas as usize],
            element,
            _pad: 0,
        });
        Ok(())
    }

    fn push_pi(&mut self, pi: PiRecord, element: u32) -> Result<(), CompileError> {
        next_id(self.out.pis.len(), "programmable instances")?;
        self.out.pis.push(pi);
        if self.in_root {
            self.pi_elements.push(element);
        }
        Ok(())
    }

    fn emit_tlas(&mut self, tlas: u32, job: Job) -> Result<(), CompileError> {
        let base = self.out.instances.len();
        let pi_base = self.out.pis.len();
        self.in_root = tlas == self.out.root_tlas;
        self.pi_elements.clear();
        match job {
            Job::Proto(p) => self.walk(p)?,
            Job::Lod(first, count) => {
                for record in first..first + count {
                    let blas = self.triangle_blas(&[record], NONE_U32)?;
                    self.push_instance(blas, &Transform34::IDENTITY, NONE_U32)?;
                }
            }
        }
        let pi_end = self.out.pis.len();
        if pi_end > pi_base {
            self.aabb_blases(pi_base, pi_end)?;
        }
        let t = &mut self.out.tlases[tlas as usize];
        t.instance_base = next_id(base, "instances")?;
        t.instance_count = next_id(self.out.instances.len() - base, "instances")?;
        self.split_tlas(tlas)?;
        self.in_root = false;
        Ok(())
    }

    /// The walk from `root` with identity: expanded edges add their content, the others PIs.
    fn walk(&mut self, root: PrototypeId) -> Result<(), CompileError> {
        let scene = self.plan.scene;
        let edges = scene.all_edges();
        self.visit(root, &Transform34::IDENTITY, NONE_U32)?;
        self.push_frame(root, Transform34::IDENTITY, NONE_U32);
        while let Some(top) = self.frames.last_mut() {
            if top.next_edge == top.end_edge {
                self.frames.pop();
                continue;
            }
            let i = top.next_edge;
            top.next_edge += 1;
            let (parent, tlas_from_parent) = (top.proto, top.tlas_from_proto);
            let mut element = top.element;
            let e = &edges[i];
            if !self.plan.edge_kept(parent, i, edge_ref!(e)) {
                continue;
            }
            if self.in_root && parent == Scene::ROOT {
                let local = i - scene.edge_base(Scene::ROOT) as usize;
                element = scene
                    .root_edge_elements()
                    .get(local)
                    .map_or(NONE_U32, |e| e.0);
            }
            let tlas_from_child = xform::compose(&tlas_from_parent, &e.parent_from_child);
            if self.plan.bakes(e.child) {
                let (first, count) = self.bake_for_proto(e.child)?;
                for b in first..first + count {
                    self.push_instance(b, &tlas_from_child, element)?;
                }
                continue;
            }
            let child_from_tlas = if self.plan.expands(edge_ref!(e)) {
                None
            } else {
                // A composition can underflow to singular even when every edge is invertible:
                // such a child is expanded instead, which needs no inverse.
                xform::inverse(&tlas_from_child)
            };
            match child_from_tlas {
                None => {
                    self.visit(e.child, &tlas_from_child, element)?;
                    self.push_frame(e.child, tlas_from_child, element);
                }
                Some(child_from_tlas) => {
                    let target = self.tlas_for_proto(e.child)?;
                    let aabb = scene.bounds(e.child).transformed(&tlas_from_child);
                    self.push_pi(
                        PiRecord {
                            child_from_parent: xform::to_array(&child_from_tlas),
                            aabb_min: aabb.min,
                            kind: PI_TLAS,
                            aabb_max: aabb.max,
                            target,
                        },
                        element,
                    )?;
                }
            }
        }
        Ok(())
    }

    fn push_frame(&mut self, proto: PrototypeId, tlas_from_proto: Transform34, element: u32) {
        let scene = self.plan.scene;
        let begin = scene.edge_base(proto) as usize;
        self.frames.push(Frame {
            proto,
            next_edge: begin,
            end_edge: begin + scene.edges(proto).len(),
            tlas_from_proto,
            element,
        });
    }

    /// `p`'s own meshes placed at `tlas_from_proto`.
    /// `element`: the root edge's element in the root TLAS (`NONE_U32` for the root's meshes,
    /// whose BLASes carry their own).
    fn visit(
        &mut self,
        p: PrototypeId,
        tlas_from_proto: &Transform34,
        element: u32,
    ) -> Result<(), CompileError> {
        if self.plan.lod_mesh_count[p.index()] > 0 {
            let scene = self.plan.scene;
            let inv = xform::inverse(tlas_from_proto);
            for (j, &m) in scene.meshes_of(p).iter().enumerate() {
                if !self.plan.mesh_kept(p, j, m) || !self.plan.mesh_gets_lod(m) {
                    continue;
                }
                let Some(proto_from_tlas) = inv else {
                    self.out.report.dropped_degenerate_instances += 1;
                    continue;
                };
                let selector = self.selector_for(p, j, m)?;
                let aabb = scene.mesh(m).bounds.transformed(tlas_from_proto);
                let element = if element == NONE_U32 {
                    self.mesh_element(p, j)
                } else {
                    element
                };
                self.push_pi(
                    PiRecord {
                        child_from_parent: xform::to_array(&proto_from_tlas),
                        aabb_min: aabb.min,
                        kind: PI_LOD_SELECTOR,
                        aabb_max: aabb.max,
                        target: selector,
                    },
                    element,
                )?;
            }
        }
        if self.plan.g_mesh_count[p.index()] > 0 {
            let (first, count) = self.g_for_proto(p)?;
            for b in first..first + count {
                self.push_instance(b, tlas_from_proto, element)?;
            }
        }
        Ok(())
    }

    fn mesh_element(&self, p: PrototypeId, j: usize) -> u32 {
        let scene = self.plan.scene;
        if p == Scene::ROOT {
            scene.root_mesh_elements().get(j).map_or(NONE_U32, |e| e.0)
        } else {
            scene.prototype(p).element.0
        }
    }

    /// The record of source mesh `m` (whole, LOD 0), as it is in the scene.
    fn source_record(&self, p: PrototypeId, j: usize, m: MeshId) -> MeshRecord {
        let info = self.plan.scene.mesh(m);
        let mut flags = self.material_flags(info.material.0);
        if info.has_normals {
            flags |= FLAG_HAS_NORMALS;
        }
        if info.has_uvs {
            flags |= FLAG_HAS_UVS;
        }
        MeshRecord {
            source_mesh: m.0,
            lod: 0,
            material: info.material.0,
            flags,
            vertex_count: info.vertex_count,
            triangle_count: info.triangle_count,
            element: self.mesh_element(p, j),
            ..empty_mesh_record(&info.bounds)
        }
    }

    fn record_for(&mut self, p: PrototypeId, j: usize, m: MeshId) -> Result<u32, CompileError> {
        let r = self.record_of_mesh[m.index()];
        if r != NONE_U32 {
            return Ok(r);
        }
        let rec = self.source_record(p, j, m);
        let id = next_id(self.out.meshes.len(), "meshes")?;
        self.out.meshes.push(rec);
        self.record_of_mesh[m.index()] = id;
        Ok(id)
    }

    /// The partitioner's bound: triangles per triangle BLAS.
    fn bound(&self) -> u32 {
        self.plan.opts.blas_triangle_bound()
    }

    fn load_source(&mut self, m: MeshId) -> Result<MeshData, CompileError> {
        let t = std::time::Instant::now();
        let data = (self.load)(m).map_err(|source| CompileError::MeshLoad { mesh: m.0, source })?;
        self.out.report.phases.load_ms += t.elapsed().as_secs_f64() * 1e3;
        let info = self.plan.scene.mesh(m);
        if data.triangle_count() != info.triangle_count as usize
            || data.positions.len() != info.vertex_count as usize
        {
            return Err(CompileError::Mesh {
                mesh: m.0,
                reason: format!(
                    "stored data has {} vertices and {} triangles, the scene says {} and {}",
                    data.positions.len(),
                    data.triangle_count(),
                    info.vertex_count,
                    info.triangle_count
                ),
            });
        }
        data.validate()
            .map_err(|reason| CompileError::Mesh { mesh: m.0, reason })?;
        Ok(data)
    }

    /// Compiled mesh records for `data` (source mesh `m` at LOD `lod`, whose record template
    /// is `template`): one record handed to the sink when within the bound, else one per
    /// spatial cluster with its primitive map. `base_map` maps `data`'s triangles to the source
    /// mesh's when they are not the same (baked copies); cluster maps compose with it. Returns
    /// the records `(first, count)`.
    fn made_records(
        &mut self,
        m: MeshId,
        template: &MeshRecord,
        lod: u32,
        data: &MeshData,
        base_map: Option<&[u32]>,
    ) -> Result<(u32, u32), CompileError> {
        let first = next_id(self.out.meshes.len(), "meshes")?;
        let bound = self.bound();
        let mut flags = template.flags & !(FLAG_HAS_NORMALS | FLAG_PRIMITIVE_MAP);
        if data.normals.is_some() {
            flags |= FLAG_HAS_NORMALS;
        }
        let meshes = &mut self.out.meshes;
        let sink = &mut *self.sink;
        let started = std::time::Instant::now();
        let mut sink_ms = 0.0;
        let mut push = |data: &MeshData, map: Option<&[u32]>, bounds: Aabb| {
            let id = next_id(meshes.len(), "meshes")?;
            let map_flag = if map.is_some() { FLAG_PRIMITIVE_MAP } else { 0 };
            meshes.push(MeshRecord {
                source_mesh: m.0,
                lod,
                flags: flags | map_flag,
                vertex_count: data.positions.len() as u32,
                triangle_count: data.triangle_count() as u32,
                bounds_min: bounds.min,
                bounds_max: bounds.max,
                ..*template
            });
            let t = std::time::Instant::now();
            let r = sink(id, data, map).map_err(|source| CompileError::Sink {
                mesh_record: id,
                source,
            });
            sink_ms += t.elapsed().as_secs_f64() * 1e3;
            r
        };
        if data.triangle_count() <= bound as usize {
            push(data, base_map, data.bounds())?;
        } else {
            let _span = tracing::debug_span!(
                "partition",
                mesh = m.0,
                lod,
                triangles = data.triangle_count()
            )
            .entered();
            partition_mesh(data, bound, &mut |c: Cluster| match base_map {
                Some(base) => {
                    let map: Vec<u32> = c.primitive_map.iter().map(|&t| base[t as usize]).collect();
                    push(&c.data, Some(&map), c.bounds)
                }
                None => push(&c.data, Some(&c.primitive_map), c.bounds),
            })?;
            self.out.report.partitioned_meshes += 1;
            self.out.report.partition_clusters +=
                u64::from(next_id(meshes.len(), "meshes")? - first);
        }
        let phases = &mut self.out.report.phases;
        phases.sink_ms += sink_ms;
        if data.triangle_count() > bound as usize {
            phases.partition_ms += started.elapsed().as_secs_f64() * 1e3 - sink_ms;
        }
        let count = next_id(self.out.meshes.len(), "meshes")? - first;
        Ok((first, count))
    }

    /// The records of source mesh `m` (over the bound, LOD 0, not baked) from clusters its
    /// caller cut and stored already ([`crate::StoredClusters`]): the records
    /// [`Self::made_records`] would make, field for field, or `None` if there are none.
    fn stored_records(
        &mut self,
        m: MeshId,
        template: &MeshRecord,
    ) -> Result<Option<(u32, u32)>, CompileError> {
        let first = next_id(self.out.meshes.len(), "meshes")?;
        let bound = self.bound();
        let Some(shapes) = (self.stored)(m, bound, first) else {
            return Ok(None);
        };
        let base = template.flags & !(FLAG_HAS_NORMALS | FLAG_PRIMITIVE_MAP);
        for c in &shapes {
            next_id(self.out.meshes.len(), "meshes")?;
            let normals = if c.has_normals { FLAG_HAS_NORMALS } else { 0 };
            self.out.meshes.push(MeshRecord {
                source_mesh: m.0,
                lod: 0,
                flags: base | normals | FLAG_PRIMITIVE_MAP,
                vertex_count: c.vertex_count,
                triangle_count: c.triangle_count,
                bounds_min: c.bounds.min,
                bounds_max: c.bounds.max,
                ..*template
            });
        }
        let count = next_id(self.out.meshes.len(), "meshes")? - first;
        self.out.report.partitioned_meshes += 1;
        self.out.report.partition_clusters += u64::from(count);
        Ok(Some((first, count)))
    }

    fn material_flags(&self, material: u32) -> u32 {
        match self.plan.scene.materials().get(material as usize) {
            Some(mat) if mat.opacity < 1.0 || mat.alpha_texture.is_some() => FLAG_NEEDS_ANY_HIT,
            _ => 0,
        }
    }

    /// `G(P)`: `P`'s non-LOD meshes as triangle BLASes of at most [`Self::bound`] triangles
    /// (for the root, per element first, so every root placement has one element): a mesh over
    /// the bound is split into clusters (a BLAS each); the others, one geometry each, are
    /// grouped by location under the bound.
    fn g_for_proto(&mut self, p: PrototypeId) -> Result<(u32, u32), CompileError> {
        let g = self.g_of_proto[p.index()];
        if g.1 > 0 {
            return Ok(g);
        }
        let scene = self.plan.scene;
        let bound = self.bound();
        // (element, record, item); few per prototype.
        let mut small: Vec<(u32, u32, Item)> = Vec::new();
        let mut big: Vec<(u32, usize, MeshId)> = Vec::new();
        for (j, &m) in scene.meshes_of(p).iter().enumerate() {
            if !self.plan.mesh_kept(p, j, m) || self.plan.mesh_gets_lod(m) {
                continue;
            }
            let info = scene.mesh(m);
            let element = if p == Scene::ROOT {
                self.mesh_element(p, j)
            } else {
                NONE_U32
            };
            if info.triangle_count > bound {
                big.push((element, j, m));
                continue;
            }
            let record = self.record_for(p, j, m)?;
            let item = Item {
                index: NONE_U32, // set once sorted by element
                centre: info.bounds.center().to_array(),
                triangles: u64::from(info.triangle_count),
            };
            small.push((element, record, item));
        }
        let first = next_id(self.out.blases.len(), "BLASes")?;
        for (element, j, m) in big {
            let template = self.source_record(p, j, m);
            let (r0, n) = match self.stored_records(m, &template)? {
                Some(made) => made,
                None => {
                    let data = self.load_source(m)?;
                    self.made_records(m, &template, 0, &data, None)?
                }
            };
            for r in r0..r0 + n {
                self.triangle_blas(&[r], element)?;
            }
        }
        small.sort_by_key(|it| it.0);
        for (k, it) in small.iter_mut().enumerate() {
            it.2.index = k as u32;
        }
        let records: Vec<u32> = small.iter().map(|it| it.1).collect();
        let mut items: Vec<Item> = Vec::new();
        let mut k = 0;
        while k < small.len() {
            let element = small[k].0;
            let run_end = small[k..]
                .iter()
                .position(|it| it.0 != element)
                .map_or(small.len(), |n| k + n);
            items.clear();
            items.extend(small[k..run_end].iter().map(|it| it.2));
            self.blases_by_location(&mut items, &records, element)?;
            k = run_end;
        }
        let count = next_id(self.out.blases.len(), "BLASes")? - first;
        self.g_of_proto[p.index()] = (first, count);
        Ok((first, count))
    }

    /// A baked prototype `p` (`Plan::bakes`): every kept mesh in its subtree, one copy per
    /// path from `p` transformed into `p`'s space, as mesh records of the source mesh with a
    /// primitive map to its triangles (hits name the source mesh and triangle, as instanced
    /// copies do), grouped by location into triangle BLASes under the bound.
    fn bake_for_proto(&mut self, p: PrototypeId) -> Result<(u32, u32), CompileError> {
        let b = self.bake_of_proto[p.index()];
        if b.1 > 0 {
            return Ok(b);
        }
        let scene = self.plan.scene;
        // Per source mesh (in id order): its owner and index there, and every placement.
        let mut uses: std::collections::BTreeMap<u32, (PrototypeId, usize, Vec<Transform34>)> =
            std::collections::BTreeMap::new();
        let mut stack = vec![(p, Transform34::IDENTITY)];
        while let Some((q, proto_from_q)) = stack.pop() {
            for (j, &m) in scene.meshes_of(q).iter().enumerate() {
                if self.plan.mesh_kept(q, j, m) {
                    uses.entry(m.0)
                        .or_insert_with(|| (q, j, Vec::new()))
                        .2
                        .push(proto_from_q);
                }
            }
            let base = scene.edge_base(q) as usize;
            for (k, e) in scene.edges(q).iter().enumerate() {
                if self.plan.edge_kept(q, base + k, edge_ref!(e)) {
                    stack.push((e.child, xform::compose(&proto_from_q, &e.parent_from_child)));
                }
            }
        }
        let mut records: Vec<(u32, Item)> = Vec::new();
        for (m, (q, j, placements)) in uses {
            let m = MeshId(m);
            let data = self.load_source(m)?;
            let (baked, map) = bake_copies(&data, &placements);
            drop(data);
            let template = self.source_record(q, j, m);
            let (r0, n) = self.made_records(m, &template, 0, &baked, Some(&map))?;
            for r in r0..r0 + n {
                let rec = &self.out.meshes[r as usize];
                let bounds = xform::aabb_from_record(rec.bounds_min, rec.bounds_max);
                records.push((
                    r,
                    Item {
                        index: records.len() as u32,
                        centre: bounds.center().to_array(),
                        triangles: u64::from(rec.triangle_count),
                    },
                ));
            }
        }
        let first = next_id(self.out.blases.len(), "BLASes")?;
        let (ids, mut items): (Vec<u32>, Vec<Item>) = records.into_iter().unzip();
        self.blases_by_location(&mut items, &ids, NONE_U32)?;
        let count = next_id(self.out.blases.len(), "BLASes")? - first;
        self.out.report.baked_prototypes += 1;
        self.bake_of_proto[p.index()] = (first, count);
        Ok((first, count))
    }

    /// Triangle BLASes of `element` over mesh records `records[item.index]` for `items`,
    /// grouped by location under the bound.
    fn blases_by_location(
        &mut self,
        items: &mut [Item],
        records: &[u32],
        element: u32,
    ) -> Result<(), CompileError> {
        let mut ranges: Vec<(usize, usize)> = Vec::new();
        group_by_location(items, u64::from(self.bound()), &mut ranges);
        let mut group: Vec<u32> = Vec::new();
        for &(a, b) in &ranges {
            group.clear();
            group.extend(items[a..b].iter().map(|it| records[it.index as usize]));
            // Mesh order inside a group: as in the scene (stable ids per geometry).
            group.sort_unstable();
            self.triangle_blas(&group, element)?;
        }
        Ok(())
    }

    fn triangle_blas(&mut self, records: &[u32], element: u32) -> Result<u32, CompileError> {
        let id = next_id(self.out.blases.len(), "BLASes")?;
        let item_base = next_id(self.out.geometries.len(), "geometries")?;
        let mut bounds = Aabb::EMPTY;
        let (mut tris, mut flags) = (0u64, 0u32);
        for &r in records {
            next_id(self.out.geometries.len(), "geometries")?;
            self.out.geometries.push(GeometryRecord {
                mesh: r,
                _pad: [0; 3],
            });
            let m = &self.out.meshes[r as usize];
            bounds = bounds.union(&xform::aabb_from_record(m.bounds_min, m.bounds_max));
            tris += u64::from(m.triangle_count);
            flags |= m.flags & FLAG_NEEDS_ANY_HIT;
        }
        let primitive_count = u32::try_from(tris).map_err(|_| CompileError::TooMany {
            what: "triangles in one BLAS",
            count: tris,
        })?;
        let mut rec = BlasRecord {
            kind: BLAS_TRIANGLES,
            item_base,
            item_count: records.len() as u32,
            primitive_count,
            ..Default::default()
        };
        set_bounds(&mut rec.bounds_min, &mut rec.bounds_max, &bounds);
        self.out.blases.push(rec);
        self.blas_flags.push(flags);
        self.blas_element.push(element);
        Ok(id)
    }

    /// One AABB BLAS over `pis[begin..end]`, instanced with identity by the TLAS being emitted;
    /// several (median-split by AABB centre) when over the primitive cap, and in the root TLAS
    /// one group per element.
    fn aabb_blases(&mut self, begin: usize, end: usize) -> Result<(), CompileError> {
        let cap = self.plan.opts.max_primitives_per_blas as usize;
        // Runs of one element: (begin, end, element).
        let mut runs: Vec<(usize, usize, u32)> = Vec::new();
        if self.in_root && self.pi_elements.len() == end - begin {
            let mut tagged: Vec<(u32, PiRecord)> = self
                .pi_elements
                .iter()
                .copied()
                .zip(self.out.pis[begin..end].iter().copied())
                .collect();
            tagged.sort_by_key(|t| t.0);
            for (k, (element, pi)) in tagged.iter().enumerate() {
                self.out.pis[begin + k] = *pi;
                match runs.last_mut() {
                    Some(run) if run.2 == *element => run.1 += 1,
                    _ => runs.push((begin + k, begin + k + 1, *element)),
                }
            }
        } else {
            runs.push((begin, end, NONE_U32));
        }
        let mut ranges = Vec::new();
        for (a, b, element) in runs {
            ranges.clear();
            if b - a > cap {
                self.out.report.split_aabb_blases += 1;
                median_partition(&mut self.out.pis[a..b], pi_centre, cap, &mut ranges);
            } else {
                ranges.push((0, b - a));
            }
            for &(x, y) in &ranges {
                let blas = self.aabb_blas(a + x, a + y)?;
                self.push_instance(blas, &Transform34::IDENTITY, element)?;
            }
        }
        Ok(())
    }

    fn aabb_blas(&mut self, begin: usize, end: usize) -> Result<u32, CompileError> {
        let id = tlas_split::push_aabb_blas(&mut self.out, begin, end)?;
        self.blas_flags.push(0);
        self.blas_element.push(NONE_U32);
        Ok(id)
    }

    /// Splits `tlas` until its instance count fits the cap ([`tlas_split::split_tlas`]).
    fn split_tlas(&mut self, tlas: u32) -> Result<(), CompileError> {
        let per_blas = self.plan.opts.max_primitives_per_blas as usize;
        let (flags, elements) = (&mut self.blas_flags, &mut self.blas_element);
        tlas_split::split_tlas(
            &mut self.out,
            tlas,
            self.instance_cap,
            per_blas,
            self.in_root,
            &mut |element| {
                flags.push(0);
                elements.push(element);
            },
        )
    }

    /// The LOD selector of mesh `m` (its chain is built, and handed to the sink, on first use).
    /// Every level over the bound is partitioned like any mesh: its TLAS instances one BLAS per
    /// cluster.
    fn selector_for(&mut self, p: PrototypeId, j: usize, m: MeshId) -> Result<u32, CompileError> {
        let s = self.selector_of_mesh[m.index()];
        if s != NONE_U32 {
            return Ok(s);
        }
        let levels = self.plan.opts.lod_levels.unwrap_or(1);
        let template = self.source_record(p, j, m);
        let data = self.load_source(m)?;
        let mut level_records = Vec::new();
        if data.triangle_count() > self.bound() as usize {
            level_records.push(self.made_records(m, &template, 0, &data, None)?);
        } else {
            level_records.push((self.record_for(p, j, m)?, 1));
        }
        {
            let mut emit = |lod, level: &MeshData| -> Result<(), CompileError> {
                let made = self.made_records(m, &template, lod, level, None)?;
                self.out.report.lod_meshes_made += 1;
                level_records.push(made);
                Ok(())
            };
            lod::build_chain(m, data, levels, &mut emit)?;
        }
        self.out.report.lod_source_meshes += 1;
        let id = next_id(self.out.lod_selectors.len(), "LOD selectors")?;
        let level_base = next_id(self.out.lod_levels.len(), "LOD levels")?;
        let element = template.element;
        for &(first, count) in &level_records {
            let t = self.new_tlas(Job::Lod(first, count), element)?;
            self.out.lod_levels.push(t);
        }
        let b = xform::aabb_from_record(template.bounds_min, template.bounds_max);
        self.out.lod_selectors.push(LodSelectorRecord {
            center: b.center().to_array(),
            radius: b.extent().length() * 0.5,
            level_base,
            level_count: level_records.len() as u32,
            source_mesh: m.0,
            _pad: 0,
        });
        self.selector_of_mesh[m.index()] = id;
        Ok(id)
    }
}

pub(crate) fn empty_mesh_record(bounds: &Aabb) -> MeshRecord {
    MeshRecord {
        chunk: NONE_U32,
        positions_offset: NONE_U64,
        indices_offset: NONE_U64,
        normals_offset: NONE_U64,
        primitive_map_offset: NONE_U64,
        bounds_min: bounds.min,
        bounds_max: bounds.max,
        ..Default::default()
    }
}

fn pi_centre(pi: &PiRecord) -> [f32; 3] {
    std::array::from_fn(|i| 0.5 * (pi.aabb_min[i] + pi.aabb_max[i]))
}

/// The root TLAS's element: the one element all kept root content comes from, else none.
fn root_element(plan: &Plan<'_>) -> u32 {
    let scene = plan.scene;
    let root = Scene::ROOT;
    let base = scene.edge_base(root) as usize;
    let mut found: Option<u32> = None;
    let mut mixed = false;
    let mut see = |e: u32| match found {
        None => found = Some(e),
        Some(f) if f != e => mixed = true,
        _ => {}
    };
    for (i, e) in scene.edges(root).iter().enumerate() {
        if plan.edge_kept(root, base + i, edge_ref!(e)) {
            if let Some(el) = scene.root_edge_elements().get(i) {
                see(el.0);
            }
        }
    }
    for (j, &m) in scene.meshes_of(root).iter().enumerate() {
        if plan.mesh_kept(root, j, m) {
            if let Some(el) = scene.root_mesh_elements().get(j) {
                see(el.0);
            }
        }
    }
    match (found, mixed) {
        (Some(e), false) => e,
        _ => NONE_U32,
    }
}

/// `data` copied once per placement (`proto_from_mesh`), positions and normals transformed (a
/// mirroring placement flips the winding back), with each copy's triangle-to-source map.
fn bake_copies(data: &MeshData, placements: &[Transform34]) -> (MeshData, Vec<u32>) {
    let (nv, nt) = (data.positions.len(), data.triangle_count());
    let copies = placements.len();
    let mut out = MeshData {
        positions: Vec::with_capacity(nv * copies),
        normals: data
            .normals
            .as_ref()
            .map(|_| Vec::with_capacity(nv * copies)),
        uvs: data.uvs.as_ref().map(|_| Vec::with_capacity(nv * copies)),
        indices: Vec::with_capacity(3 * nt * copies),
    };
    let mut map = Vec::with_capacity(nt * copies);
    for xf in placements {
        let m = xf.to_mat4();
        let linear = glam::Mat3::from_mat4(m);
        // Normals by the cofactor matrix (the inverse transpose up to det, defined even when
        // the placement is singular), its sign kept so they still point outward.
        let det = linear.determinant();
        let cofactor = glam::Mat3::from_cols(
            linear.y_axis.cross(linear.z_axis),
            linear.z_axis.cross(linear.x_axis),
            linear.x_axis.cross(linear.y_axis),
        );
        let sign = if det < 0.0 { -1.0 } else { 1.0 };
        let base = out.positions.len() as u32;
        out.positions.extend(
            data.positions
                .iter()
                .map(|&p| m.transform_point3(glam::Vec3::from(p)).to_array()),
        );
        if let (Some(on), Some(n)) = (out.normals.as_mut(), data.normals.as_ref()) {
            on.extend(n.iter().map(|&v| {
                (sign * (cofactor * glam::Vec3::from(v)))
                    .normalize_or_zero()
                    .to_array()
            }));
        }
        if let (Some(ou), Some(u)) = (out.uvs.as_mut(), data.uvs.as_ref()) {
            ou.extend_from_slice(u);
        }
        for t in data.indices.chunks_exact(3) {
            let (a, b, c) = (t[0] + base, t[1] + base, t[2] + base);
            if det < 0.0 {
                out.indices.extend_from_slice(&[a, c, b]);
            } else {
                out.indices.extend_from_slice(&[a, b, c]);
            }
        }
        map.extend(0..nt as u32);
    }
    (out, map)
}

#[cfg(test)]
mod tests;
