//! A binary BVH over axis-aligned boxes: binned SAH (16 bins on every axis), built in parallel
//! with rayon over subtrees, stored as one flat node array with siblings adjacent. The same
//! builder serves triangles (mesh BVHs), instances (TLASes) and programmable instances / meshes
//! (BLASes).

use rayon::join;

/// An axis-aligned box; `EMPTY` has `min > max` so unions start from it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Aabb {
    pub min: [f32; 3],
    pub max: [f32; 3],
}

impl Aabb {
    pub const EMPTY: Self = Self {
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
    };

    pub fn new(min: [f32; 3], max: [f32; 3]) -> Self {
        Self { min, max }
    }

    #[inline]
    pub fn is_empty(&self) -> bool {
        !(self.min[0] <= self.max[0] && self.min[1] <= self.max[1] && self.min[2] <= self.max[2])
    }

    #[inline]
    pub fn grow_point(&mut self, p: [f32; 3]) {
        self.min = std::array::from_fn(|a| self.min[a].min(p[a]));
        self.max = std::array::from_fn(|a| self.max[a].max(p[a]));
    }

    #[inline]
    pub fn union(&self, o: &Self) -> Self {
        let mut r = *self;
        for a in 0..3 {
            r.min[a] = r.min[a].min(o.min[a]);
            r.max[a] = r.max[a].max(o.max[a]);
        }
        r
    }

    #[inline]
    pub fn centroid(&self) -> [f32; 3] {
        [
            0.5 * (self.min[0] + self.max[0]),
            0.5 * (self.min[1] + self.max[1]),
            0.5 * (self.min[2] + self.max[2]),
        ]
    }

    /// Half the surface area (the SAH only needs ratios); 0 for an empty box.
    #[inline]
    pub fn half_area(&self) -> f32 {
        if self.is_empty() {
            return 0.0;
        }
        let d = [
            self.max[0] - self.min[0],
            self.max[1] - self.min[1],
            self.max[2] - self.min[2],
        ];
        d[0] * d[1] + d[1] * d[2] + d[2] * d[0]
    }

    /// `true` when `o` lies inside `self` up to `tol` (absolute, per axis).
    pub fn contains(&self, o: &Self, tol: f32) -> bool {
        (0..3).all(|a| o.min[a] >= self.min[a] - tol && o.max[a] <= self.max[a] + tol)
    }

    /// Grows the box by `rel` of its largest coordinate magnitude, so boxes of transformed
    /// corners stay conservative under f32 rounding of the transform.
    pub fn padded(&self, rel: f32) -> Self {
        if self.is_empty() {
            return *self;
        }
        let mag = (0..3)
            .map(|a| self.min[a].abs().max(self.max[a].abs()))
            .fold(0.0f32, f32::max);
        let pad = rel * mag.max(1e-30);
        Self {
            min: [self.min[0] - pad, self.min[1] - pad, self.min[2] - pad],
            max: [self.max[0] + pad, self.max[1] + pad, self.max[2] + pad],
        }
    }

    /// The box of the 8 corners transformed by a row-major 3×4 matrix.
    pub fn transformed(&self, m: &[f32; 12]) -> Self {
        if self.is_empty() {
            return *self;
        }
        let mut r = Self::EMPTY;
        for i in 0..8 {
            let p = [
                if i & 1 == 0 { self.min[0] } else { self.max[0] },
                if i & 2 == 0 { self.min[1] } else { self.max[1] },
                if i & 4 == 0 { self.min[2] } else { self.max[2] },
            ];
            r.grow_point(motu_abi::xform_point(m, p));
        }
        r
    }
}

/// A node: a leaf when `count > 0` (items `order[first .. first + count]`), else an interior
/// node whose children are `nodes[first]` and `nodes[first + 1]`. 32 bytes, bounds as plain
/// `f32` arrays so the slab test vectorises.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C)]
pub struct BvhNode {
    pub min: [f32; 3],
    pub first: u32,
    pub max: [f32; 3],
    pub count: u32,
}

impl BvhNode {
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.count > 0
    }
}

/// A built BVH: `nodes[0]` is the root (absent when there are no items) and `order` maps leaf
/// slots to the caller's item indices.
#[derive(Clone, Debug, Default)]
pub struct Bvh {
    pub nodes: Vec<BvhNode>,
    pub order: Vec<u32>,
}

