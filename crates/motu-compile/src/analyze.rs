//! Per-prototype analysis before emission, O(prototypes + edges) with per-prototype arrays
//! only: which edges are kept (subset, degenerate transforms, pruned subtrees), which edges are
//! expanded into their parent's TLAS, and the instance totals (checked against `u32` and used
//! to reserve the instance table once).

use crate::{xform, CompileError, CompileOptions, Levels};
use motu_scene::{MeshId, PrototypeId, Scene, Transform34};

/// The parts of a scene edge the rules look at.
#[derive(Clone, Copy)]
pub(crate) struct EdgeRef<'a> {
    pub child: PrototypeId,
    pub parent_from_child: &'a Transform34,
}

/// Views `scene.edges(p)[i]` (the scene's edge type is not exported).
macro_rules! edge_ref {
    ($e:expr) => {
        $crate::analyze::EdgeRef {
            child: $e.child,
            parent_from_child: &$e.parent_from_child,
        }
    };
}
pub(crate) use edge_ref;

pub(crate) struct Plan<'s> {
    pub scene: &'s Scene,
    pub opts: &'s CompileOptions,
    /// Per element: kept by the subset (`None`: all).
    element_kept: Option<Vec<bool>>,
    /// Reachable from the root through kept edges and carrying geometry below.
    pub reachable: Vec<bool>,
    has_geometry: Vec<bool>,
    /// Kept incoming edges (saturating).
    indeg: Vec<u32>,
    /// Has kept geometry and no kept child edges.
    plain: Vec<bool>,
    /// TLAS levels of `TLAS(P)`'s subtree under the ML rules.
    tlas_height: Vec<u32>,
    /// [`Levels::Auto`]: the prototype is a cheap grouping level, inlined into its parents.
    auto_inline: Vec<bool>,
    /// [`Levels::Auto`]: the prototype is baked (its meshes' copies become triangle BLASes,
    /// instanced where it is placed) and its triangles, copies included (saturating).
    bake: Vec<bool>,
    bake_triangles: Vec<u64>,
    /// Kept meshes of a prototype that get a LOD chain / that go into `G(P)`.
    pub lod_mesh_count: Vec<u32>,
    pub g_mesh_count: Vec<u32>,
    pub dropped_degenerate: u64,
    pub collapsed_prototypes: u64,
    /// [`Levels::Auto`]: reachable prototypes inlined by its rules.
    pub auto_inlined_prototypes: u64,
    pub flattened_instances: u64,
    /// Instance-table size estimate (exact unless composed transforms degenerate or location
    /// grouping makes more groups than the triangle total needs).
    pub instance_estimate: u64,
}

