//! Instance-level LOD: the hierarchy rewritten so that LOD selectors whose level depends only
//! on the camera become plain TLAS instances of the chosen level's BLASes (one trace, no
//! traversal-shader hop), mirrored in `shaders/lod_instances.comp` and `shaders/lod.glsl`.
//!
//! A selector qualifies when its TLAS has a single world placement (the root, the pieces of a
//! split root, any TLAS reached from there through exactly one programmable instance) and each
//! of its levels is a TLAS of triangle BLASes placed with the identity (what the compiler
//! makes). Such a selector PI becomes a *slot*: `width` consecutive instances of its TLAS, one
//! per BLAS of every level (finest level first), placed with the PI's `parent_from_child`. Per
//! frame the level is [`camera_level`] (distance from the eye to the selector's world bounding
//! sphere, the same [`crate::lod::select_lod`] rule): the chosen level's instances are active,
//! the others inactive (address 0 on the GPU, the empty BLAS on the CPU). Every level's BLASes
//! stay referenced, so they are built with the scene. Every ray then sees one level of an
//! instance, so shadow rays need no bias or forcing. Other selectors keep the traversal path.

use bytemuck::{Pod, Zeroable};

use crate::lod::{select_lod, LodParams, RAY_PRIMARY};
use crate::{
    BlasRecord, HierarchyError, HierarchyView, InstanceRecord, PiRecord, TlasRecord, BLAS_AABBS,
    BLAS_TRIANGLES, IDENTITY_3X4, PI_LOD_SELECTOR, PI_TLAS,
};

/// One LOD instance slot (shared with `shaders/lod_instances.comp`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
#[repr(C)]
pub struct LodSlotRecord {
    /// The selector's bounding sphere in world space.
    pub center_world: [f32; 3],
    pub radius_world: f32,
    pub selector: u32,
    /// First of the slot's instances in the instance table.
    pub instance: u32,
    /// Instances reserved: the BLASes of all levels together.
    pub width: u32,
    /// The TLAS whose instance range holds the slot.
    pub tlas: u32,
}

/// The level a slot shows for a camera at `world_eye`: [`select_lod`] with the distance from
/// the eye to the sphere's centre as `t_near` and a primary ray (mirrored in `lod.glsl`'s
/// `camera_lod`).
pub fn camera_level(
    p: &LodParams,
    pixels_per_unit_at_1: f32,
    world_eye: [f32; 3],
    slot: &LodSlotRecord,
    level_count: u32,
) -> u32 {
    let d = [
        slot.center_world[0] - world_eye[0],
        slot.center_world[1] - world_eye[1],
        slot.center_world[2] - world_eye[2],
    ];
    let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
    select_lod(
        p,
        pixels_per_unit_at_1,
        slot.radius_world,
        1.0,
        dist,
        level_count,
        RAY_PRIMARY,
        0.0,
    )
}

/// Whether the LOD rule depends only on the camera (stochastic dithering is per ray).
pub fn rule_is_camera_only(p: &LodParams) -> bool {
    p.stochastic == 0
}

/// The rewritten tables (other tables are borrowed from the base view unchanged).
#[derive(Clone, Debug)]
pub struct InstanceLod {
    pub tlases: Vec<TlasRecord>,
    pub instances: Vec<InstanceRecord>,
    pub blases: Vec<BlasRecord>,
    pub pis: Vec<PiRecord>,
    pub slots: Vec<LodSlotRecord>,
    /// TLASes holding slots (rebuilt when levels change), ascending; their instance ranges
    /// are consecutive from [`InstanceLod::lod_instance_base`] on, in this order.
    pub lod_tlases: Vec<u32>,
    pub lod_instance_base: u32,
    /// The empty triangle BLAS unused slot instances point at.
    pub empty_blas: u32,
    /// Selectors (PIs) left on the traversal path: in TLASes placed more than once, or with
    /// levels the slot form cannot express.
    pub traversal_selectors: u32,
}

/// `a ∘ b` (apply `b` first), in f64.
fn compose(a: &[f32; 12], b: &[f32; 12]) -> [f32; 12] {
    let mut out = [0f32; 12];
    for r in 0..3 {
        for c in 0..4 {
            let mut v: f64 = (0..3)
                .map(|k| f64::from(a[4 * r + k]) * f64::from(b[4 * k + c]))
                .sum();
            if c == 3 {
                v += f64::from(a[4 * r + 3]);
            }
            out[4 * r + c] = v as f32;
        }
    }
    out
}

