//! The cost model over a compiled hierarchy: what every TLAS, BLAS, mesh and table costs, who
//! owns it (one element, or several: shared), and what flattened variants would cost.
//!
//! The graph's edges are the package's BLAS counts (`motu_compile::blas_counts`: per TLAS,
//! the BLASes its instances place, each once with its count), so every walk below is
//! proportional to the distinct placements, not to the instances. Ownership: see `owner`.
//!
//! Variants: `--levels N` keeps a child TLAS (and its whole subtree, unchanged) when its
//! subtree needs at most `N − 1` TLAS levels and expands it into the root otherwise — the
//! compiler's rule, applied to the compiled graph. `sl` is `N = 1`: every triangle-BLAS
//! placement lands in one top TLAS (split into pieces of `maxInstanceCount`). LOD selectors
//! expand into their finest level.

use motu_abi::{
    BlasRecord, GeometryRecord, HierarchyView, InstanceRecord, LodSelectorRecord, MaterialRecord,
    MeshRecord, PiRecord, TlasRecord, BLAS_AABBS, BLAS_TRIANGLES, FLAG_NEEDS_ANY_HIT,
    FLAG_PRIMITIVE_MAP, NONE_U64, PI_LOD_SELECTOR, PI_TLAS,
};
use motu_compile::blas_counts::BlasCounts;
use serde::Serialize;

use crate::sizes::{
    AsSizes, BlasShape, SizeSource, TriangleGeometry, AABB_RECORD_SIZE_BYTES, AS_ALIGNMENT_BYTES,
    INSTANCE_RECORD_SIZE_BYTES,
};
use crate::ReportError;

/// Bytes one part of a scene costs on the GPU. Sums add; peaks take the maximum.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct Cost {
    /// Vertex buffers (positions, and normals where stored), index buffers (`u32`) and AABB
    /// build inputs (24 B per box).
    pub geometry_bytes: u64,
    /// BLASes as built (each rounded up to the 256-byte AS alignment).
    pub blas_bytes: u64,
    /// BLASes after compaction.
    pub blas_compacted_bytes: u64,
    /// TLAS acceleration structures (aligned).
    pub tlas_bytes: u64,
    /// TLAS build inputs: 64 B per instance (`VkAccelerationStructureInstanceKHR`).
    pub instance_buffer_bytes: u64,
    /// motu's record tables the traversal shader reads (TLAS, instance, BLAS, geometry, PI,
    /// LOD, mesh and material records).
    pub table_bytes: u64,
    /// Textures for shading: texture records, every mip chain's texels and every Ptex
    /// texture's faces and tables.
    pub texture_bytes: u64,
    /// The Ptex part of `texture_bytes`: Ptex textures' texels and face tables (counted there
    /// too, not again in the totals).
    pub ptex_bytes: u64,
    /// The largest build scratch of any one structure.
    pub build_scratch_peak_bytes: u64,
    /// The most one build adds on top of the resident bytes: a BLAS's uncompacted size plus
    /// its scratch, or a TLAS's scratch (builds one at a time).
    pub build_transient_peak_bytes: u64,
    /// What rendering needs besides the structures (a full build at the report's image
    /// size): frame buffers, the staging ring and partly used allocator blocks under a budget
    /// of `peak_bytes` (`motu_gpu::full_build_overhead`, the renderer's own policy). Set on
    /// what renders on its own (variants, an element alone, a subset); 0 on per-element rows,
    /// which are parts of a render.
    pub render_overhead_bytes: u64,
    /// What stays on the GPU: geometry + compacted BLASes + TLASes + instance buffers + tables.
    pub resident_bytes: u64,
    /// `resident_bytes + build_transient_peak_bytes + render_overhead_bytes`: the least
    /// `--vram-budget` under which the full build builds and renders.
    pub peak_bytes: u64,
    pub tlas_count: u64,
    pub blas_count: u64,
    /// Instance records over all TLASes.
    pub instances: u64,
    /// Triangles in triangle BLASes (each BLAS once).
    pub blas_triangles: u64,
}