impl<'s> Plan<'s> {
    pub fn new(scene: &'s Scene, opts: &'s CompileOptions) -> Result<Self, CompileError> {
        let _span = tracing::info_span!("analyze").entered();
        let n = scene.prototypes().len();
        let element_kept = opts.subset.as_ref().map(|subset| {
            let mut kept = vec![false; scene.elements().len()];
            for e in subset {
                if let Some(k) = kept.get_mut(e.index()) {
                    *k = true;
                }
            }
            kept
        });
        let mut plan = Plan {
            scene,
            opts,
            element_kept,
            reachable: vec![false; n],
            has_geometry: vec![false; n],
            indeg: vec![0; n],
            plain: vec![false; n],
            tlas_height: vec![0; n],
            auto_inline: vec![false; n],
            bake: vec![false; n],
            bake_triangles: vec![0; n],
            lod_mesh_count: vec![0; n],
            g_mesh_count: vec![0; n],
            dropped_degenerate: 0,
            collapsed_prototypes: 0,
            auto_inlined_prototypes: 0,
            flattened_instances: 0,
            instance_estimate: 0,
        };

        // Bottom-up: own meshes, geometry below, plain-ness.
        for &p in scene.topo_order() {
            let (mut lod, mut g) = (0u32, 0u32);
            for (j, &m) in scene.meshes_of(p).iter().enumerate() {
                if plan.mesh_kept(p, j, m) {
                    if plan.mesh_gets_lod(m) {
                        lod += 1;
                    } else {
                        g += 1;
                    }
                }
            }
            plan.lod_mesh_count[p.index()] = lod;
            plan.g_mesh_count[p.index()] = g;
            let base = scene.edge_base(p) as usize;
            let mut child_geometry = false;
            for (i, e) in scene.walk_edges(p).enumerate() {
                child_geometry |= plan.edge_kept(p, base + i, edge_ref!(e));
            }
            plan.has_geometry[p.index()] = lod + g > 0 || child_geometry;
            plan.plain[p.index()] = lod + g > 0 && !child_geometry;
        }

        // Top-down: reachability, in-degrees, path counts, dropped degenerate edges.
        let mut paths = vec![0u64; n];
        plan.reachable[Scene::ROOT.index()] = true;
        paths[Scene::ROOT.index()] = 1;
        for &p in scene.topo_order().iter().rev() {
            if !plan.reachable[p.index()] {
                continue;
            }
            let base = scene.edge_base(p) as usize;
            for (i, e) in scene.walk_edges(p).enumerate() {
                let c = e.child.index();
                if !plan.element_ok(p, base + i) || !plan.has_geometry[c] {
                    continue;
                }
                if !xform::is_invertible(&e.parent_from_child) {
                    plan.dropped_degenerate += 1;
                    continue;
                }
                plan.reachable[c] = true;
                plan.indeg[c] = plan.indeg[c].saturating_add(1);
                paths[c] = paths[c].saturating_add(paths[p.index()]);
            }
        }
        if plan.dropped_degenerate > 0 {
            tracing::warn!(
                count = plan.dropped_degenerate,
                "dropped instances with non-invertible transforms"
            );
        }
        plan.flattened_instances = scene
            .prototype_ids()
            .filter(|&p| p != Scene::ROOT && plan.reachable[p.index()] && plan.has_own_meshes(p))
            .fold(0u64, |acc, p| acc.saturating_add(paths[p.index()]));

        // Bottom-up: ML TLAS heights (for Levels::N).
        for &p in scene.topo_order() {
            if !plan.reachable[p.index()] {
                continue;
            }
            let base = scene.edge_base(p) as usize;
            let mut below = 0u32;
            for (i, e) in scene.walk_edges(p).enumerate() {
                if !plan.edge_kept(p, base + i, edge_ref!(e)) {
                    continue;
                }
                let h = plan.tlas_height[e.child.index()];
                below = below.max(if plan.expands_ml(edge_ref!(e)) {
                    h.saturating_sub(1)
                } else {
                    h
                });
            }
            plan.tlas_height[p.index()] = below + 1;
        }
        if plan.opts.levels == Levels::Auto {
            plan.plan_auto_inlining();
        }
        plan.estimate_instances()?;
        // The passes above read every edge: file-held edges (an import's) leave the resident
        // set until the emitter walks them.
        crate::release_edge_pages(scene);
        Ok(plan)
    }

    fn element_ok(&self, parent: PrototypeId, edge_index: usize) -> bool {
        match &self.element_kept {
            Some(kept) if parent == Scene::ROOT => {
                let local = edge_index - self.scene.edge_base(Scene::ROOT) as usize;
                self.scene
                    .root_edge_elements()
                    .get(local)
                    .and_then(|e| kept.get(e.index()))
                    .copied()
                    .unwrap_or(false)
            }
            _ => true,
        }
    }

    /// Mesh `j` of `p` is compiled.
    pub fn mesh_kept(&self, p: PrototypeId, j: usize, m: MeshId) -> bool {
        if self.scene.mesh(m).triangle_count == 0 {
            return false;
        }
        match &self.element_kept {
            Some(kept) if p == Scene::ROOT => self
                .scene
                .root_mesh_elements()
                .get(j)
                .and_then(|e| kept.get(e.index()))
                .copied()
                .unwrap_or(false),
            _ => true,
        }
    }

    pub fn mesh_gets_lod(&self, m: MeshId) -> bool {
        self.opts.lod_levels.is_some_and(|n| n >= 2)
            && self.scene.mesh(m).triangle_count > self.opts.lod_triangle_threshold
    }

    pub fn has_own_meshes(&self, p: PrototypeId) -> bool {
        self.lod_mesh_count[p.index()] + self.g_mesh_count[p.index()] > 0
    }

