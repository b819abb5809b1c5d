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
//! `LEAF_TRIANGLES` triangles each, `fan` ≤ `MAX_FAN`). The shader tests the top boxes and
//! only the leaves of those the ray enters (`candidates.glsl` `record_proxy`); the boxes are
//! padded as proxy boxes are, so a ray that can hit a triangle always enters its leaf and the
//! image stays the full build's.
//!
//! The maths lives in `motu_compile::proxy_boxes`, which `motu import` also runs to store the
//! table in the package (its `proxy_boxes` section): the start takes each streamable BLAS's
//! boxes from there when the entry matches the BLAS's records, else from the structure cache
//! (`cache.rs`), else makes them from the meshes (read in parallel, none kept), so old
//! packages get them too. Their size depends only on the triangle counts, so the floor
//! ([`super::streaming_floor`]) counts them from [`layout`] without reading any mesh.

use motu_abi::{HierarchyView, BLAS_TRIANGLES};
pub(super) use motu_compile::proxy_boxes::Box6;
use motu_compile::proxy_boxes::{blas_boxes, fan, Stored, StoredProxyBoxes, EMPTY};
use rayon::prelude::*;

use crate::scene::MeshBlobSource;

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

/// The box table for `index` (from [`layout`]) with every BLAS whose entry in `stored`
/// matches its records filled, the BLASes left to make, and how many of those had a stale
/// entry (one made for other records).
pub(super) fn from_stored(
    view: &HierarchyView<'_>,
    stored: &StoredProxyBoxes,
    index: &[[u32; 2]],
    total: usize,
) -> (Vec<Box6>, Vec<usize>, usize) {
    let found: Vec<(usize, Stored<'_>)> = index
        .par_iter()
        .enumerate()
        .filter(|(_, ix)| ix[1] != 0)
        .map(|(b, _)| (b, stored.boxes_of(view, b)))
        .collect();
    let mut out = vec![EMPTY; total];
    let (mut left, mut stale) = (Vec::new(), 0);
    for (b, s) in found {
        match s {
            Stored::Valid(boxes) => {
                let first = index[b][0] as usize;
                out[first..first + boxes.len()].copy_from_slice(boxes);
            }
            Stored::Stale => {
                stale += 1;
                left.push(b);
            }
            Stored::Absent => left.push(b),
        }
    }
    (out, left, stale)
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
    let mut out = vec![EMPTY; total];
    let all: Vec<usize> = (0..index.len()).filter(|&b| index[b][1] != 0).collect();
    fill(view, source, index, &mut out, &all);
    out
}

/// Makes BLASes `blases`' boxes from their meshes into `table` (laid out by `index`).
pub(super) fn fill(
    view: &HierarchyView<'_>,
    source: &dyn MeshBlobSource,
    index: &[[u32; 2]],
    table: &mut [Box6],
    blases: &[usize],
) {
    let made: Vec<(usize, Vec<Box6>)> = blases
        .par_iter()
        .map(|&b| {
            let [first, fan] = index[b];
            let boxes = blas_boxes(view, b, fan as usize, |m| source.mesh_data(m));
            (first as usize, boxes)
        })
        .collect();
    for (first, boxes) in made {
        table[first..first + boxes.len()].copy_from_slice(&boxes);
    }
}

impl super::StreamingRenderer<'_> {
    /// The boxes inside streamable BLASes, laid out as `index`: each BLAS's from the table the
    /// mesh source stores (a package's `proxy_boxes` section) where its entry matches the
    /// BLAS's records; when any is left, the whole table from the structure cache, else the
    /// rest made from the meshes (`cache.rs`). Where they came from is in the totals
    /// (`proxy_boxes_source`); a stored table that does not match is a warning, never used.
    pub(super) fn proxy_boxes_start(&mut self, index: &[[u32; 2]], box_count: usize) -> Vec<Box6> {
        let view = self.view;
        let source = self.source;
        let mut partial = None;
        if let Some(bytes) = source.stored_proxy_boxes() {
            match motu_compile::proxy_boxes::decode_section(bytes) {
                None => tracing::warn!(
                    bytes = bytes.len(),
                    "the package's proxy-box table is not one this reader knows (another \
                     version, or damaged); the boxes are made from the meshes"
                ),
                Some(stored) => {
                    let (table, left, stale) = from_stored(&view, &stored, index, box_count);
                    self.totals.proxy_boxes_stale_blases = stale as u64;
                    if left.is_empty() {
                        self.totals.proxy_boxes_source = "package";
                        tracing::info!(boxes = box_count, "proxy boxes from the package");
                        return table;
                    }
                    if stale > 0 {
                        tracing::warn!(
                            stale,
                            left = left.len(),
                            "the package's proxy-box table does not match the records of \
                             {stale} BLASes; their boxes are made from the meshes"
                        );
                    }
                    partial = Some((table, left));
                }
            }
        }
        self.proxy_boxes_cached(index, box_count, partial)
    }
}

#[cfg(test)]
mod tests;