impl Cost {
    pub fn add(&mut self, o: &Cost) {
        self.add_times(o, 1);
    }

    /// Adds `times` copies of `o` (saturating: flattened exponential instancing reaches 2^64).
    pub(crate) fn add_times(&mut self, o: &Cost, times: u64) {
        let add = |a: &mut u64, b: u64| *a = a.saturating_add(b.saturating_mul(times));
        add(&mut self.geometry_bytes, o.geometry_bytes);
        add(&mut self.blas_bytes, o.blas_bytes);
        add(&mut self.blas_compacted_bytes, o.blas_compacted_bytes);
        add(&mut self.tlas_bytes, o.tlas_bytes);
        add(&mut self.instance_buffer_bytes, o.instance_buffer_bytes);
        add(&mut self.table_bytes, o.table_bytes);
        add(&mut self.texture_bytes, o.texture_bytes);
        add(&mut self.ptex_bytes, o.ptex_bytes);
        self.build_scratch_peak_bytes = self
            .build_scratch_peak_bytes
            .max(o.build_scratch_peak_bytes);
        self.build_transient_peak_bytes = self
            .build_transient_peak_bytes
            .max(o.build_transient_peak_bytes);
        // One render's overhead, not one per part.
        self.render_overhead_bytes = self.render_overhead_bytes.max(o.render_overhead_bytes);
        add(&mut self.tlas_count, o.tlas_count);
        add(&mut self.blas_count, o.blas_count);
        add(&mut self.instances, o.instances);
        add(&mut self.blas_triangles, o.blas_triangles);
        self.seal();
    }

    pub fn sum<'a>(parts: impl IntoIterator<Item = &'a Cost>) -> Cost {
        let mut c = Cost::default();
        for p in parts {
            c.add(p);
        }
        c
    }

    /// Recomputes the derived totals.
    pub(crate) fn seal(&mut self) {
        self.resident_bytes = [
            self.blas_compacted_bytes,
            self.tlas_bytes,
            self.instance_buffer_bytes,
            self.table_bytes,
            self.texture_bytes,
        ]
        .iter()
        .fold(self.geometry_bytes, |a, &b| a.saturating_add(b));
        self.peak_bytes = self
            .resident_bytes
            .saturating_add(self.build_transient_peak_bytes)
            .saturating_add(self.render_overhead_bytes);
    }

    /// This cost rendered on its own at `width × height`: with the full build's overhead.
    pub fn rendered_at(mut self, (width, height): (u32, u32)) -> Cost {
        self.render_overhead_bytes = 0;
        self.seal();
        // Past an exbibyte the overhead is moot (flattened exponential instancing saturates
        // at 2^64): clamped so the budget fixed point stays in range.
        self.render_overhead_bytes =
            motu_gpu::full_build_overhead(self.peak_bytes.min(1 << 60), width, height).total_bytes;
        self.seal();
        self
    }

    /// TLAS bytes including the instance buffer (the report's "TLAS" column).
    pub fn tlas_total_bytes(&self) -> u64 {
        self.tlas_bytes.saturating_add(self.instance_buffer_bytes)
    }
}

pub(crate) fn align_as(bytes: u64) -> u64 {
    bytes.div_ceil(AS_ALIGNMENT_BYTES) * AS_ALIGNMENT_BYTES
}

const fn rec<T>() -> u64 {
    std::mem::size_of::<T>() as u64
}

/// A node of the compiled graph.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub(crate) enum Node {
    Tlas(u32),
    Blas(u32),
    Mesh(u32),
    Lod(u32),
}

