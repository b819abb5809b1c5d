//! Emission: one walk per TLAS, depth-first from the root, writing straight into the output
//! tables (the instance table is the only large allocation; the walk itself keeps one frame per
//! graph level). Levels and exact bounds are filled in by `finalize`.

use crate::analyze::{edge_ref, Plan};
use crate::tables::next_id;
use crate::{lod, xform, CompileError, CompiledScene, MeshLoader, MeshSink, StoredClusters};
use motu_abi::{
    InstanceRecord, LodSelectorRecord, MaterialRecord, MeshRecord, PiRecord, TlasRecord, NONE_U32,
    NONE_U64, PI_LOD_SELECTOR, PI_TLAS,
};
use motu_scene::{Aabb, MeshData, MeshId, PrototypeId, Scene, Transform34};

mod blas;
mod records;

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
    /// Edges walked so far: every [`RELEASE_EVERY_EDGES`], file-held edges already read
    /// leave the resident set (the instance table grows meanwhile).
    walked_edges: u64,
}

/// How many walked edges between releases of file-held edge pages (3.4 MB of edges).
const RELEASE_EVERY_EDGES: u64 = 1 << 16;

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
            walked_edges: 0,
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
        // With a scratch directory (an import's), a table of at least `PARK_MIN_INSTANCES`
        // is an unnamed file mapped shared, its pages released as it is written and read:
        // on the heap it is the compile's peak (64 bytes an instance; issue 48 item 1).
        if let Some(dir) = &self.plan.opts.split_scratch_dir {
            if reserve >= crate::PARK_MIN_INSTANCES {
                self.out.instances = crate::InstanceTable::in_file(dir)?;
            }
        }
        self.out.instances.try_reserve_exact(reserve)?;
        let root = self.tlas_for_proto(Scene::ROOT)?;
        self.out.root_tlas = root;
        let mut jobs = std::mem::take(&mut self.new_children);
        while let Some((tlas, job)) = jobs.pop() {
            self.emit_tlas(tlas, job)?;
            // Children got consecutive ids; push reversed so the first is emitted next.
            jobs.extend(self.new_children.drain(..).rev());
        }
        crate::release_edge_pages(self.plan.scene);
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
        })
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
            self.walked_edges += 1;
            if self.walked_edges % RELEASE_EVERY_EDGES == 0 {
                crate::release_edge_pages(scene);
            }
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
    for (i, e) in scene.walk_edges(root).enumerate() {
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

#[cfg(test)]
mod tests;
