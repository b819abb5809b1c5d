//! Full flattening of the source graph and of a compiled hierarchy into leaf placements, the
//! oracle for "compiling preserves the scene". Output is one entry per placed mesh, so use it on
//! small scenes only.

use crate::xform;
use motu_abi::{HierarchyView, BLAS_AABBS, BLAS_TRIANGLES, PI_LOD_SELECTOR, PI_TLAS};
use motu_scene::{MeshId, PrototypeId, Scene, Transform34};

/// Every `(world_from_mesh, mesh)` of the scene: each root-to-prototype path times each of the
/// prototype's meshes, root meshes included. Follows the compiler's rules: meshes without
/// triangles and edges with non-invertible transforms are skipped. No subset is applied.
pub fn flatten_source(scene: &Scene) -> Vec<(Transform34, MeshId)> {
    let mut out = Vec::new();
    let mut stack: Vec<(PrototypeId, Transform34)> = vec![(Scene::ROOT, Transform34::IDENTITY)];
    while let Some((p, world_from_p)) = stack.pop() {
        for &m in scene.meshes_of(p) {
            if scene.mesh(m).triangle_count > 0 {
                out.push((world_from_p, m));
            }
        }
        for e in scene.walk_edges(p) {
            if xform::is_invertible(&e.parent_from_child) {
                stack.push((e.child, xform::compose(&world_from_p, &e.parent_from_child)));
            }
        }
    }
    out
}

/// Every `(world_from_mesh, source_mesh)` of a compiled hierarchy, choosing LOD level `lod`
/// (clamped to each selector's chain) at every selector. A path is not followed deeper than
/// the TLAS count, so even a cyclic (invalid) hierarchy terminates; validate it first.
pub fn flatten_compiled(view: &HierarchyView<'_>, lod: u32) -> Vec<(Transform34, u32)> {
    flatten_compiled_records(view, lod)
        .into_iter()
        .map(|(t, r)| (t, view.meshes[r as usize].source_mesh))
        .collect()
}

/// [`flatten_compiled`] naming the mesh *record* of each placement (a baked or partitioned
/// record holds part of, or copies of, its source mesh: compare triangles, not placements).
pub fn flatten_compiled_records(view: &HierarchyView<'_>, lod: u32) -> Vec<(Transform34, u32)> {
    let mut out = Vec::new();
    if view.check_references().is_err() {
        return out;
    }
    let max_depth = view.tlases.len();
    let mut stack: Vec<(u32, Transform34, usize)> =
        vec![(view.root_tlas, Transform34::IDENTITY, 0)];
    while let Some((t, world_from_tlas, depth)) = stack.pop() {
        if depth > max_depth {
            continue;
        }
        let tlas = &view.tlases[t as usize];
        let range = tlas.instance_range();
        for inst in &view.instances[range] {
            let world_from_blas =
                xform::compose(&world_from_tlas, &xform::from_array(&inst.tlas_from_blas));
            let b = &view.blases[inst.blas as usize];
            let items = b.item_base as usize..(b.item_base + b.item_count) as usize;
            match b.kind {
                BLAS_TRIANGLES => {
                    for g in &view.geometries[items] {
                        out.push((world_from_blas, g.mesh));
                    }
                }
                BLAS_AABBS => {
                    for pi in &view.pis[items] {
                        let Some(parent_from_child) =
                            xform::inverse(&xform::from_array(&pi.child_from_parent))
                        else {
                            continue;
                        };
                        let world_from_child = xform::compose(&world_from_blas, &parent_from_child);
                        let target = match pi.kind {
                            PI_TLAS => pi.target,
                            PI_LOD_SELECTOR => {
                                let s = &view.lod_selectors[pi.target as usize];
                                view.lod_levels
                                    [(s.level_base + lod.min(s.level_count - 1)) as usize]
                            }
                            _ => continue,
                        };
                        stack.push((target, world_from_child, depth + 1));
                    }
                }
                _ => {}
            }
        }
    }
    out
}