/// A TLAS of `instance_count` instances on the target device, split into pieces of at most
/// `maxInstanceCount` (plus the AABB BLAS and 1-instance TLAS that join them) when needed.
pub(crate) fn tlas_cost(
    sizes: &dyn SizeSource,
    instance_count: u64,
) -> Result<(Cost, u64), ReportError> {
    let max = sizes.max_instance_count().max(1);
    let pieces = instance_count.div_ceil(max).max(1);
    let mut c = Cost {
        // Saturating: exponential instancing flattens to counts near 2^64.
        instance_buffer_bytes: instance_count.saturating_mul(INSTANCE_RECORD_SIZE_BYTES),
        instances: instance_count,
        ..Default::default()
    };
    let add_tlas = |c: &mut Cost, n: u64| -> Result<(), ReportError> {
        let s = sizes.tlas_sizes(n)?;
        c.tlas_bytes = c.tlas_bytes.saturating_add(align_as(s.size_bytes));
        c.tlas_count = c.tlas_count.saturating_add(1);
        c.build_scratch_peak_bytes = c.build_scratch_peak_bytes.max(s.build_scratch_bytes);
        c.build_transient_peak_bytes = c.build_transient_peak_bytes.max(s.build_scratch_bytes);
        Ok(())
    };
    if pieces == 1 {
        add_tlas(&mut c, instance_count)?;
    } else {
        let full = pieces - 1;
        let last = instance_count - full * max;
        // Every full piece has the same size: query once.
        let mut one = Cost::default();
        add_tlas(&mut one, max)?;
        c.tlas_bytes = c
            .tlas_bytes
            .saturating_add(one.tlas_bytes.saturating_mul(full));
        c.tlas_count = c.tlas_count.saturating_add(full);
        c.build_scratch_peak_bytes = one.build_scratch_peak_bytes;
        c.build_transient_peak_bytes = one.build_transient_peak_bytes;
        add_tlas(&mut c, last)?;
        // The pieces are joined by AABB BLASes of one box each (as many as maxPrimitiveCount
        // allows per BLAS: a flattened exponential scene has more pieces than one BLAS may
        // hold, which asked the device for a 2^32 − 1 box BLAS) under one TLAS.
        let max_boxes = sizes.max_primitive_count().clamp(1, u64::from(u32::MAX));
        let joins = pieces.div_ceil(max_boxes);
        let last_boxes = pieces - (joins - 1) * max_boxes;
        for (boxes, times) in [(max_boxes, joins - 1), (last_boxes, 1)] {
            if times == 0 {
                continue;
            }
            let shape = BlasShape::Aabbs {
                box_count: u32::try_from(boxes).unwrap_or(u32::MAX),
            };
            let one = blas_cost_of(sizes, &shape, 0)?;
            c.add_times(&one, times);
        }
        add_tlas(&mut c, joins)?;
        c.instance_buffer_bytes = c
            .instance_buffer_bytes
            .saturating_add(joins.saturating_mul(INSTANCE_RECORD_SIZE_BYTES));
        c.instances = c.instances.saturating_add(joins);
    }
    c.seal();
    Ok((c, pieces))
}

/// One BLAS's AS bytes (built, compacted, transient) plus `geometry_bytes` of inputs.
pub(crate) fn blas_cost_of(
    sizes: &dyn SizeSource,
    shape: &BlasShape,
    geometry_bytes: u64,
) -> Result<Cost, ReportError> {
    let s: AsSizes = sizes.blas_sizes(shape)?;
    let built = align_as(s.size_bytes);
    let compacted = align_as(sizes.compacted_blas_bytes(shape, s).min(s.size_bytes));
    let mut c = Cost {
        geometry_bytes,
        blas_bytes: built,
        blas_compacted_bytes: compacted,
        build_scratch_peak_bytes: s.build_scratch_bytes,
        build_transient_peak_bytes: blas_transient(built, compacted, s.build_scratch_bytes),
        blas_count: 1,
        blas_triangles: match shape {
            BlasShape::Triangles(_) => shape.primitive_count(),
            BlasShape::Aabbs { .. } => 0,
        },
        ..Default::default()
    };
    if let BlasShape::Aabbs { box_count } = shape {
        c.geometry_bytes += u64::from(*box_count) * AABB_RECORD_SIZE_BYTES;
    }
    c.seal();
    Ok(c)
}