    /// Edge `edge_index` (global) of `parent` survives subset, pruning and degeneracy.
    #[inline]
    pub fn edge_kept(&self, parent: PrototypeId, edge_index: usize, e: EdgeRef<'_>) -> bool {
        self.has_geometry[e.child.index()]
            && self.element_ok(parent, edge_index)
            && xform::is_invertible(e.parent_from_child)
    }

    fn expands_ml(&self, e: EdgeRef<'_>) -> bool {
        let c = e.child.index();
        self.plain[c]
            || (self.indeg[c] == 1
                && e.parent_from_child
                    .is_identity(self.opts.identity_tolerance))
    }

    /// A kept edge's child is baked: its triangle BLASes are instanced in the parent's TLAS
    /// (neither inlined nor a PI).
    #[inline]
    pub fn bakes(&self, child: PrototypeId) -> bool {
        self.bake[child.index()]
    }

    /// BLASes a baked prototype makes (an estimate: location grouping may make a few more).
    fn bake_blas_estimate(&self, p: PrototypeId) -> u64 {
        let bound = self.opts.blas_triangle_bound();
        self.bake_triangles[p.index()]
            .div_ceil(u64::from(bound))
            .max(1)
    }

    /// A kept edge is inlined into its parent's TLAS (otherwise it becomes a PI or, baked,
    /// instances of its BLASes).
    #[inline]
    pub fn expands(&self, e: EdgeRef<'_>) -> bool {
        match self.opts.levels {
            Levels::Sl => true,
            Levels::Ml => self.expands_ml(e),
            Levels::Auto => self.expands_ml(e) || self.auto_inline[e.child.index()],
            Levels::N(n) => {
                self.expands_ml(e) || self.tlas_height[e.child.index()] > n.saturating_sub(1)
            }
        }
    }

    /// Bottom-up: the entries TLAS(p) would hold under `Auto` (own meshes' BLAS, expanded
    /// children's entries, a baked child's BLASes, one PI per other child) decide whether a
    /// mesh-less `p` is inlined as a grouping level; a prototype that is not, but would be a
    /// TLAS of instances, with no LOD below it and at most `auto_bake_max_triangles` triangles
    /// in all, is baked: no traversal-shader hop reaches it, for a few MB of geometry
    /// (instancing saves memory where prototypes are big, not in a tree of small leaves); what
    /// is left is inlined when its entries times its uses are at most
    /// `auto_inline_max_instances`, so only levels whose sharing saves memory stay hops.
    fn plan_auto_inlining(&mut self) {
        let scene = self.scene;
        let mut entries = vec![0u64; scene.prototypes().len()];
        // Triangles of p's content with its copies, or None when a LOD mesh is below p.
        let mut content: Vec<Option<u64>> = vec![None; scene.prototypes().len()];
        for &p in scene.topo_order() {
            if !self.reachable[p.index()] {
                continue;
            }
            let mut count = u64::from(self.g_mesh_count[p.index()] > 0)
                + u64::from(self.lod_mesh_count[p.index()]);
            let mut tris = (self.lod_mesh_count[p.index()] == 0).then(|| {
                scene
                    .meshes_of(p)
                    .iter()
                    .enumerate()
                    .filter(|&(j, &m)| self.mesh_kept(p, j, m))
                    .map(|(_, &m)| u64::from(scene.mesh(m).triangle_count))
                    .fold(0u64, u64::saturating_add)
            });
            let mut kept_edges = 0u64;
            let base = scene.edge_base(p) as usize;
            for (k, e) in scene.walk_edges(p).enumerate() {
                if !self.edge_kept(p, base + k, edge_ref!(e)) {
                    continue;
                }
                let c = e.child;
                kept_edges += 1;
                tris = tris
                    .zip(content[c.index()])
                    .map(|(a, b)| a.saturating_add(b));
                count = count.saturating_add(if self.bakes(c) {
                    self.bake_blas_estimate(c)
                } else if self.expands(edge_ref!(e)) {
                    entries[c.index()]
                } else {
                    1
                });
            }
            entries[p.index()] = count;
            content[p.index()] = tris;
            let not_root = p != Scene::ROOT;
            // A mesh-less grouping level of a few entries is inlined whatever its uses (the
            // thesis forest's groups: a hop saves no memory worth a trace).
            let grouping =
                not_root && !self.has_own_meshes(p) && count <= self.opts.auto_inline_max_entries;
            if let Some(t) = tris {
                self.bake_triangles[p.index()] = t;
                self.bake[p.index()] = not_root
                    && !grouping
                    && kept_edges > 0
                    && t <= self.opts.auto_bake_max_triangles;
            }
            // What would still be a hop is inlined when that is cheap: its `count` entries go
            // into its parents' TLASes once per use (a sphereflake's flake3: 820 × 9).
            let cheap = count.saturating_mul(u64::from(self.indeg[p.index()]))
                <= self.opts.auto_inline_max_instances;
            self.auto_inline[p.index()] =
                grouping || (not_root && !self.bake[p.index()] && kept_edges > 0 && cheap);
            self.auto_inlined_prototypes += u64::from(self.auto_inline[p.index()]);
        }
    }

