//! After emission: node levels (longest path from the root, which makes TLASes even and
//! BLASes odd) and exact bounds, computed bottom-up from the compiled tables themselves so that
//! `validate` recomputes bit-identical PI boxes.

use crate::instance_map::RELEASE_EVERY_RECORDS;
use crate::{xform, CompileError, CompiledScene};
use motu_abi::{HierarchyView, BLAS_AABBS, BLAS_TRIANGLES, PI_LOD_SELECTOR, PI_TLAS};
use motu_scene::Aabb;

/// Calls `f` with every child of node `node` (TLASes are `0..nt`, BLASes `nt..`): a TLAS's
/// instanced BLASes, an AABB BLAS's target TLASes (every level of a LOD selector).
pub(crate) fn for_each_child(v: &HierarchyView<'_>, node: usize, mut f: impl FnMut(usize)) {
    let nt = v.tlases.len();
    if node < nt {
        let t = &v.tlases[node];
        let range = t.instance_range();
        for inst in &v.instances[range] {
            f(nt + inst.blas as usize);
        }
        return;
    }
    let b = &v.blases[node - nt];
    if b.kind != BLAS_AABBS {
        return;
    }
    for pi in &v.pis[b.item_base as usize..(b.item_base + b.item_count) as usize] {
        match pi.kind {
            PI_TLAS => f(pi.target as usize),
            PI_LOD_SELECTOR => {
                let s = &v.lod_selectors[pi.target as usize];
                for &t in
                    &v.lod_levels[s.level_base as usize..(s.level_base + s.level_count) as usize]
                {
                    f(t as usize);
                }
            }
            _ => {}
        }
    }
}

/// The bounds a PI must enclose: its target's bounds (all LOD levels) in the BLAS's space.
pub(crate) fn pi_target_bounds(
    v: &HierarchyView<'_>,
    tlas_bounds: impl Fn(usize) -> Aabb,
    pi: &motu_abi::PiRecord,
) -> Option<Aabb> {
    let parent_from_child = xform::inverse(&xform::from_array(&pi.child_from_parent))?;
    let child = match pi.kind {
        PI_TLAS => tlas_bounds(pi.target as usize),
        PI_LOD_SELECTOR => {
            let s = &v.lod_selectors[pi.target as usize];
            v.lod_levels[s.level_base as usize..(s.level_base + s.level_count) as usize]
                .iter()
                .fold(Aabb::EMPTY, |b, &t| b.union(&tlas_bounds(t as usize)))
        }
        _ => return None,
    };
    Some(child.transformed(&parent_from_child))
}

/// [`for_each_child`] that reads a TLAS's instances a piece at a time, the pages of a mapped
/// instance table dropped behind (`out` is the table `v` views).
fn for_each_child_released(
    out: &CompiledScene,
    v: &HierarchyView<'_>,
    node: usize,
    mut f: impl FnMut(usize),
) {
    let nt = v.tlases.len();
    if node >= nt {
        return for_each_child(v, node, f);
    }
    for (begin, end) in pieces(v.tlases[node].instance_range()) {
        for inst in &v.instances[begin..end] {
            f(nt + inst.blas as usize);
        }
        out.instances.release_range(begin, end);
    }
}

/// `range` in pieces of [`RELEASE_EVERY_RECORDS`] records.
fn pieces(range: std::ops::Range<usize>) -> impl Iterator<Item = (usize, usize)> {
    range
        .clone()
        .step_by(RELEASE_EVERY_RECORDS)
        .map(move |b| (b, (b + RELEASE_EVERY_RECORDS).min(range.end)))
}