/// Build settings.
#[derive(Clone, Copy, Debug)]
pub struct BuildParams {
    /// Leaves may hold up to this many items when the SAH prefers it.
    pub max_leaf: usize,
    /// Cost of one node visit relative to one item test.
    pub traversal_cost: f32,
    /// Subtrees with at least this many items are built in parallel (`usize::MAX`: serial).
    pub parallel_threshold: usize,
}

impl Default for BuildParams {
    fn default() -> Self {
        Self {
            max_leaf: 4,
            traversal_cost: 1.0,
            parallel_threshold: 4096,
        }
    }
}

impl BuildParams {
    /// Serial: for builds that run inside `OnceLock::get_or_init` during rendering, where a
    /// rayon worker that steals a job touching the same lock would deadlock.
    pub fn serial(self) -> Self {
        Self {
            parallel_threshold: usize::MAX,
            ..self
        }
    }
}

const BINS: usize = 16;
/// Leaves above this size are split even when the SAH disagrees, so traversal stays bounded.
const MAX_LEAF_HARD: usize = 16;

struct Ctx<'a> {
    boxes: &'a [Aabb],
    centroids: Vec<[f32; 3]>,
    p: BuildParams,
}

impl Bvh {
    /// Builds over `boxes`; empty boxes are left out (an instance of an empty BLAS).
    pub fn build(boxes: &[Aabb], p: BuildParams) -> Self {
        let mut order: Vec<u32> = (0..boxes.len() as u32)
            .filter(|&i| !boxes[i as usize].is_empty())
            .collect();
        if order.is_empty() {
            return Self::default();
        }
        let ctx = Ctx {
            boxes,
            centroids: boxes.iter().map(Aabb::centroid).collect(),
            p,
        };
        let nodes = build_par(&ctx, &mut order, 0);
        Self { nodes, order }
    }

    /// Root bounds (`EMPTY` for an empty BVH).
    pub fn bounds(&self) -> Aabb {
        self.nodes
            .first()
            .map_or(Aabb::EMPTY, |n| Aabb::new(n.min, n.max))
    }

    /// Depth of the deepest leaf (1 for a single leaf), for tests and sizing.
    pub fn depth(&self) -> usize {
        fn rec(nodes: &[BvhNode], i: usize) -> usize {
            let n = nodes[i];
            if n.is_leaf() {
                1
            } else {
                1 + rec(nodes, n.first as usize).max(rec(nodes, n.first as usize + 1))
            }
        }
        if self.nodes.is_empty() {
            0
        } else {
            rec(&self.nodes, 0)
        }
    }
}

fn range_bounds(ctx: &Ctx<'_>, idx: &[u32]) -> (Aabb, Aabb) {
    let mut b = Aabb::EMPTY;
    let mut c = Aabb::EMPTY;
    for &i in idx {
        b = b.union(&ctx.boxes[i as usize]);
        c.grow_point(ctx.centroids[i as usize]);
    }
    (b, c)
}

fn leaf(b: &Aabb, first: usize, count: usize) -> BvhNode {
    BvhNode {
        min: b.min,
        first: first as u32,
        max: b.max,
        count: count as u32,
    }
}

