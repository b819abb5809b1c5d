//! Proxy boxes inside a triangle BLAS: the maths, and the table a package stores.
//!
//! A streamed render (`motu-gpu` `stream/proxy_boxes.rs`) lets a ray that enters a
//! non-resident BLAS's box open it only if the ray also enters one of the boxes around the
//! BLAS's triangles: `fan` top boxes, each followed in the table by its `fan` leaves, from
//! centroid-median splits of the triangles (`fan` × `fan` leaves in all, about
//! [`LEAF_TRIANGLES`] triangles each, `fan` ≤ [`MAX_FAN`]), padded as proxy boxes are, so a ray
//! that can hit a triangle always enters its leaf.
//!
//! Making them reads every mesh (seconds on a large scene), so `motu import` makes them once
//! and stores them in the package's `proxy_boxes` section ([`encode_section`], FORMAT.md);
//! the streamer uses a stored BLAS's boxes only when the entry's hash of the BLAS's records
//! ([`blas_hash`]) matches, and makes the rest itself. Both sides call [`blas_boxes`] (the
//! streamer) or [`boxes_from_triangles`] over [`push_triangle_boxes`] (the importer, a chunk at
//! a time): the same operations in the same order, so the boxes are equal bit for bit.

use std::borrow::Cow;
#[cfg(test)]
use std::ops::Range;

use motu_abi::blob::{BlobReader, BlobWriter};
use motu_abi::{BlasRecord, HierarchyView, BLAS_TRIANGLES};

/// Triangles per leaf box the fan aims at.
pub const LEAF_TRIANGLES: u32 = 32;
/// At most this many top boxes (and leaves per top box): the shader keeps the entered top
/// boxes in a 16-bit mask.
pub const MAX_FAN: u32 = 16;

/// `[min x, y, z, max x, y, z]`; an unused box is empty (min > max).
pub type Box6 = [f32; 6];

/// A triangle's centroid and box, as the splits read them.
pub type TriangleBox = ([f32; 3], Box6);