    /// Triangle BLASes `G(p)` will have (an estimate for reserving the instance table): a
    /// cluster count per mesh over the bound, the small meshes' triangles over the bound.
    fn g_blas_estimate(&self, p: PrototypeId) -> u64 {
        if self.g_mesh_count[p.index()] == 0 {
            return 0;
        }
        let bound = self.opts.blas_triangle_bound();
        let (mut blases, mut small) = (0u64, 0u64);
        for (j, &m) in self.scene.meshes_of(p).iter().enumerate() {
            if !self.mesh_kept(p, j, m) || self.mesh_gets_lod(m) {
                continue;
            }
            let t = self.scene.mesh(m).triangle_count;
            if t > bound {
                blases += crate::partition::cluster_count(u64::from(t), bound);
            } else {
                small += u64::from(t);
            }
        }
        blases + small.div_ceil(u64::from(bound)).max(u64::from(small > 0))
    }

    /// Counts the instances and PIs each TLAS's walk will make; errors early when the tables
    /// would overflow `u32` (e.g. `--levels sl` on a scene with billions of leaf instances).
    fn estimate_instances(&mut self) -> Result<(), CompileError> {
        let scene = self.scene;
        let n = scene.prototypes().len();
        // Per prototype, when expanded: instances and PIs its walk makes.
        let mut inst = vec![0u64; n];
        let mut pis = vec![0u64; n];
        let mut is_tlas = vec![false; n];
        is_tlas[Scene::ROOT.index()] = true;
        let mut collapsed = 0u64;
        for &p in scene.topo_order() {
            if !self.reachable[p.index()] {
                continue;
            }
            let mut i = self.g_blas_estimate(p);
            let mut q = u64::from(self.lod_mesh_count[p.index()]);
            let base = scene.edge_base(p) as usize;
            for (k, e) in scene.walk_edges(p).enumerate() {
                if !self.edge_kept(p, base + k, edge_ref!(e)) {
                    continue;
                }
                let c = e.child.index();
                if self.bakes(e.child) {
                    i = i.saturating_add(self.bake_blas_estimate(e.child));
                } else if self.expands(edge_ref!(e)) {
                    i = i.saturating_add(inst[c]);
                    q = q.saturating_add(pis[c]);
                    if !self.plain[c] && self.expands_ml(edge_ref!(e)) {
                        collapsed += 1;
                    }
                } else {
                    q = q.saturating_add(1);
                    is_tlas[c] = true;
                }
            }
            inst[p.index()] = i;
            pis[p.index()] = q;
        }
        self.collapsed_prototypes = collapsed;
        let per_blas = u64::from(self.opts.max_primitives_per_blas.max(1));
        let (mut total_inst, mut total_pis) = (0u64, 0u64);
        for p in 0..n {
            if is_tlas[p] && self.reachable[p] {
                total_inst = total_inst
                    .saturating_add(inst[p])
                    .saturating_add(pis[p].div_ceil(per_blas));
                total_pis = total_pis.saturating_add(pis[p]);
            }
        }
        if total_inst > u64::from(u32::MAX) {
            return Err(CompileError::TooMany {
                what: "instances",
                count: total_inst,
            });
        }
        if total_pis > u64::from(u32::MAX) {
            return Err(CompileError::TooMany {
                what: "programmable instances",
                count: total_pis,
            });
        }
        self.instance_estimate = total_inst;
        tracing::debug!(instances = total_inst, pis = total_pis, "estimated tables");
        Ok(())
    }
}
