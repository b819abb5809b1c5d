//! The proxy-box routines as main had them before the cheaper passes (session 51), kept to
//! assert that the new ones make the same boxes bit for bit: a key pass that pushed and grew
//! the bounds as it went, a second pass through a callback, sample positions by division and a
//! partition that wrote each item to both sides' next free slots.

use super::super::{
    grow, padded, Box6, Centroid, SplitKey, EMPTY, EXACT_MEDIAN_BELOW, MIN_PIVOT_SAMPLES,
    PIVOT_SAMPLE_STRIDE,
};

pub(super) fn boxes_from_meshes(meshes: &[(&[[f32; 3]], &[u32])], fan: usize) -> Vec<Box6> {
    // Each mesh's first triangle in the BLAS's numbering (a key's `u32`).
    let mut starts = Vec::with_capacity(meshes.len() + 1);
    let mut total = 0usize;
    for (_, indices) in meshes {
        starts.push(total);
        total += indices.len() / 3;
    }
    starts.push(total);
    let mut bounds = EMPTY;
    let mut keys: Vec<SplitKey> = Vec::with_capacity(total);
    for (m, (positions, indices)) in meshes.iter().enumerate() {
        for (t, tri) in indices.chunks_exact(3).enumerate() {
            if let Some(bx) = triangle_box(positions, tri) {
                let c = std::array::from_fn(|a| 0.5 * (bx[a] + bx[3 + a]));
                grow(&mut bounds, &c, &c);
                keys.push(SplitKey(c, (starts[m] + t) as u32));
            }
        }
    }
    boxes_from_keys(keys, bounds, fan, total, |grow_leaf| {
        for (m, (positions, indices)) in meshes.iter().enumerate() {
            for (t, tri) in indices.chunks_exact(3).enumerate() {
                if let Some(bx) = triangle_box(positions, tri) {
                    grow_leaf(starts[m] + t, &bx);
                }
            }
        }
    })
}

fn triangle_box(positions: &[[f32; 3]], tri: &[u32]) -> Option<Box6> {
    let mut bx = EMPTY;
    for &i in tri {
        if let Some(p) = positions.get(i as usize) {
            grow(&mut bx, p, p);
        }
    }
    (bx[0] <= bx[3]).then_some(bx)
}

fn boxes_from_keys(
    mut keys: Vec<SplitKey>,
    bounds: Box6,
    fan: usize,
    triangles: usize,
    each_box: impl FnOnce(&mut dyn FnMut(usize, &Box6)),
) -> Vec<Box6> {
    let mut out = vec![EMPTY; fan + fan * fan];
    // Each triangle's leaf (at most MAX_FAN² = 256 leaves; `u16::MAX`: none).
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
    drop(keys);
    drop(room);
    // A top box is the union of its leaves.
    let mut leaf_boxes = vec![EMPTY; leaves];
    each_box(&mut |i, t| {
        if let Some(bx) = leaf_of
            .get(i)
            .and_then(|&l| leaf_boxes.get_mut(usize::from(l)))
        {
            grow(bx, &t[..3], &t[3..]);
        }
    });
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

fn centroid_bounds<T: Centroid>(tris: &[T]) -> Box6 {
    let mut c = EMPTY;
    for t in tris {
        grow(&mut c, t.centroid(), t.centroid());
    }
    c
}

pub(super) fn sampled_partition_into<T: Centroid + Copy>(
    src: &[T],
    dst: &mut [T],
    axis: usize,
) -> Option<(usize, Box6, Box6)> {
    let n = src.len();
    let samples = (n / PIVOT_SAMPLE_STRIDE).max(MIN_PIVOT_SAMPLES).min(n);
    let mut sample: Vec<[f32; 3]> = (0..samples)
        .map(|i| *src[(2 * i + 1) * n / (2 * samples)].centroid())
        .collect();
    let (_, &mut pivot, _) =
        sample.select_nth_unstable_by(samples / 2, |x, y| x[axis].total_cmp(&y[axis]));
    let pivot = pivot[axis];
    let mut sides = [EMPTY, EMPTY];
    for c in &sample {
        grow(&mut sides[1 - usize::from(c[axis] < pivot)], c, c);
    }
    let (mut lo, mut hi) = (0usize, n);
    for t in src {
        // Before each item lo < hi: slots below lo and from hi on are taken.
        // Not below (NaN included): right.
        let right = 1 - usize::from(t.centroid()[axis] < pivot);
        dst[lo] = *t;
        dst[hi - 1] = *t;
        lo += 1 - right;
        hi -= right;
    }
    (lo > 0 && lo < n).then_some((lo, sides[0], sides[1]))
}