/// The empty box (min > max).
pub const EMPTY: Box6 = [
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
pub fn fan(triangles: u32) -> u32 {
    let mut f = 1u32;
    while f < MAX_FAN && u64::from(4 * f * f) * u64::from(LEAF_TRIANGLES) <= u64::from(triangles) {
        f *= 2;
    }
    f
}

/// Whether BLAS `r` gets boxes: a triangle BLAS with geometry (what a streamer streams).
pub fn has_boxes(r: &BlasRecord) -> bool {
    r.kind == BLAS_TRIANGLES && r.item_count > 0
}

/// Boxes of a BLAS whose fan is `fan`: `fan` top boxes and `fan` leaves each.
pub fn box_count(fan: u32) -> usize {
    (fan + fan * fan) as usize
}

/// Appends the centroid and box of every triangle of one mesh (`indices` in threes) whose
/// indices reach a position (an index out of range is skipped: the build reports it).
pub fn push_triangle_boxes(positions: &[[f32; 3]], indices: &[u32], out: &mut Vec<TriangleBox>) {
    for t in indices.chunks_exact(3) {
        if let Some(bx) = triangle_box(positions, t) {
            out.push((centre(&bx), bx));
        }
    }
}

/// A BLAS's boxes ([`box_count`] of `fan`) from its triangles ([`push_triangle_boxes`] over
/// its geometries in order): `fan` top boxes then `fan` leaves per top box, in BLAS space,
/// padded. The same boxes as [`boxes_from_meshes`] makes from the meshes themselves.
pub fn boxes_from_triangles(tris: &[TriangleBox], fan: usize) -> Vec<Box6> {
    let mut bounds = EMPTY;
    let keys: Vec<SplitKey> = tris
        .iter()
        .enumerate()
        .map(|(i, t)| {
            grow(&mut bounds, &t.0, &t.0);
            SplitKey(t.0, i as u32)
        })
        .collect();
    let leaf_of = leaves_of_keys(keys, bounds, fan, tris.len());
    let mut leaf_boxes = vec![EMPTY; fan * fan];
    for (t, &l) in tris.iter().zip(&leaf_of) {
        if let Some(bx) = leaf_boxes.get_mut(usize::from(l)) {
            grow(bx, &t.1[..3], &t.1[3..]);
        }
    }
    boxes_of_leaves(&leaf_boxes, fan)
}

/// A BLAS's boxes (as [`boxes_from_triangles`]) from its meshes' positions and indices, in
/// geometry order, without a box per triangle in between: each triangle's box is made from
/// its vertices when its key is made and again, front to back, when the leaves grow (two
/// reads of three vertices cost less than writing and reading 36 bytes a triangle, in fresh
/// memory each BLAS).
pub fn boxes_from_meshes(meshes: &[(&[[f32; 3]], &[u32])], fan: usize) -> Vec<Box6> {
    let total: usize = meshes.iter().map(|(_, indices)| indices.len() / 3).sum();
    // A key's `u32` numbers its triangle in the BLAS: a mesh's triangles follow the meshes
    // before it. Written in place (a push's capacity check kept the loop's state in memory);
    // triangles without a box have no key.
    let mut keys = vec![SplitKey([0.0; 3], 0); total];
    let mut made = 0usize;
    let mut first = 0usize;
    for (positions, indices) in meshes {
        each_triangle_box(positions, indices, |t, bx| {
            keys[made] = SplitKey(centre(&bx), (first + t) as u32);
            made += 1;
        });
        first += indices.len() / 3;
    }
    keys.truncate(made);
    let bounds = centroid_bounds(&keys);
    let leaf_of = leaves_of_keys(keys, bounds, fan, total);
    let mut leaf_boxes = vec![EMPTY; fan * fan];
    let mut first = 0usize;
    for (positions, indices) in meshes {
        let count = indices.len() / 3;
        let mine = &leaf_of[first..first + count];
        each_triangle_box(positions, indices, |t, bx| {
            if let Some(leaf) = leaf_boxes.get_mut(usize::from(mine[t])) {
                grow(leaf, &bx[..3], &bx[3..]);
            }
        });
        first += count;
    }
    boxes_of_leaves(&leaf_boxes, fan)
}

/// Calls `f(t, box)` for each triangle `t` of a mesh (`indices` in threes) in order, with the
/// box [`triangle_box`] makes, for those it makes one for. When every index reaches a position
/// (the usual mesh) the box is made without looking for missing vertices: the same grows in
/// the same order from [`EMPTY`], so the same bits.
#[inline(always)]
fn each_triangle_box(positions: &[[f32; 3]], indices: &[u32], mut f: impl FnMut(usize, Box6)) {
    // A max over the indices vectorises; `all` would stop early and not.
    let max_index = indices.iter().fold(0u32, |m, &i| m.max(i));
    if (max_index as usize) < positions.len() {
        for (t, tri) in indices.chunks_exact(3).enumerate() {
            let mut bx = EMPTY;
            for &i in tri {
                let p = &positions[i as usize];
                grow(&mut bx, p, p);
            }
            // All of a triangle's x NaN: no box (as `triangle_box`).
            if bx[0] <= bx[3] {
                f(t, bx);
            }
        }
    } else {
        for (t, tri) in indices.chunks_exact(3).enumerate() {
            if let Some(bx) = triangle_box(positions, tri) {
                f(t, bx);
            }
        }
    }
}

/// A box's centre, the centroid the splits order triangles by.
#[inline(always)]
fn centre(bx: &Box6) -> [f32; 3] {
    std::array::from_fn(|a| 0.5 * (bx[a] + bx[3 + a]))
}

/// The box of a triangle's vertices that lie in `positions` (`None`: none does; the build
/// reports the index).
fn triangle_box(positions: &[[f32; 3]], tri: &[u32]) -> Option<Box6> {
    let mut bx = EMPTY;
    for &i in tri {
        if let Some(p) = positions.get(i as usize) {
            grow(&mut bx, p, p);
        }
    }
    (bx[0] <= bx[3]).then_some(bx)
}

/// Each triangle's leaf (below `fan²`; `u16::MAX`: none, a triangle without a key) from the
/// split keys (`bounds`: their centroids' bounds; a key's `u32` numbers its triangle below
/// `triangles`).
fn leaves_of_keys(mut keys: Vec<SplitKey>, bounds: Box6, fan: usize, triangles: usize) -> Vec<u16> {
    // At most MAX_FAN² = 256 leaves.
    let mut leaf_of = vec![u16::MAX; triangles];
    let mut room = keys.clone();
    let mut leaves = 0;
    split_into(
        &mut keys,
        &mut room,
        2 * fan.trailing_zeros(),
        Some(bounds),
        &mut leaves,
        &mut |l, keys| {
            for k in keys {
                leaf_of[k.1 as usize] = l as u16;
            }
        },
    );
    leaf_of
}

/// The table's boxes from the leaves' (unpadded) boxes, `fan` per top box: a top box is the
/// union of its leaves; non-empty boxes are padded.
fn boxes_of_leaves(leaf_boxes: &[Box6], fan: usize) -> Vec<Box6> {
    let mut out = vec![EMPTY; fan + fan * fan];
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

/// What [`split_with`] reorders: a centroid and the index of its triangle.
#[derive(Clone, Copy, Debug)]
struct SplitKey([f32; 3], u32);

/// Something with a centroid [`split_with`] can order.
trait Centroid {
    fn centroid(&self) -> &[f32; 3];
}

impl Centroid for SplitKey {
    fn centroid(&self) -> &[f32; 3] {
        &self.0
    }
}

impl Centroid for TriangleBox {
    fn centroid(&self) -> &[f32; 3] {
        &self.0
    }
}

/// Positions and indices of a mesh record.
pub type MeshSlices<'a> = (Cow<'a, [[f32; 3]]>, Cow<'a, [u32]>);

/// BLAS `b`'s boxes (fan `fan`) from its meshes, read through `mesh`. A BLAS one of whose
/// meshes cannot be read gets its padded bounds as its only top box and leaf (the build
/// reports the error when a ray needs it).
pub fn blas_boxes<'m, E>(
    view: &HierarchyView<'_>,
    b: usize,
    fan: usize,
    mut mesh: impl FnMut(u32) -> Result<MeshSlices<'m>, E>,
) -> Vec<Box6> {
    let r = &view.blases[b];
    let range = r.item_base as usize..(r.item_base + r.item_count) as usize;
    let mut meshes: Vec<MeshSlices<'m>> = Vec::with_capacity(range.len());
    for g in &view.geometries[range] {
        let Ok(slices) = mesh(g.mesh) else {
            let mut out = vec![EMPTY; fan + fan * fan];
            let bounds = padded(r.bounds_box());
            out[0] = bounds;
            out[fan] = bounds;
            return out;
        };
        meshes.push(slices);
    }
    let borrowed: Vec<(&[[f32; 3]], &[u32])> =
        meshes.iter().map(|(p, i)| (&p[..], &i[..])).collect();
    boxes_from_meshes(&borrowed, fan)
}

/// `b` grown by a little more than float error: a proxy box only has to contain what it
/// stands for, and a flat one (a ground or ocean plane) is otherwise missed by box tests at
/// grazing angles where the triangle itself is hit (a far pixel lost its hit at small budgets,
/// where no neighbour happened to make the BLAS resident).
pub fn padded(b: [f32; 6]) -> [f32; 6] {
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
    // Selects, not `f32::min`/`max`: one instruction each (a NaN bound is passed over either
    // way, as `bx` never holds one).
    for a in 0..3 {
        bx[a] = if lo[a] < bx[a] { lo[a] } else { bx[a] };
        bx[3 + a] = if hi[a] > bx[3 + a] { hi[a] } else { bx[3 + a] };
    }
}

/// [`split_with`]'s splits, the same items in the same leaves in the same order, without
/// copying each range out before partitioning it: the items lie in `a` and `b` is room of the
/// same length; a sampled partition writes from one into the other and the halves go on from
/// where it wrote them (island 0.0127's import spent ~1% of its CPU on those copies). Calls
/// `leaf(j, items)` for each leaf `j` holding items, in order; `next` is the next leaf's number
/// (it ends at the leaf count: `2^depth` more than it started at).
fn split_into<T: Centroid + Copy>(
    a: &mut [T],
    b: &mut [T],
    depth: u32,
    bounds: Option<Box6>,
    next: &mut usize,
    leaf: &mut dyn FnMut(usize, &[T]),
) {
    if depth == 0 || a.len() < 2 {
        leaf(*next, a);
        *next += 1 << depth;
        return;
    }
    let c = bounds.unwrap_or_else(|| centroid_bounds(a));
    let axis = (0..3)
        .max_by(|&x, &y| (c[3 + x] - c[x]).total_cmp(&(c[3 + y] - c[y])))
        .unwrap_or(0);
    let n = a.len();
    let exact = |items: &mut [T]| {
        items.select_nth_unstable_by(n / 2, |x, y| {
            x.centroid()[axis].total_cmp(&y.centroid()[axis])
        });
    };
    // Where the items lie after this level, the room beside them, the split and the halves'
    // sampled bounds.
    let (items, room, mid, halves) = if n > EXACT_MEDIAN_BELOW {
        match sampled_partition_into(a, b, axis) {
            Some((mid, l, r)) => (b, a, mid, [Some(l), Some(r)]),
            // One side took everything (in `b`, as `split_with` leaves it): exact median.
            None => {
                exact(b);
                (b, a, n / 2, [None, None])
            }
        }
    } else {
        exact(a);
        (a, b, n / 2, [None, None])
    };
    let (il, ir) = items.split_at_mut(mid);
    let (rl, rr) = room.split_at_mut(mid);
    split_into(il, rl, depth - 1, halves[0], next, leaf);
    split_into(ir, rr, depth - 1, halves[1], next, leaf);
}

/// [`split_with`] with a scratch buffer of its own.
#[cfg(test)]
fn split<T: Centroid + Copy>(
    tris: &mut [T],
    depth: u32,
    base: usize,
    bounds: Option<Box6>,
    leaves: &mut Vec<Range<usize>>,
) {
    split_with(tris, &mut Vec::new(), depth, base, bounds, leaves);
}

/// Appends `2^depth` leaf ranges (absolute, from `base`) of centroid-median splits along the
/// widest centroid axis, depth first, so leaf `j`'s ancestor `d` levels up is `j >> d`; a range
/// too small to split ends in empty leaves. `bounds` are the centroids' bounds (or `None`: made
/// here); `scratch` holds a range while it is partitioned.
///
/// A range of more than [`EXACT_MEDIAN_BELOW`] items splits at the median of an evenly spaced
/// eighth of its centroids (not the exact median), and its halves choose their axes by the
/// bounds of those sampled centroids: one branch-free pass partitions it, where the exact
/// median took a bounds pass and a selection (two to three passes) per level. The halves'
/// sizes differ by a few percent; the boxes still hold every triangle (all a streamed render
/// needs of them), and on island 0.02 their leaves' area is 10% smaller (all of a run of tied
/// centroids goes to one side).
#[cfg(test)]
fn split_with<T: Centroid + Copy>(
    tris: &mut [T],
    scratch: &mut Vec<T>,
    depth: u32,
    base: usize,
    bounds: Option<Box6>,
    leaves: &mut Vec<Range<usize>>,
) {
    if depth == 0 || tris.len() < 2 {
        leaves.push(base..base + tris.len());
        let end = base + tris.len();
        leaves.extend((1..1usize << depth).map(|_| end..end));
        return;
    }
    let c = bounds.unwrap_or_else(|| centroid_bounds(tris));
    let axis = (0..3)
        .max_by(|&x, &y| (c[3 + x] - c[x]).total_cmp(&(c[3 + y] - c[y])))
        .unwrap_or(0);
    let sampled = if tris.len() > EXACT_MEDIAN_BELOW {
        sampled_partition(tris, scratch, axis)
    } else {
        None
    };
    let (mid, halves) = match sampled {
        Some((mid, l, r)) => (mid, [Some(l), Some(r)]),
        None => {
            let mid = tris.len() / 2;
            tris.select_nth_unstable_by(mid, |x, y| {
                x.centroid()[axis].total_cmp(&y.centroid()[axis])
            });
            (mid, [None, None])
        }
    };
    let (l, r) = tris.split_at_mut(mid);
    split_with(l, scratch, depth - 1, base, halves[0], leaves);
    split_with(r, scratch, depth - 1, base + mid, halves[1], leaves);
}

/// Ranges of at most this many items split at their exact centroid median.
const EXACT_MEDIAN_BELOW: usize = 512;
/// A larger range's pivot is the median of one centroid in this many (at least
/// [`MIN_PIVOT_SAMPLES`]): the halves' sizes then differ by about `3 / sqrt(len)` of the range.
const PIVOT_SAMPLE_STRIDE: usize = 8;
const MIN_PIVOT_SAMPLES: usize = 63;

/// The centroids' bounds, grown in order as [`grow`] grows them (one accumulator per bound, so
/// they stay in registers).
fn centroid_bounds<T: Centroid>(tris: &[T]) -> Box6 {
    let [mut x0, mut y0, mut z0, mut x1, mut y1, mut z1] = EMPTY;
    for t in tris {
        let [x, y, z] = *t.centroid();
        x0 = if x < x0 { x } else { x0 };
        y0 = if y < y0 { y } else { y0 };
        z0 = if z < z0 { z } else { z0 };
        x1 = if x > x1 { x } else { x1 };
        y1 = if y > y1 { y } else { y1 };
        z1 = if z > z1 { z } else { z1 };
    }
    [x0, y0, z0, x1, y1, z1]
}

/// Moves the items whose centroid on `axis` lies below the median of evenly spaced ones
/// ([`PIVOT_SAMPLE_STRIDE`]) before the rest (those after in reverse order); returns the split
/// and the bounds of the sampled centroids on either side (what the halves choose their axis
/// by), or `None` when a side would be empty (ties, NaN: the caller splits at the exact
/// median). Without branches on the data: each item is copied out to `scratch`, then written
/// to its side's next free slot (a select), and only its side's cursor moves.
#[cfg(test)]
fn sampled_partition<T: Centroid + Copy>(
    tris: &mut [T],
    scratch: &mut Vec<T>,
    axis: usize,
) -> Option<(usize, Box6, Box6)> {
    scratch.clear();
    scratch.extend_from_slice(tris);
    sampled_partition_into(scratch, tris, axis)
}

/// [`sampled_partition`] of `src` written into `dst` (as long), `src` left as it was.
fn sampled_partition_into<T: Centroid + Copy>(
    src: &[T],
    dst: &mut [T],
    axis: usize,
) -> Option<(usize, Box6, Box6)> {
    let n = src.len();
    let samples = (n / PIVOT_SAMPLE_STRIDE).max(MIN_PIVOT_SAMPLES).min(n);
    // Item (2i + 1) n / (2 samples) for each sample i, stepped without a division each.
    let den = 2 * samples;
    let (step, step_rem) = ((2 * n) / den, (2 * n) % den);
    let (mut at, mut rem) = (n / den, n % den);
    let mut sample: Vec<[f32; 3]> = Vec::with_capacity(samples);
    for _ in 0..samples {
        sample.push(*src[at].centroid());
        at += step;
        rem += step_rem;
        if rem >= den {
            rem -= den;
            at += 1;
        }
    }
    let (_, &mut pivot, _) =
        sample.select_nth_unstable_by(samples / 2, |x, y| x[axis].total_cmp(&y[axis]));
    let pivot = pivot[axis];
    let mut sides = [EMPTY, EMPTY];
    for c in &sample {
        grow(&mut sides[1 - usize::from(c[axis] < pivot)], c, c);
    }
    // One loop per axis: the axis's coordinate is then a fixed offset in each item.
    let lo = match axis {
        0 => partition_by::<T, 0>(src, dst, pivot),
        1 => partition_by::<T, 1>(src, dst, pivot),
        _ => partition_by::<T, 2>(src, dst, pivot),
    };
    (lo > 0 && lo < n).then_some((lo, sides[0], sides[1]))
}

/// Writes the items of `src` whose centroid on `AXIS` lies below `pivot` to the front of `dst`
/// in order, the rest to its back in reverse order; returns how many went to the front.
fn partition_by<T: Centroid + Copy, const AXIS: usize>(
    src: &[T],
    dst: &mut [T],
    pivot: f32,
) -> usize {
    let (mut lo, mut hi) = (0usize, dst.len());
    for t in src {
        // Before each item lo < hi: slots below lo and from hi on are taken. The item goes to
        // its side's next free slot, chosen without a branch. Not below (NaN included): right.
        let left = t.centroid()[AXIS] < pivot;
        let slot = if left { lo } else { hi - 1 };
        dst[slot] = *t;
        lo += usize::from(left);
        hi -= usize::from(!left);
    }
    lo
}

/// What BLAS `b`'s boxes are made from, hashed: the box maths' constants, its record, its
/// geometry records and their mesh records (where its data lies, its counts and bounds; the
/// data itself is covered by the package's chunk checksums). A stored entry whose hash differs
/// was made for other records and is not used.
pub fn blas_hash(view: &HierarchyView<'_>, b: usize) -> u64 {
    let mut h = xxhash_rust::xxh3::Xxh3::new();
    h.update(HASH_DOMAIN);
    h.update(&LEAF_TRIANGLES.to_le_bytes());
    h.update(&MAX_FAN.to_le_bytes());
    let r = &view.blases[b];
    h.update(bytemuck::bytes_of(r));
    let range = r.item_base as usize..(r.item_base as usize + r.item_count as usize);
    for g in view.geometries.get(range).unwrap_or(&[]) {
        h.update(bytemuck::bytes_of(g));
        if let Some(m) = view.meshes.get(g.mesh as usize) {
            h.update(bytemuck::bytes_of(m));
        }
    }
    h.digest()
}

const HASH_DOMAIN: &[u8] = b"motu-proxy-boxes-blas-v1";

/// The `proxy_boxes` section's first bytes (FORMAT.md): the name and the version. Version 2's
/// large ranges split at sampled medians ([`split_with`]).
pub const SECTION_MAGIC: &[u8; 16] = b"motu pboxes v2\0\0";
/// Version 1's magic (exact medians): its boxes hold their triangles as well, so a package
/// written before reads as it did (its entries are still checked against the records).
pub const SECTION_MAGIC_V1: &[u8; 16] = b"motu pboxes v1\0\0";

/// One BLAS's entry of a stored table: its id, fan, first box, and [`blas_hash`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct StoredEntry {
    pub blas: u32,
    pub fan: u32,
    pub first_box: u64,
    pub hash: u64,
}

