//! Proxy boxes inside a BLAS: a ray that enters a member instance's box of a non-resident BLAS
//! opens it (a build before the pixel can finish) only if it also enters one of the boxes
//! around the BLAS's triangles.
//!
//! A BLAS box is loose around most geometry (a palm's fronds, a cluster of rocks, a strip of
//! terrain seen edge-on), and every ray through its empty part used to demand the build; at a
//! quarter of the default island's full build that made a frame's working set of opened
//! structures larger than the room, and each frame took two passes. Each buildable triangle
//! BLAS gets a two-level tree of boxes from centroid-median splits of its triangles: `fan` top
//! boxes, each followed in the table by its `fan` leaves (`fan` × `fan` leaves in all, about
//! [`LEAF_TRIANGLES`] triangles each, `fan` ≤ [`MAX_FAN`]). The shader tests the top boxes and
//! only the leaves of those the ray enters (`candidates.glsl` `record_proxy`); the boxes are
//! padded as proxy boxes are, so a ray that can hit a triangle always enters its leaf and the
//! image stays the full build's.
//!
//! Made once when the renderer starts, from the meshes (read in parallel, none kept), so old
//! packages get them too; their size depends only on the triangle counts, so the floor
//! ([`super::streaming_floor`]) counts them from [`layout`] without reading any mesh.

use std::ops::Range;

use motu_abi::{HierarchyView, BLAS_TRIANGLES};
use rayon::prelude::*;

use crate::scene::MeshBlobSource;

/// Triangles per leaf box the fan aims at.
pub(super) const LEAF_TRIANGLES: u32 = 32;
/// At most this many top boxes (and leaves per top box): the shader keeps the entered top
/// boxes in a 16-bit mask.
pub(super) const MAX_FAN: u32 = 16;

/// `[min x, y, z, max x, y, z]`; an unused box is empty (min > max).
pub(super) type Box6 = [f32; 6];

const EMPTY: Box6 = [
    f32::INFINITY,
    f32::INFINITY,
    f32::INFINITY,
    f32::NEG_INFINITY,
    f32::NEG_INFINITY,
    f32::NEG_INFINITY,
];

/// Top boxes (= leaves per top box) of a BLAS of `triangles`: the greatest power of two whose
/// square of leaves holds at least [`LEAF_TRIANGLES`] each (1 for fewer), capped at
/// [`MAX_FAN`]. Rounding down keeps the table at most a 32nd of the triangles (24 bytes a box,
/// resident in the floor); rounding up made 4,096-triangle units 272 boxes of 16 triangles.
pub(super) fn fan(triangles: u32) -> u32 {
    let mut f = 1u32;
    while f < MAX_FAN && u64::from(4 * f * f) * u64::from(LEAF_TRIANGLES) <= u64::from(triangles) {
        f *= 2;
    }
    f
}

/// Where each BLAS's boxes start in the box table and its fan (`[first, fan]`, fan 0: none,
/// as for AABB BLASes and BLASes that never stream), and the table's length.
pub(super) fn layout(
    view: &HierarchyView<'_>,
    buildable: impl Fn(usize) -> bool,
) -> (Vec<[u32; 2]>, usize) {
    let mut next = 0usize;
    let index = view
        .blases
        .iter()
        .enumerate()
        .map(|(b, r)| {
            if r.kind != BLAS_TRIANGLES || !buildable(b) {
                return [0, 0];
            }
            let f = fan(r.primitive_count);
            let first = next;
            next += (f + f * f) as usize;
            [first as u32, f]
        })
        .collect();
    (index, next)
}

/// The box table for `index` (from [`layout`]): every BLAS with a fan gets its boxes from its
/// meshes; one whose meshes cannot be read gets its bounds as its only top box and leaf (the
/// build reports the error when a ray needs it).
pub(super) fn compute(
    view: &HierarchyView<'_>,
    source: &dyn MeshBlobSource,
    index: &[[u32; 2]],
    total: usize,
) -> Vec<Box6> {
    let per_blas: Vec<(usize, Vec<Box6>)> = index
        .par_iter()
        .enumerate()
        .filter(|(_, ix)| ix[1] != 0)
        .map(|(b, ix)| (ix[0] as usize, blas_boxes(view, source, b, ix[1] as usize)))
        .collect();
    let mut out = vec![EMPTY; total];
    for (first, boxes) in per_blas {
        out[first..first + boxes.len()].copy_from_slice(&boxes);
    }
    out
}