fn too_many(what: &str) -> HierarchyError {
    HierarchyError {
        table: "instance LOD",
        index: 0,
        reason: format!("too many {what}"),
    }
}

impl InstanceLod {
    /// The rewrite of `view`; `None` when no selector qualifies (nothing to do).
    pub fn new(view: &HierarchyView<'_>) -> Result<Option<Self>, HierarchyError> {
        view.check_references()?;
        let nt = view.tlases.len();
        let range = |t: u32| {
            let r = &view.tlases[t as usize];
            r.instance_range()
        };
        // Reachable TLASes, uses of each AABB BLAS (per reachable placement) and references
        // to each TLAS (LOD levels count as many).
        let mut seen = vec![false; nt];
        let mut todo = vec![view.root_tlas];
        seen[view.root_tlas as usize] = true;
        let mut blas_uses = vec![0u32; view.blases.len()];
        while let Some(t) = todo.pop() {
            for inst in &view.instances[range(t)] {
                let b = &view.blases[inst.blas as usize];
                if b.kind != BLAS_AABBS {
                    continue;
                }
                blas_uses[inst.blas as usize] += 1;
                if blas_uses[inst.blas as usize] > 1 {
                    continue;
                }
                for pi in &view.pis[b.item_base as usize..(b.item_base + b.item_count) as usize] {
                    let targets: Vec<u32> = if pi.kind == PI_TLAS {
                        vec![pi.target]
                    } else {
                        let s = &view.lod_selectors[pi.target as usize];
                        view.lod_levels
                            [s.level_base as usize..(s.level_base + s.level_count) as usize]
                            .to_vec()
                    };
                    for c in targets {
                        if !std::mem::replace(&mut seen[c as usize], true) {
                            todo.push(c);
                        }
                    }
                }
            }
        }
        let mut refs = vec![0u32; nt];
        for (b, &uses) in blas_uses.iter().enumerate() {
            if uses == 0 {
                continue;
            }
            let b = &view.blases[b];
            for pi in &view.pis[b.item_base as usize..(b.item_base + b.item_count) as usize] {
                if pi.kind == PI_TLAS {
                    refs[pi.target as usize] = refs[pi.target as usize].saturating_add(uses);
                } else {
                    let s = &view.lod_selectors[pi.target as usize];
                    for &l in &view.lod_levels
                        [s.level_base as usize..(s.level_base + s.level_count) as usize]
                    {
                        refs[l as usize] = 2;
                    }
                }
            }
        }
        // TLASes with one world placement, and that placement (`world_from_tlas`).
        let mut placed: Vec<Option<[f32; 12]>> = vec![None; nt];
        placed[view.root_tlas as usize] = Some(IDENTITY_3X4);
        let mut order = vec![view.root_tlas];
        let mut k = 0;
        while k < order.len() {
            let t = order[k];
            k += 1;
            let world_from_t = placed[t as usize].unwrap_or(IDENTITY_3X4);
            for inst in &view.instances[range(t)] {
                let b = &view.blases[inst.blas as usize];
                if b.kind != BLAS_AABBS || blas_uses[inst.blas as usize] != 1 {
                    continue;
                }
                for pi in &view.pis[b.item_base as usize..(b.item_base + b.item_count) as usize] {
                    if pi.kind != PI_TLAS || refs[pi.target as usize] != 1 {
                        continue;
                    }
                    if placed[pi.target as usize].is_some() {
                        continue;
                    }
                    let Some(parent_from_child) = crate::invert_3x4(&pi.child_from_parent) else {
                        continue;
                    };
                    placed[pi.target as usize] = Some(compose(&world_from_t, &parent_from_child));
                    order.push(pi.target);
                }
            }
        }
        // A level qualifies when it is a TLAS of identity-placed triangle BLASes.
        let level_ok = |l: u32| {
            view.instances[range(l)].iter().all(|i| {
                i.tlas_from_blas == IDENTITY_3X4
                    && view.blases[i.blas as usize].kind == BLAS_TRIANGLES
            })
        };
        let selector_width = |s: u32| -> Option<u32> {
            let s = &view.lod_selectors[s as usize];
            let levels =
                &view.lod_levels[s.level_base as usize..(s.level_base + s.level_count) as usize];
            if levels.is_empty() || !levels.iter().all(|&l| level_ok(l)) {
                return None;
            }
            Some(
                levels
                    .iter()
                    .map(|&l| view.tlases[l as usize].instance_count)
                    .sum(),
            )
        };

        let mut out = InstanceLod {
            tlases: view.tlases.to_vec(),
            instances: view.instances.to_vec(),
            blases: view.blases.to_vec(),
            pis: view.pis.to_vec(),
            slots: Vec::new(),
            lod_tlases: Vec::new(),
            lod_instance_base: u32::try_from(view.instances.len())
                .map_err(|_| too_many("instances"))?,
            empty_blas: u32::try_from(view.blases.len()).map_err(|_| too_many("BLASes"))?,
            traversal_selectors: 0,
        };
        out.blases.push(BlasRecord {
            kind: BLAS_TRIANGLES,
            item_base: 0,
            item_count: 0,
            level: 1,
            bounds_min: [f32::INFINITY; 3],
            primitive_count: 0,
            bounds_max: [f32::NEG_INFINITY; 3],
            _pad: 0,
        });
        let mut sorted: Vec<u32> = order.clone();
        sorted.sort_unstable();
        for t in sorted {
            let world_from_t = placed[t as usize].unwrap_or(IDENTITY_3X4);
            let src = &view.instances[range(t)];
            let has_slot = src.iter().any(|inst| {
                let b = &view.blases[inst.blas as usize];
                b.kind == BLAS_AABBS
                    && blas_uses[inst.blas as usize] == 1
                    && view.pis[b.item_base as usize..(b.item_base + b.item_count) as usize]
                        .iter()
                        .any(|p| p.kind == PI_LOD_SELECTOR && selector_width(p.target).is_some())
            });
            if !has_slot {
                continue;
            }
            let base = out.instances.len();
            let mut slots_here = Vec::new();
            for inst in src {
                let b = &view.blases[inst.blas as usize];
                if b.kind != BLAS_AABBS || blas_uses[inst.blas as usize] != 1 {
                    out.instances.push(*inst);
                    continue;
                }
                let pis = &view.pis[b.item_base as usize..(b.item_base + b.item_count) as usize];
                let mut kept = Vec::new();
                for pi in pis {
                    let width = if pi.kind == PI_LOD_SELECTOR {
                        selector_width(pi.target)
                    } else {
                        None
                    };
                    match (width, crate::invert_3x4(&pi.child_from_parent)) {
                        (Some(w), Some(parent_from_child)) => {
                            slots_here.push((*pi, w, parent_from_child, inst.element))
                        }
                        _ => kept.push(*pi),
                    }
                }
                if kept.is_empty() {
                    continue;
                }
                // The PIs that stay: a new AABB BLAS of their own.
                let item_base =
                    u32::try_from(out.pis.len()).map_err(|_| too_many("programmable instances"))?;
                let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
                for p in &kept {
                    for a in 0..3 {
                        lo[a] = lo[a].min(p.aabb_min[a]);
                        hi[a] = hi[a].max(p.aabb_max[a]);
                    }
                }
                out.pis.extend_from_slice(&kept);
                let nb = u32::try_from(out.blases.len()).map_err(|_| too_many("BLASes"))?;
                out.blases.push(BlasRecord {
                    item_base,
                    item_count: kept.len() as u32,
                    primitive_count: kept.len() as u32,
                    bounds_min: lo,
                    bounds_max: hi,
                    ..*b
                });
                out.instances.push(InstanceRecord { blas: nb, ..*inst });
            }
            for (pi, width, parent_from_child, element) in slots_here {
                let sel = &view.lod_selectors[pi.target as usize];
                let world_from_child = compose(&world_from_t, &parent_from_child);
                let first =
                    u32::try_from(out.instances.len()).map_err(|_| too_many("instances"))?;
                for &level in &view.lod_levels
                    [sel.level_base as usize..(sel.level_base + sel.level_count) as usize]
                {
                    for i in &view.instances[range(level)] {
                        out.instances.push(InstanceRecord {
                            tlas_from_blas: parent_from_child,
                            blas: i.blas,
                            flags: i.flags,
                            element,
                            _pad: 0,
                        });
                    }
                }
                out.slots.push(LodSlotRecord {
                    center_world: crate::xform_point(&world_from_child, sel.center),
                    radius_world: sel.radius * max_scale(&world_from_child),
                    selector: pi.target,
                    instance: first,
                    width,
                    tlas: t,
                });
            }
            let count = out.instances.len() - base;
            let rec = &mut out.tlases[t as usize];
            rec.instance_base = u32::try_from(base).map_err(|_| too_many("instances"))?;
            rec.instance_count = u32::try_from(count).map_err(|_| too_many("instances"))?;
            out.lod_tlases.push(t);
        }
        // Selectors that stay on the traversal path (reachable ones only).
        out.traversal_selectors = count_reachable_selectors(&out.view(view));
        if out.slots.is_empty() {
            return Ok(None);
        }
        Ok(Some(out))
    }