/// What building one BLAS needs on top of its compacted (resident) size: while building, the
/// uncompacted structure and the scratch; while compacting, the uncompacted structure next to
/// the compacted copy. Without a compaction gain the builder keeps the built structure and
/// only the scratch is transient.
pub(crate) fn blas_transient(built: u64, compacted: u64, scratch: u64) -> u64 {
    if compacted < built {
        (built + scratch - compacted).max(built)
    } else {
        scratch
    }
}

/// Where flattening a TLAS's content into a top TLAS leads.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Expansion {
    /// Triangle-BLAS placements landing in the top TLAS.
    pub tri_instances: u64,
    /// PIs kept (their target subtree stays a separate TLAS).
    pub kept_pis: u64,
    /// Triangles of those placements (kept subtrees not included).
    pub instanced_triangles: u64,
}

impl Expansion {
    /// Adds `times` copies of `o` (saturating, as `times` additions would).
    fn add_times(&mut self, o: &Expansion, times: u64) {
        let add = |a: &mut u64, b: u64| *a = a.saturating_add(b.saturating_mul(times));
        add(&mut self.tri_instances, o.tri_instances);
        add(&mut self.kept_pis, o.kept_pis);
        add(&mut self.instanced_triangles, o.instanced_triangles);
    }
}

/// The per-node costs and graph queries of one hierarchy.
pub(crate) struct Graph<'a> {
    pub view: HierarchyView<'a>,
    pub tlas: Vec<Cost>,
    pub blas: Vec<Cost>,
    pub mesh: Vec<Cost>,
    pub lod: Vec<Cost>,
    /// TLAS levels of each TLAS's subtree (1 = only triangle instances).
    pub depth: Vec<u32>,
    /// Per TLAS, the BLASes its instances place with their counts: the graph's edges, walked
    /// instead of the instances (stored by the import, or counted by the caller).
    pub counts: BlasCounts,
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Mark {
    New,
    Busy,
    Done,
}

impl<'a> Graph<'a> {
    /// The graph of `view` with its BLAS counts (`counts` must be `view`'s: see
    /// [`BlasCounts::fits`]). `references_checked`: `view` passed
    /// `HierarchyView::check_references` already (a package's view, checked when opened).
    pub fn new(
        view: HierarchyView<'a>,
        sizes: &dyn SizeSource,
        counts: BlasCounts,
        references_checked: bool,
    ) -> Result<Self, ReportError> {
        if !references_checked {
            view.check_references()?;
        }
        if !counts.fits(&view) {
            return Err(ReportError::Invalid(
                "the BLAS counts are not this hierarchy's".into(),
            ));
        }
        let _span = tracing::info_span!(
            "report_costs",
            tlases = view.tlases.len(),
            blases = view.blases.len(),
            meshes = view.meshes.len()
        )
        .entered();
        let mesh: Vec<Cost> = view.meshes.iter().map(mesh_cost).collect();
        let mut blas = Vec::with_capacity(view.blases.len());
        for (i, b) in view.blases.iter().enumerate() {
            blas.push(Self::blas_cost(&view, i, b, sizes)?);
        }
        let mut tlas = Vec::with_capacity(view.tlases.len());
        for t in view.tlases {
            let (mut c, _) = tlas_cost(sizes, u64::from(t.instance_count))?;
            c.table_bytes +=
                rec::<TlasRecord>() + u64::from(t.instance_count) * rec::<InstanceRecord>();
            c.seal();
            tlas.push(c);
        }
        let lod = view
            .lod_selectors
            .iter()
            .map(|s| {
                let mut c = Cost {
                    table_bytes: rec::<LodSelectorRecord>() + u64::from(s.level_count) * 4,
                    ..Default::default()
                };
                c.seal();
                c
            })
            .collect();
        let mut g = Graph {
            view,
            tlas,
            blas,
            mesh,
            lod,
            depth: Vec::new(),
            counts,
        };
        g.depth = g.compute_depths()?;
        Ok(g)
    }