/// `fan` top boxes then `fan` leaves per top box, in BLAS space, padded.
fn blas_boxes(
    view: &HierarchyView<'_>,
    source: &dyn MeshBlobSource,
    b: usize,
    fan: usize,
) -> Vec<Box6> {
    let r = &view.blases[b];
    let mut out = vec![EMPTY; fan + fan * fan];
    let bounds = padded(r.bounds_box());
    // (centroid, box) per triangle.
    let mut tris: Vec<([f32; 3], Box6)> = Vec::with_capacity(r.primitive_count as usize);
    let range = r.item_base as usize..(r.item_base + r.item_count) as usize;
    for g in &view.geometries[range] {
        let Ok((positions, indices)) = source.mesh_data(g.mesh) else {
            out[0] = bounds;
            out[fan] = bounds;
            return out;
        };
        for t in indices.chunks_exact(3) {
            let mut bx = EMPTY;
            for &i in t {
                // An index out of range fails the build itself (`MeshGpu::upload`).
                let Some(p) = positions.get(i as usize) else {
                    continue;
                };
                grow(&mut bx, p, p);
            }
            if bx[0] <= bx[3] {
                let c = std::array::from_fn(|a| 0.5 * (bx[a] + bx[3 + a]));
                tris.push((c, bx));
            }
        }
    }
    let mut leaves = Vec::with_capacity(fan * fan);
    split(&mut tris, 2 * fan.trailing_zeros(), 0, &mut leaves);
    // Each leaf's triangles once; a top box is the union of its leaves.
    let leaf_boxes: Vec<Box6> = leaves
        .iter()
        .map(|r| {
            let mut bx = EMPTY;
            for t in &tris[r.clone()] {
                grow(&mut bx, &t.1[..3], &t.1[3..]);
            }
            bx
        })
        .collect();
    let pad_nonempty = |bx: Box6| if bx[0] <= bx[3] { padded(bx) } else { bx };
    for (k, group) in leaf_boxes.chunks_exact(fan).enumerate() {
        let mut top = EMPTY;
        for (j, leaf) in group.iter().enumerate() {
            grow(&mut top, &leaf[..3], &leaf[3..]);
            out[fan + k * fan + j] = pad_nonempty(*leaf);
        }
        out[k] = pad_nonempty(top);
    }
    out
}

/// `b` grown by a little more than float error: a proxy box only has to contain what it
/// stands for, and a flat one (a ground or ocean plane) is otherwise missed by box tests at
/// grazing angles where the triangle itself is hit (a far pixel lost its hit at small budgets,
/// where no neighbour happened to make the BLAS resident).
pub(super) fn padded(b: [f32; 6]) -> [f32; 6] {
    let extent = (0..3).map(|a| b[3 + a] - b[a]).fold(0.0f32, f32::max);
    let magnitude = b.iter().map(|v| v.abs()).fold(0.0f32, f32::max);
    let pad = 1e-3 * extent + 1e-5 * magnitude;
    if !pad.is_finite() {
        return b;
    }
    [
        b[0] - pad,
        b[1] - pad,
        b[2] - pad,
        b[3] + pad,
        b[4] + pad,
        b[5] + pad,
    ]
}

fn grow(bx: &mut Box6, lo: &[f32], hi: &[f32]) {
    for a in 0..3 {
        bx[a] = bx[a].min(lo[a]);
        bx[3 + a] = bx[3 + a].max(hi[a]);
    }
}

/// Appends `2^depth` leaf ranges (absolute, from `base`) of centroid-median splits along the
/// widest centroid axis, depth first, so leaf `j`'s ancestor `d` levels up is `j >> d`; a range
/// too small to split ends in empty leaves.
fn split(tris: &mut [([f32; 3], Box6)], depth: u32, base: usize, leaves: &mut Vec<Range<usize>>) {
    if depth == 0 || tris.len() < 2 {
        leaves.push(base..base + tris.len());
        let end = base + tris.len();
        leaves.extend((1..1usize << depth).map(|_| end..end));
        return;
    }
    let mut c = EMPTY;
    for t in tris.iter() {
        grow(&mut c, &t.0, &t.0);
    }
    let axis = (0..3)
        .max_by(|&x, &y| (c[3 + x] - c[x]).total_cmp(&(c[3 + y] - c[y])))
        .unwrap_or(0);
    let mid = tris.len() / 2;
    tris.select_nth_unstable_by(mid, |x, y| x.0[axis].total_cmp(&y.0[axis]));
    let (l, r) = tris.split_at_mut(mid);
    split(l, depth - 1, base, leaves);
    split(r, depth - 1, base + mid, leaves);
}

#[cfg(test)]
mod tests;