    /// The hierarchy with slots instead of the qualifying selectors.
    pub fn view<'a>(&'a self, base: &HierarchyView<'a>) -> HierarchyView<'a> {
        HierarchyView {
            tlases: &self.tlases,
            instances: &self.instances,
            blases: &self.blases,
            pis: &self.pis,
            ..*base
        }
    }

    /// Each slot's level for a camera (the CPU side of `lod_instances.comp`).
    pub fn levels(
        &self,
        base: &HierarchyView<'_>,
        p: &LodParams,
        pixels_per_unit_at_1: f32,
        world_eye: [f32; 3],
    ) -> Vec<u32> {
        self.slots
            .iter()
            .map(|s| {
                let sel = &base.lod_selectors[s.selector as usize];
                camera_level(p, pixels_per_unit_at_1, world_eye, s, sel.level_count)
            })
            .collect()
    }

    /// Leaves only each slot's chosen level active: the other levels' instances point at the
    /// empty BLAS (on the GPU the compute pass makes them inactive instead). Call on a copy
    /// made by [`InstanceLod::new`] (every level's BLASes in place).
    pub fn apply_levels(&mut self, base: &HierarchyView<'_>, levels: &[u32]) {
        for (s, &chosen) in self.slots.iter().zip(levels) {
            let sel = &base.lod_selectors[s.selector as usize];
            let mut k = s.instance as usize;
            for l in 0..sel.level_count {
                let lt = &base.tlases[base.lod_levels[(sel.level_base + l) as usize] as usize];
                for _ in 0..lt.instance_count {
                    if l != chosen {
                        self.instances[k].blas = self.empty_blas;
                    }
                    k += 1;
                }
            }
        }
    }
}