/// A package's stored boxes: entries sorted by BLAS id, and the boxes they index.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct StoredProxyBoxes {
    pub entries: Vec<StoredEntry>,
    pub boxes: Vec<Box6>,
}

/// What [`StoredProxyBoxes::boxes_of`] found for a BLAS.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Stored<'a> {
    /// The entry matches the BLAS's records: its boxes.
    Valid(&'a [Box6]),
    /// The table has no entry for the BLAS.
    Absent,
    /// The entry was made for other records (or another fan): not used.
    Stale,
}

impl StoredProxyBoxes {
    /// Adds BLAS `b`'s boxes (ids ascending).
    pub fn push(&mut self, b: u32, fan: u32, hash: u64, boxes: &[Box6]) {
        self.entries.push(StoredEntry {
            blas: b,
            fan,
            first_box: self.boxes.len() as u64,
            hash,
        });
        self.boxes.extend_from_slice(boxes);
    }

    /// BLAS `b`'s stored boxes, checked against `view`'s records ([`blas_hash`]) and the fan
    /// its triangle count gives.
    pub fn boxes_of(&self, view: &HierarchyView<'_>, b: usize) -> Stored<'_> {
        let Ok(i) = self.entries.binary_search_by_key(&(b as u32), |e| e.blas) else {
            return Stored::Absent;
        };
        let e = self.entries[i];
        let f = fan(view.blases[b].primitive_count);
        let start = e.first_box as usize;
        let boxes = start
            .checked_add(box_count(f))
            .and_then(|end| self.boxes.get(start..end));
        match boxes {
            Some(boxes) if e.fan == f && e.hash == blas_hash(view, b) => Stored::Valid(boxes),
            _ => Stored::Stale,
        }
    }
}

/// The section's bytes: [`SECTION_MAGIC`], the entry and box counts (u64 each), the entries
/// (24 bytes each), the boxes (24 bytes each).
pub fn encode_section(t: &StoredProxyBoxes) -> Vec<u8> {
    let mut w = BlobWriter::new(
        SECTION_MAGIC,
        16 + std::mem::size_of_val(&t.entries[..]) + std::mem::size_of_val(&t.boxes[..]),
    );
    w.u64(t.entries.len() as u64)
        .u64(t.boxes.len() as u64)
        .pods(&t.entries)
        .pods(&t.boxes);
    w.finish()
}

/// Reads what [`encode_section`] wrote (or version 1's section, the same layout); `None` for
/// another magic (another version), a cut or long section, entries out of BLAS order or boxes
/// out of range.
pub fn decode_section(bytes: &[u8]) -> Option<StoredProxyBoxes> {
    let mut r = BlobReader::new(bytes, SECTION_MAGIC)
        .or_else(|| BlobReader::new(bytes, SECTION_MAGIC_V1))?;
    let n_entries = usize::try_from(r.u64()?).ok()?;
    let n_boxes = usize::try_from(r.u64()?).ok()?;
    // Counts checked against the bytes before anything is allocated.
    let need = n_entries
        .checked_mul(std::mem::size_of::<StoredEntry>())?
        .checked_add(n_boxes.checked_mul(std::mem::size_of::<Box6>())?)?;
    if need != r.remaining() {
        return None;
    }
    let entries: Vec<StoredEntry> = r.pods(n_entries)?;
    let boxes: Vec<Box6> = r.pods(n_boxes)?;
    r.finish()?;
    let ordered = entries.windows(2).all(|w| w[0].blas < w[1].blas);
    let in_range = entries.iter().all(|e| {
        e.fan <= MAX_FAN
            && (e.first_box as usize)
                .checked_add(box_count(e.fan))
                .is_some_and(|end| end <= boxes.len())
    });
    (ordered && in_range).then_some(StoredProxyBoxes { entries, boxes })
}

#[cfg(test)]
mod tests;