    fn blas_cost(
        view: &HierarchyView<'_>,
        index: usize,
        b: &BlasRecord,
        sizes: &dyn SizeSource,
    ) -> Result<Cost, ReportError> {
        let range = b.item_base as usize..(b.item_base + b.item_count) as usize;
        let (shape, records) = match b.kind {
            BLAS_TRIANGLES => {
                let geoms = view.geometries[range]
                    .iter()
                    .map(|g| {
                        let m = &view.meshes[g.mesh as usize];
                        TriangleGeometry {
                            vertex_count: m.vertex_count,
                            triangle_count: m.triangle_count,
                            opaque: m.flags & FLAG_NEEDS_ANY_HIT == 0,
                        }
                    })
                    .collect();
                (
                    BlasShape::Triangles(geoms),
                    u64::from(b.item_count) * rec::<GeometryRecord>(),
                )
            }
            BLAS_AABBS => (
                BlasShape::Aabbs {
                    box_count: b.item_count,
                },
                u64::from(b.item_count) * rec::<PiRecord>(),
            ),
            other => {
                return Err(ReportError::Invalid(format!(
                    "BLAS {index}: unknown kind {other}"
                )))
            }
        };
        if shape.primitive_count() == 0 {
            // An empty BLAS is never built; its records still cost.
            let mut c = Cost {
                table_bytes: rec::<BlasRecord>() + records,
                blas_count: 1,
                ..Default::default()
            };
            c.seal();
            return Ok(c);
        }
        let mut c = blas_cost_of(sizes, &shape, 0)?;
        c.table_bytes += rec::<BlasRecord>() + records;
        c.seal();
        Ok(c)
    }