/// The largest factor by which `m` scales a length (its linear part's largest column norm
/// bounds it from below; the Frobenius norm from above: the column norm is exact for
/// similarity transforms, what scene placements are).
fn max_scale(m: &[f32; 12]) -> f32 {
    (0..3)
        .map(|c| {
            (0..3)
                .map(|r| m[4 * r + c] * m[4 * r + c])
                .sum::<f32>()
                .sqrt()
        })
        .fold(0.0, f32::max)
}

/// LOD-selector PIs reachable from the root.
fn count_reachable_selectors(v: &HierarchyView<'_>) -> u32 {
    let mut seen_t = vec![false; v.tlases.len()];
    let mut seen_b = vec![false; v.blases.len()];
    let mut todo = vec![v.root_tlas];
    seen_t[v.root_tlas as usize] = true;
    let mut n = 0u32;
    while let Some(t) = todo.pop() {
        let r = &v.tlases[t as usize];
        for inst in &v.instances[r.instance_range()] {
            let b = &v.blases[inst.blas as usize];
            if b.kind != BLAS_AABBS || std::mem::replace(&mut seen_b[inst.blas as usize], true) {
                continue;
            }
            for pi in &v.pis[b.item_base as usize..(b.item_base + b.item_count) as usize] {
                let targets: Vec<u32> = if pi.kind == PI_TLAS {
                    vec![pi.target]
                } else {
                    n += 1;
                    let s = &v.lod_selectors[pi.target as usize];
                    v.lod_levels[s.level_base as usize..(s.level_base + s.level_count) as usize]
                        .to_vec()
                };
                for c in targets {
                    if !std::mem::replace(&mut seen_t[c as usize], true) {
                        todo.push(c);
                    }
                }
            }
        }
    }
    n
}