pub(crate) fn finalize(out: &mut CompiledScene) -> Result<(), CompileError> {
    let _span = tracing::info_span!("finalize").entered();
    crate::check_references(out).map_err(CompileError::References)?;
    let nt = out.tlases.len();
    let n = nt + out.blases.len();
    // Kahn's algorithm: a topological order and longest-path levels.
    let mut pending = vec![0u32; n];
    {
        let v = out.view();
        for node in 0..n {
            for_each_child_released(out, &v, node, |c| pending[c] += 1);
        }
    }
    if let Some(src) = (0..n).find(|&i| pending[i] == 0 && i != out.root_tlas as usize) {
        return Err(CompileError::Internal(format!("node {src} is unreachable")));
    }
    let mut level = vec![0u32; n];
    let mut order: Vec<u32> = Vec::with_capacity(n);
    order.push(out.root_tlas);
    let mut head = 0;
    {
        let v = out.view();
        while head < order.len() {
            let node = order[head] as usize;
            head += 1;
            let next = level[node] + 1;
            for_each_child_released(out, &v, node, |c| {
                level[c] = level[c].max(next);
                pending[c] -= 1;
                if pending[c] == 0 {
                    order.push(c as u32);
                }
            });
        }
    }
    if order.len() != n {
        return Err(CompileError::Internal(
            "cycle in the compiled hierarchy".into(),
        ));
    }
    for (t, l) in out.tlases.iter_mut().zip(&level) {
        t.level = *l;
    }
    for (b, l) in out.blases.iter_mut().zip(&level[nt..]) {
        b.level = *l;
    }

    // Bounds, children first.
    for &node in order.iter().rev() {
        let node = node as usize;
        if node < nt {
            let t = out.tlases[node];
            let range = t.instance_range();
            let mut b = Aabb::EMPTY;
            for (begin, end) in pieces(range) {
                b = out.instances[begin..end].iter().fold(b, |acc, inst| {
                    acc.union(&crate::tables::instance_bounds(&out.blases, inst))
                });
                out.instances.release_range(begin, end);
            }
            let t = &mut out.tlases[node];
            (t.bounds_min, t.bounds_max) = (b.min, b.max);
            continue;
        }
        let bi = node - nt;
        let blas = out.blases[bi];
        let range = blas.item_base as usize..(blas.item_base + blas.item_count) as usize;
        let mut bounds = Aabb::EMPTY;
        if blas.kind == BLAS_TRIANGLES {
            for g in &out.geometries[range] {
                let m = &out.meshes[g.mesh as usize];
                bounds = bounds.union(&xform::aabb_from_record(m.bounds_min, m.bounds_max));
            }
        } else {
            for i in range {
                let pi = out.pis[i];
                let b = {
                    let v = out.view();
                    let tlases = &out.tlases;
                    pi_target_bounds(
                        &v,
                        |t| xform::aabb_from_record(tlases[t].bounds_min, tlases[t].bounds_max),
                        &pi,
                    )
                }
                .ok_or_else(|| CompileError::Internal(format!("PI {i} is not invertible")))?;
                let p = &mut out.pis[i];
                (p.aabb_min, p.aabb_max) = (b.min, b.max);
                bounds = bounds.union(&b);
            }
        }
        let b = &mut out.blases[bi];
        (b.bounds_min, b.bounds_max) = (bounds.min, bounds.max);
    }

    let r = &mut out.report;
    r.tlas_count = out.tlases.len() as u64;
    r.blas_count = out.blases.len() as u64;
    r.triangle_blas_count = out
        .blases
        .iter()
        .filter(|b| b.kind == BLAS_TRIANGLES)
        .count() as u64;
    r.aabb_blas_count = r.blas_count - r.triangle_blas_count;
    r.instance_count = out.instances.len() as u64;
    r.geometry_count = out.geometries.len() as u64;
    r.pi_count = out.pis.len() as u64;
    r.lod_selector_count = out.lod_selectors.len() as u64;
    r.mesh_count = out.meshes.len() as u64;
    r.material_count = out.materials.len() as u64;
    r.max_level = level.iter().copied().max().unwrap_or(0);
    r.tlas_levels = level[..nt].iter().copied().max().map_or(0, |l| l / 2 + 1);
    r.max_instances_per_tlas = out
        .tlases
        .iter()
        .map(|t| t.instance_count as u64)
        .max()
        .unwrap_or(0);
    r.max_primitives_per_blas = out
        .blases
        .iter()
        .map(|b| b.primitive_count as u64)
        .max()
        .unwrap_or(0);
    r.max_triangles_per_blas = out
        .blases
        .iter()
        .filter(|b| b.kind == BLAS_TRIANGLES)
        .map(|b| b.primitive_count as u64)
        .max()
        .unwrap_or(0);
    Ok(())
}