/// Decides a split of `idx`: `None` = make a leaf; `Some(mid)` after partitioning in place.
fn split(ctx: &Ctx<'_>, idx: &mut [u32], bounds: &Aabb, cbounds: &Aabb) -> Option<usize> {
    let n = idx.len();
    if n <= 1 {
        return None;
    }
    // Best (cost, axis, bin) over all axes.
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        let (lo, hi) = (cbounds.min[axis], cbounds.max[axis]);
        let extent = hi - lo;
        if extent.partial_cmp(&0.0) != Some(std::cmp::Ordering::Greater) {
            continue;
        }
        let scale = BINS as f32 / extent;
        let mut bin_box = [Aabb::EMPTY; BINS];
        let mut bin_count = [0usize; BINS];
        for &i in idx.iter() {
            let c = ctx.centroids[i as usize][axis];
            let b = (((c - lo) * scale) as usize).min(BINS - 1);
            bin_count[b] += 1;
            bin_box[b] = bin_box[b].union(&ctx.boxes[i as usize]);
        }
        // Sweep from the right to get suffix areas, then from the left.
        let mut right_area = [0.0f32; BINS];
        let mut acc = Aabb::EMPTY;
        for b in (1..BINS).rev() {
            acc = acc.union(&bin_box[b]);
            right_area[b] = acc.half_area();
        }
        let mut left = Aabb::EMPTY;
        let mut left_n = 0usize;
        for b in 0..BINS - 1 {
            left = left.union(&bin_box[b]);
            left_n += bin_count[b];
            let right_n = n - left_n;
            if left_n == 0 || right_n == 0 {
                continue;
            }
            let cost = left.half_area() * left_n as f32 + right_area[b + 1] * right_n as f32;
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, b));
            }
        }
    }
    let area = bounds.half_area().max(1e-30);
    match best {
        Some((cost, axis, bin)) => {
            let split_cost = ctx.p.traversal_cost + cost / area;
            if n <= ctx.p.max_leaf && split_cost >= n as f32 {
                return None;
            }
            let lo = cbounds.min[axis];
            let scale = BINS as f32 / (cbounds.max[axis] - lo);
            let mid = partition(idx, |i| {
                let c = ctx.centroids[i as usize][axis];
                (((c - lo) * scale) as usize).min(BINS - 1) <= bin
            });
            Some(mid)
        }
        // Every centroid coincides: no plane separates them, split by count if too many.
        None if n > MAX_LEAF_HARD.max(ctx.p.max_leaf) => Some(n / 2),
        None => None,
    }
}

fn partition(idx: &mut [u32], left: impl Fn(u32) -> bool) -> usize {
    let mut mid = 0;
    for j in 0..idx.len() {
        if left(idx[j]) {
            idx.swap(mid, j);
            mid += 1;
        }
    }
    mid
}

/// Builds the subtree of `idx` (whose first item is `order[first]`) into `nodes`, writing its
/// root at `nodes[at]`.
fn build_serial(ctx: &Ctx<'_>, idx: &mut [u32], first: usize, at: usize, nodes: &mut Vec<BvhNode>) {
    let (b, c) = range_bounds(ctx, idx);
    match split(ctx, idx, &b, &c) {
        None => nodes[at] = leaf(&b, first, idx.len()),
        Some(mid) => {
            let children = nodes.len();
            nodes.push(BvhNode::default());
            nodes.push(BvhNode::default());
            nodes[at] = BvhNode {
                min: b.min,
                first: children as u32,
                max: b.max,
                count: 0,
            };
            let (l, r) = idx.split_at_mut(mid);
            build_serial(ctx, l, first, children, nodes);
            build_serial(ctx, r, first + mid, children + 1, nodes);
        }
    }
}

/// Returns the subtree's nodes with its root at index 0 and child links local to the vector.
fn build_par(ctx: &Ctx<'_>, idx: &mut [u32], first: usize) -> Vec<BvhNode> {
    if idx.len() < ctx.p.parallel_threshold {
        let mut nodes = Vec::with_capacity(2 * idx.len().div_ceil(2));
        nodes.push(BvhNode::default());
        build_serial(ctx, idx, first, 0, &mut nodes);
        return nodes;
    }
    let (b, c) = range_bounds(ctx, idx);
    let Some(mid) = split(ctx, idx, &b, &c) else {
        return vec![leaf(&b, first, idx.len())];
    };
    let (l, r) = idx.split_at_mut(mid);
    let (ln, rn) = join(
        || build_par(ctx, l, first),
        || build_par(ctx, r, first + mid),
    );
    // Layout: [root, left root, right root, left rest.., right rest..].
    let mut nodes = Vec::with_capacity(1 + ln.len() + rn.len());
    nodes.push(BvhNode {
        min: b.min,
        first: 1,
        max: b.max,
        count: 0,
    });
    let relink = |n: BvhNode, shift: usize| {
        if n.is_leaf() {
            n
        } else {
            BvhNode {
                first: n.first + shift as u32,
                ..n
            }
        }
    };
    // Left node i ≥ 1 lands at i + 2, right node i ≥ 1 at i + ln.len() + 1.
    let (ls, rs) = (2, ln.len() + 1);
    nodes.push(relink(ln[0], ls));
    nodes.push(relink(rn[0], rs));
    nodes.extend(ln[1..].iter().map(|&n| relink(n, ls)));
    nodes.extend(rn[1..].iter().map(|&n| relink(n, rs)));
    nodes
}

#[cfg(test)]
mod tests;