    /// The BLASes TLAS `t`'s instances place, with how many place each.
    pub fn tlas_blases(&self, t: u32) -> impl Iterator<Item = (u32, u64)> + '_ {
        self.counts
            .tlas(t as usize)
            .iter()
            .map(|c| (c.blas, c.count))
    }

    /// PIs of AABB BLAS `b` (empty for triangle BLASes).
    pub fn blas_pis(&self, b: u32) -> &'a [PiRecord] {
        let r = &self.view.blases[b as usize];
        if r.kind != BLAS_AABBS {
            return &[];
        }
        &self.view.pis[r.item_base as usize..(r.item_base + r.item_count) as usize]
    }

    fn lod_levels(&self, s: u32) -> &'a [u32] {
        let r = &self.view.lod_selectors[s as usize];
        &self.view.lod_levels[r.level_base as usize..(r.level_base + r.level_count) as usize]
    }

    /// The nodes directly below `n`.
    pub fn children(&self, n: Node, out: &mut Vec<Node>) {
        match n {
            Node::Tlas(t) => out.extend(self.tlas_blases(t).map(|(b, _)| Node::Blas(b))),
            Node::Blas(b) => {
                let r = &self.view.blases[b as usize];
                let range = r.item_base as usize..(r.item_base + r.item_count) as usize;
                if r.kind == BLAS_TRIANGLES {
                    out.extend(
                        self.view.geometries[range]
                            .iter()
                            .map(|g| Node::Mesh(g.mesh)),
                    );
                } else {
                    out.extend(self.blas_pis(b).iter().filter_map(pi_target));
                }
            }
            Node::Lod(s) => out.extend(self.lod_levels(s).iter().map(|&t| Node::Tlas(t))),
            Node::Mesh(_) => {}
        }
    }

    pub fn cost(&self, n: Node) -> &Cost {
        match n {
            Node::Tlas(t) => &self.tlas[t as usize],
            Node::Blas(b) => &self.blas[b as usize],
            Node::Mesh(m) => &self.mesh[m as usize],
            Node::Lod(s) => &self.lod[s as usize],
        }
    }

    fn compute_depths(&self) -> Result<Vec<u32>, ReportError> {
        let n = self.view.tlases.len();
        let mut depth = vec![0u32; n];
        let mut mark = vec![Mark::New; n];
        // Iterative post-order so deep or corrupt graphs cannot overflow the stack.
        for root in 0..n as u32 {
            if mark[root as usize] != Mark::New {
                continue;
            }
            let mut stack = vec![(root, false)];
            while let Some((t, expanded)) = stack.pop() {
                let ti = t as usize;
                if expanded {
                    let mut d = 0;
                    for c in self.child_tlases(t) {
                        d = d.max(depth[c as usize]);
                    }
                    depth[ti] = d + 1;
                    mark[ti] = Mark::Done;
                    continue;
                }
                match mark[ti] {
                    Mark::Done => continue,
                    Mark::Busy => {
                        return Err(ReportError::Invalid(format!(
                            "the hierarchy has a cycle through TLAS {t}"
                        )))
                    }
                    Mark::New => {}
                }
                mark[ti] = Mark::Busy;
                stack.push((t, true));
                for c in self.child_tlases(t) {
                    match mark[c as usize] {
                        Mark::Done => {}
                        Mark::Busy => {
                            return Err(ReportError::Invalid(format!(
                                "the hierarchy has a cycle through TLAS {c}"
                            )))
                        }
                        Mark::New => stack.push((c, false)),
                    }
                }
            }
        }
        Ok(depth)
    }

    /// TLASes reached from `t` through one PI (all levels of LOD selectors).
    fn child_tlases(&self, t: u32) -> Vec<u32> {
        let mut out = Vec::new();
        for (b, _) in self.tlas_blases(t) {
            for p in self.blas_pis(b) {
                match p.kind {
                    PI_TLAS => out.push(p.target),
                    PI_LOD_SELECTOR => out.extend_from_slice(self.lod_levels(p.target)),
                    _ => {}
                }
            }
        }
        out
    }

    /// The depth of a PI's target (a LOD selector: its deepest level).
    fn pi_depth(&self, p: &PiRecord) -> u32 {
        match p.kind {
            PI_TLAS => self.depth[p.target as usize],
            PI_LOD_SELECTOR => self
                .lod_levels(p.target)
                .iter()
                .map(|&t| self.depth[t as usize])
                .max()
                .unwrap_or(0),
            _ => 0,
        }
    }

    /// The TLAS a PI expands into (a LOD selector: its finest level).
    fn pi_expand_target(&self, p: &PiRecord) -> Option<u32> {
        match p.kind {
            PI_TLAS => Some(p.target),
            PI_LOD_SELECTOR => self.lod_levels(p.target).first().copied(),
            _ => None,
        }
    }

    /// What flattening each TLAS's content to at most `levels` TLAS levels yields, for every
    /// TLAS: computed in ascending depth order (a PI's target is strictly shallower), so no
    /// recursion however deep the graph. O(BLAS counts + PIs), not O(instances).
    pub fn expansions(&self, levels: u32) -> Vec<Expansion> {
        let mut order: Vec<u32> = (0..self.view.tlases.len() as u32).collect();
        order.sort_by_key(|&t| self.depth[t as usize]);
        let mut out = vec![Expansion::default(); order.len()];
        for t in order {
            out[t as usize] = self.expand(self.tlas_blases(t), levels, &out);
        }
        out
    }

    /// Flattens placements (a BLAS and how many instances place it) into a top TLAS with at
    /// most `levels` TLAS levels, given [`Graph::expansions`] for the same `levels`.
    pub fn expand(
        &self,
        placements: impl Iterator<Item = (u32, u64)>,
        levels: u32,
        expanded: &[Expansion],
    ) -> Expansion {
        let mut e = Expansion::default();
        for (b, n) in placements {
            let r = &self.view.blases[b as usize];
            if r.kind == BLAS_TRIANGLES {
                let one = Expansion {
                    tri_instances: 1,
                    kept_pis: 0,
                    instanced_triangles: u64::from(r.primitive_count),
                };
                e.add_times(&one, n);
                continue;
            }
            for p in self.blas_pis(b) {
                if self.pi_depth(p) < levels {
                    e.kept_pis = e.kept_pis.saturating_add(n);
                } else if let Some(t) = self.pi_expand_target(p) {
                    if let Some(sub) = expanded.get(t as usize) {
                        e.add_times(sub, n);
                    }
                }
            }
        }
        e
    }

    /// The TLASes a flattening to `levels` expands (from TLAS `top`'s instances), the triangle
    /// BLASes it places in the top TLAS, and the roots of the subtrees it keeps.
    pub fn expansion_nodes(&self, top: u32, levels: u32) -> (Vec<u32>, Vec<u32>) {
        let mut seen_tlas = vec![false; self.view.tlases.len()];
        let mut tri_blas = vec![false; self.view.blases.len()];
        let mut kept = vec![false; self.view.tlases.len()];
        let mut stack: Vec<u32> = self.tlas_blases(top).map(|(b, _)| b).collect();
        while let Some(b) = stack.pop() {
            if self.view.blases[b as usize].kind == BLAS_TRIANGLES {
                tri_blas[b as usize] = true;
                continue;
            }
            for p in self.blas_pis(b) {
                if self.pi_depth(p) < levels {
                    match p.kind {
                        PI_TLAS => kept[p.target as usize] = true,
                        PI_LOD_SELECTOR => {
                            for &t in self.lod_levels(p.target) {
                                kept[t as usize] = true;
                            }
                        }
                        _ => {}
                    }
                } else if let Some(t) = self.pi_expand_target(p) {
                    if !seen_tlas[t as usize] {
                        seen_tlas[t as usize] = true;
                        stack.extend(self.tlas_blases(t).map(|(b, _)| b));
                    }
                }
            }
        }
        let idx = |v: Vec<bool>| {
            v.iter()
                .enumerate()
                .filter(|(_, &x)| x)
                .map(|(i, _)| i as u32)
                .collect()
        };
        (idx(tri_blas), idx(kept))
    }

    /// Every node reachable from `starts`, each once.
    pub fn reachable(&self, starts: impl IntoIterator<Item = Node>) -> Vec<Node> {
        let mut seen: std::collections::HashSet<Node> = Default::default();
        let mut stack: Vec<Node> = starts.into_iter().collect();
        let mut out = Vec::new();
        let mut kids = Vec::new();
        while let Some(n) = stack.pop() {
            if !seen.insert(n) {
                continue;
            }
            out.push(n);
            kids.clear();
            self.children(n, &mut kids);
            stack.extend(kids.iter().copied().filter(|k| !seen.contains(k)));
        }
        out
    }

    /// The global tables every render uploads whatever the subset (materials, textures).
    pub fn global_tables(&self) -> Cost {
        let mut c = Cost {
            table_bytes: self.view.materials.len() as u64 * rec::<MaterialRecord>(),
            texture_bytes: self.view.textures.len() as u64 * rec::<motu_abi::TextureRecord>()
                + self.view.texels.len() as u64 * 4,
            ptex_bytes: self
                .view
                .textures
                .iter()
                .filter(|t| motu_abi::ptex::is_ptex(t))
                .map(|t| t.texel_count() * 4)
                .sum(),
            ..Default::default()
        };
        c.seal();
        c
    }
}

fn pi_target(p: &PiRecord) -> Option<Node> {
    match p.kind {
        PI_TLAS => Some(Node::Tlas(p.target)),
        PI_LOD_SELECTOR => Some(Node::Lod(p.target)),
        _ => None,
    }
}

fn mesh_cost(m: &MeshRecord) -> Cost {
    let v = u64::from(m.vertex_count);
    let normals = if m.normals_offset != NONE_U64 {
        v * 12
    } else {
        0
    };
    // A cluster's primitive map is uploaded with its indices (u32 per triangle).
    let map = if m.flags & FLAG_PRIMITIVE_MAP != 0 {
        u64::from(m.triangle_count) * 4
    } else {
        0
    };
    let uvs = if m.flags & motu_abi::FLAG_HAS_UVS != 0 {
        v * 8
    } else {
        0
    };
    let mut c = Cost {
        geometry_bytes: v * 12 + normals + uvs + u64::from(m.triangle_count) * 12 + map,
        table_bytes: rec::<MeshRecord>(),
        ..Default::default()
    };
    c.seal();
    c
}
