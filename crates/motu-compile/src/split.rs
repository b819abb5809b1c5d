//! Partitioning for TLAS and AABB-BLAS splits.
//!
//! [`median_partition`] (AABB BLASes) splits a range at its middle *index* after
//! `select_nth_unstable_by` along the largest axis of the centres' bounds (O(n) per step), so
//! both halves are strictly smaller: it terminates on any input, coincident or NaN centres
//! included (the thesis's position-median split looped forever on those).
//!
//! [`sah_partition`] (TLAS splits) picks each split by a binned surface-area heuristic over the
//! items' *bounds*, so pieces overlap as little as the data allows: a ray pays one trace per
//! piece it enters, and median splits of centres made pieces whose boxes overlapped wherever
//! large instances straddled the median (issue 15: 4.4 traces/ray on a split island).

pub(crate) use crate::instance_table::Pages;

/// Partitions `items` in place into consecutive ranges of at most `cap` items (`cap ≥ 1`),
/// appended to `out` as `(begin, end)` in spatial order (left half before right half).
pub(crate) fn median_partition<T: Send>(
    items: &mut [T],
    centre: impl Fn(&T) -> [f32; 3] + Sync,
    cap: usize,
    out: &mut Vec<(usize, usize)>,
) {
    out.extend(median_ranges(items, &centre, cap.max(1), 0));
}

/// [`median_partition`] of a range that starts at `offset` in the whole: its ranges, in order.
/// Ranges of at least `PARALLEL_ITEMS` items are split, then their halves partitioned on two
/// threads (the same ranges as serially: each step depends on its range alone).
fn median_ranges<T: Send>(
    items: &mut [T],
    centre: &(impl Fn(&T) -> [f32; 3] + Sync),
    cap: usize,
    offset: usize,
) -> Vec<(usize, usize)> {
    let len = items.len();
    if len >= PARALLEL_ITEMS && len > cap {
        let mid = median_split(items, centre);
        let (left_items, right_items) = items.split_at_mut(mid);
        let (mut left, right) = rayon::join(
            || median_ranges(left_items, centre, cap, offset),
            || median_ranges(right_items, centre, cap, offset + mid),
        );
        left.extend(right);
        return left;
    }
    serial_ranges(len, cap, offset, |begin, end| {
        median_split(&mut items[begin..end], centre)
    })
}

/// The ranges of at most `cap` items that halving `0..len` leaves, in order, moved by
/// `offset`: `split(begin, end)` partitions `begin..end` and returns where its right half
/// starts (from `begin`).
fn serial_ranges(
    len: usize,
    cap: usize,
    offset: usize,
    mut split: impl FnMut(usize, usize) -> usize,
) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut stack = vec![(0usize, len)];
    while let Some((begin, end)) = stack.pop() {
        if end - begin <= cap {
            if end > begin {
                out.push((offset + begin, offset + end));
            }
            continue;
        }
        let mid = begin + split(begin, end);
        // Right first so the left half is popped (and emitted) first.
        stack.push((mid, end));
        stack.push((begin, mid));
    }
    out
}

/// One step of [`median_partition`]: the median along the largest axis of the centres moved
/// to `len / 2`, smaller before it; returns `len / 2`.
fn median_split<T>(slice: &mut [T], centre: &impl Fn(&T) -> [f32; 3]) -> usize {
    let len = slice.len();
    let (lo, hi) = centre_bounds(slice, centre);
    let extent: [f32; 3] = std::array::from_fn(|k| hi[k] - lo[k]);
    let axis = (0..3)
        .filter(|&k| extent[k].is_finite())
        .max_by(|&a, &b| extent[a].total_cmp(&extent[b]))
        .unwrap_or(0);
    let mid = len / 2;
    // All centres equal (or none finite): an object-median split by index.
    if extent[axis] > 0.0 {
        slice.select_nth_unstable_by(mid, |a, b| centre(a)[axis].total_cmp(&centre(b)[axis]));
    }
    mid
}

/// The bounds of the centres of `items` (NaN passed over), as `f32::min`/`max` folds make them
/// but with selects: one `minss`/`maxss` each instead of a NaN test, blend and min (the bounds
/// pass was a third of a median step's instructions when cutting meshes at import). The result
/// can differ from the folds only in the sign of a zero bound, which no caller can see: an
/// extent `hi - lo` is the same number either way unless it is zero, and a zero extent is
/// never split along.
fn centre_bounds<T>(items: &[T], centre: &impl Fn(&T) -> [f32; 3]) -> ([f32; 3], [f32; 3]) {
    let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    for item in items {
        let c = centre(item);
        for k in 0..3 {
            // A NaN compares false and is passed over, as `f32::min`/`max` pass it over.
            lo[k] = if c[k] < lo[k] { c[k] } else { lo[k] };
            hi[k] = if c[k] > hi[k] { c[k] } else { hi[k] };
        }
    }
    (lo, hi)
}

/// Bins per axis of [`sah_partition`].
pub(crate) const SAH_BINS: usize = 32;
/// Neither side of a SAH split may hold fewer than this fraction of the range's items: keeps
/// the piece count within a small factor of the minimum (`n / cap`) when SAH would rather
/// peel off a few items at a time.
pub(crate) const SAH_MIN_SIDE_FRACTION: usize = 8;

pub(crate) fn surface_area(min: [f32; 3], max: [f32; 3]) -> f32 {
    let d: [f32; 3] = std::array::from_fn(|k| (max[k] - min[k]).max(0.0));
    let a = 2.0 * (d[0] * d[1] + d[1] * d[2] + d[2] * d[0]);
    if a.is_finite() {
        a
    } else {
        f32::MAX
    }
}

#[derive(Clone, Copy)]
pub(crate) struct Bin {
    pub min: [f32; 3],
    pub max: [f32; 3],
    pub count: usize,
}

impl Bin {
    pub const EMPTY: Self = Self {
        min: [f32::INFINITY; 3],
        max: [f32::NEG_INFINITY; 3],
        count: 0,
    };

    pub fn grow(&mut self, min: [f32; 3], max: [f32; 3], count: usize) {
        for k in 0..3 {
            self.min[k] = self.min[k].min(min[k]);
            self.max[k] = self.max[k].max(max[k]);
        }
        self.count += count;
    }
}

/// An item's bounds, `(min, max)`.
pub(crate) type Bounds = ([f32; 3], [f32; 3]);

/// Ranges of at least this many items are split with their halves partitioned on two threads
/// and their bins filled in parallel chunks (rayon); smaller ones serially. Either way the
/// ranges are the same: a step's split depends on its range alone, and bins merge exactly
/// (minima, maxima, counts).
pub(crate) const PARALLEL_ITEMS: usize = 1 << 16;

/// Items a partition's pass over mapped arrays walks between two releases of the pages behind
/// it (768 KiB of bounds).
pub(crate) const RELEASE_ITEMS: usize = 1 << 15;

/// Partitions `items` (with `bounds[i]` = `(min, max)` of `items[i]`, permuted alongside) in
/// place into consecutive ranges of at most `cap` items (`cap ≥ 1`), appended to `out` as
/// `(begin, end)` in spatial order. Each step takes the binned-SAH split (area × count of both
/// sides, centroids binned along each axis) among those leaving at least 1/8 of the items on
/// either side; when no axis offers one (coincident or non-finite centroids) it splits at the
/// middle index, so every step shrinks both sides and the partition always terminates. Large
/// ranges are split in parallel (`PARALLEL_ITEMS`): a streamer splits a Moana-sized root
/// (tens of millions of instances) when it loads the package.
pub fn sah_partition<T: Send + bytemuck::Zeroable>(
    items: &mut [T],
    bounds: &mut [Bounds],
    cap: usize,
    out: &mut Vec<(usize, usize)>,
) {
    sah_partition_paged(items, bounds, cap, out, Pages::HEAP);
}

/// [`sah_partition`] of arrays in `pages` (the same ranges; mapped arrays' pages released
/// behind each pass).
pub(crate) fn sah_partition_paged<T: Send + bytemuck::Zeroable>(
    items: &mut [T],
    bounds: &mut [Bounds],
    cap: usize,
    out: &mut Vec<(usize, usize)>,
    pages: Pages,
) {
    assert_eq!(items.len(), bounds.len());
    out.extend(sah_ranges(items, bounds, cap.max(1), 0, pages));
}

/// [`sah_partition`] of a range that starts at `offset` in the whole: its ranges, in order.
fn sah_ranges<T: Send + bytemuck::Zeroable>(
    items: &mut [T],
    bounds: &mut [Bounds],
    cap: usize,
    offset: usize,
    pages: Pages,
) -> Vec<(usize, usize)> {
    let len = items.len();
    if len <= cap {
        return if len > 0 {
            vec![(offset, offset + len)]
        } else {
            Vec::new()
        };
    }
    if len < PARALLEL_ITEMS {
        let out = serial_ranges(len, cap, offset, |begin, end| {
            sah_split(&mut items[begin..end], &mut bounds[begin..end], Pages::HEAP)
        });
        pages.release(items);
        pages.release(bounds);
        return out;
    }
    let mid = sah_split(items, bounds, pages);
    let (left_items, right_items) = items.split_at_mut(mid);
    let (left_bounds, right_bounds) = bounds.split_at_mut(mid);
    let (mut left, right) = rayon::join(
        || sah_ranges(left_items, left_bounds, cap, offset, pages),
        || sah_ranges(right_items, right_bounds, cap, offset + mid, pages),
    );
    left.extend(right);
    left
}

pub(crate) fn centroid(b: &Bounds, k: usize) -> f32 {
    0.5 * (b.0[k] + b.1[k])
}

/// The finite centroids' bounds of `bs`, per axis (`lo`, `hi`).
#[cfg(test)]
pub(crate) fn centroid_bounds(bs: &[Bounds]) -> ([f32; 3], [f32; 3]) {
    centroid_bounds_paged(bs, Pages::HEAP)
}

/// `centroid_bounds` of bounds in `pages` (released behind the pass).
fn centroid_bounds_paged(bs: &[Bounds], pages: Pages) -> ([f32; 3], [f32; 3]) {
    let fold = |(mut lo, mut hi): ([f32; 3], [f32; 3]), b: &Bounds| {
        for k in 0..3 {
            let c = centroid(b, k);
            if c.is_finite() {
                lo[k] = lo[k].min(c);
                hi[k] = hi[k].max(c);
            }
        }
        (lo, hi)
    };
    let empty = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
    if bs.len() < PARALLEL_ITEMS {
        return bs.iter().fold(empty, fold);
    }
    use rayon::prelude::*;
    bs.par_chunks(PARALLEL_ITEMS / 4)
        .map(|c| {
            let folded = c.iter().fold(empty, fold);
            pages.release(c);
            folded
        })
        .reduce(
            || empty,
            |(a_lo, a_hi), (b_lo, b_hi)| {
                (
                    std::array::from_fn(|k| a_lo[k].min(b_lo[k])),
                    std::array::from_fn(|k| a_hi[k].max(b_hi[k])),
                )
            },
        )
}

/// The SAH bins of `bs` along every axis in `axes` (`bin_of(b, axis)` gives an item's bin),
/// filled in one pass over the items (the other axes' bins stay empty).
fn fill_bins(
    bs: &[Bounds],
    axes: [bool; 3],
    bin_of: impl Fn(&Bounds, usize) -> usize + Sync,
    pages: Pages,
) -> [[Bin; SAH_BINS]; 3] {
    // A loop over arrays in place (a fold moving the 32 bins per item took twice the time).
    let fill = |chunk: &[Bounds]| {
        let mut bins = [[Bin::EMPTY; SAH_BINS]; 3];
        for b in chunk {
            for (axis, bins) in bins.iter_mut().enumerate() {
                if axes[axis] {
                    bins[bin_of(b, axis)].grow(b.0, b.1, 1);
                }
            }
        }
        bins
    };
    if bs.len() < PARALLEL_ITEMS {
        return fill(bs);
    }
    use rayon::prelude::*;
    let fill_released = |chunk: &[Bounds]| {
        let bins = fill(chunk);
        pages.release(chunk);
        bins
    };
    bs.par_chunks(PARALLEL_ITEMS / 4).map(fill_released).reduce(
        || [[Bin::EMPTY; SAH_BINS]; 3],
        |mut a, b| {
            for (xa, ya) in a.iter_mut().zip(&b) {
                for (x, y) in xa.iter_mut().zip(ya) {
                    x.grow(y.min, y.max, y.count);
                }
            }
            a
        },
    )
}

/// One step of [`sah_partition`] over a range of more than `cap` items: reorders `items` and
/// `bounds` so the split's left side comes first and returns its length (`0 < mid < len`).
fn sah_split<T: bytemuck::Zeroable>(items: &mut [T], bounds: &mut [Bounds], pages: Pages) -> usize {
    let len = items.len();
    let (lo, hi) = centroid_bounds_paged(bounds, pages);
    let min_side = (len / SAH_MIN_SIDE_FRACTION).max(1);
    let axes: [bool; 3] = std::array::from_fn(|k| {
        let extent = hi[k] - lo[k];
        extent > 0.0 && extent.is_finite()
    });
    let scale: [f32; 3] = std::array::from_fn(|k| SAH_BINS as f32 / (hi[k] - lo[k]));
    // NaN and out-of-range centroids clamp (a saturating cast), so every item has a bin.
    let bin_of = |b: &Bounds, axis: usize| {
        (((centroid(b, axis) - lo[axis]) * scale[axis]) as usize).min(SAH_BINS - 1)
    };
    let all_bins = fill_bins(bounds, axes, bin_of, pages);
    // (cost, axis, first bin of the right side)
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in (0..3).filter(|&k| axes[k]) {
        let bins = &all_bins[axis];
        let mut right = [Bin::EMPTY; SAH_BINS];
        let mut acc = Bin::EMPTY;
        for i in (1..SAH_BINS).rev() {
            acc.grow(bins[i].min, bins[i].max, bins[i].count);
            right[i] = acc;
        }
        let mut left = Bin::EMPTY;
        for i in 1..SAH_BINS {
            left.grow(bins[i - 1].min, bins[i - 1].max, bins[i - 1].count);
            // Past an empty bin the sides are those of the candidate before, whose cost (the
            // same floats) this one could not beat: only the areas are skipped.
            if bins[i - 1].count == 0 {
                continue;
            }
            let r = &right[i];
            if left.count < min_side || r.count < min_side {
                continue;
            }
            let cost = surface_area(left.min, left.max) * left.count as f32
                + surface_area(r.min, r.max) * r.count as f32;
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, i));
            }
        }
    }
    let Some((_, axis, split)) = best else {
        return len / 2;
    };
    // Hoare-style partition of both arrays: bins < split to the left. The items behind `i`
    // and past `j` are in place: mapped pages there are released as the ends move.
    let (mut i, mut j) = (0, len);
    let (mut i_released, mut j_released) = (0, len);
    while i < j {
        if bin_of(&bounds[i], axis) < split {
            i += 1;
            if i - i_released >= RELEASE_ITEMS {
                pages.release(&items[i_released..i]);
                pages.release(&bounds[i_released..i]);
                i_released = i;
            }
        } else {
            j -= 1;
            items.swap(i, j);
            bounds.swap(i, j);
            if j_released - j >= RELEASE_ITEMS {
                pages.release(&items[j..j_released]);
                pages.release(&bounds[j..j_released]);
                j_released = j;
            }
        }
    }
    pages.release(&items[i_released..j_released]);
    pages.release(&bounds[i_released..j_released]);
    i
}

/// Leaves [`split_keeping_direct`] cuts a range into (at most the cap each) before choosing
/// what stays direct. Few and coarse: every piece is a box the root's traversal must test and
/// report. On the H100 (4.16M-instance island, 2M cap) 4 leaves rendered in 6.11 ms, 16 in
/// 6.38, 64 in 6.48 and the split without a kept part in 6.71, although 64 took the fewest
/// traces per ray (1.42 against 1.63 for 4); on the default island at a 5000 cap 4 leaves
/// left 2.06 traces per ray against 1.57 for 8, so 8 (not timed on the device).
const DIRECT_LEAVES: usize = 8;

/// Splits `items` (bounds alongside, as in [`sah_partition`]) for a TLAS that keeps part of
/// its content itself: a binned SAH cuts them into a few spatially compact leaves (each of
/// at most `cap`), and the leaves with the smallest box area per item (the densest) become
/// pieces until what is left fits `room(pieces)`, the items the TLAS can keep beside the
/// instances of `pieces` pieces. Rays then pay a second trace only where they enter a dense
/// piece's box (and the area of those boxes is what the choice keeps small), instead of
/// wherever they reach any piece. Reorders `items` to pieces first (appended to `out` as
/// consecutive ranges in spatial order), then the kept items; returns the count kept, which
/// is 0 when even no kept item leaves enough room.
#[cfg(test)]
pub fn split_keeping_direct<T: Copy + Send + bytemuck::Zeroable>(
    items: &mut [T],
    bounds: &mut [Bounds],
    cap: usize,
    room: impl Fn(usize) -> usize,
    out: &mut Vec<(usize, usize)>,
) -> usize {
    split_keeping_direct_paged(items, bounds, cap, room, out, Pages::HEAP, None)
}

/// Arrays as long as a partition's items and bounds, that [`split_keeping_direct_paged`] moves
/// them through instead of permuting them in place.
pub(crate) type Scratch<'a, T> = (&'a mut [T], &'a mut [Bounds]);

/// `split_keeping_direct` of arrays in `pages` (the same split and order): with `scratch`
/// the pieces and kept leaves are copied out in their new order and back, two sequential
/// passes that release their pages behind them (mapped arrays), where the in-place permutation
/// would touch them all at once (and hold 5 bytes an item of its own).
pub(crate) fn split_keeping_direct_paged<T: Copy + Send + bytemuck::Zeroable>(
    items: &mut [T],
    bounds: &mut [Bounds],
    cap: usize,
    room: impl Fn(usize) -> usize,
    out: &mut Vec<(usize, usize)>,
    pages: Pages,
    scratch: Option<Scratch<'_, T>>,
) -> usize {
    assert_eq!(items.len(), bounds.len());
    let n = items.len();
    let mut leaves = Vec::new();
    sah_partition_paged(
        items,
        bounds,
        n.div_ceil(DIRECT_LEAVES).clamp(1, cap.max(1)),
        &mut leaves,
        pages,
    );
    let area_per_item: Vec<f32> = leaves
        .iter()
        .map(|&(a, b)| {
            let mut bin = Bin::EMPTY;
            for (k, bb) in bounds[a..b].iter().enumerate() {
                bin.grow(bb.0, bb.1, 1);
                if (k + 1) % RELEASE_ITEMS == 0 {
                    pages.release(&bounds[a + k + 1 - RELEASE_ITEMS..a + k + 1]);
                }
            }
            pages.release(&bounds[a + (b - a) / RELEASE_ITEMS * RELEASE_ITEMS..b]);
            let area = surface_area(bin.min, bin.max);
            // Non-finite boxes (NaN, infinite) go last: never worth a piece first.
            if area.is_finite() {
                area / (b - a) as f32
            } else {
                f32::MAX
            }
        })
        .collect();
    let mut densest: Vec<usize> = (0..leaves.len()).collect();
    densest.sort_by(|&x, &y| {
        area_per_item[x]
            .total_cmp(&area_per_item[y])
            .then(x.cmp(&y))
    });
    let mut piece = vec![false; leaves.len()];
    // Ends with what is kept fitting the room, or with every leaf a piece (nothing kept).
    let (mut kept, mut pieces) = (n, 0usize);
    for &l in &densest {
        if kept <= room(pieces) {
            break;
        }
        piece[l] = true;
        kept -= leaves[l].1 - leaves[l].0;
        pieces += 1;
    }
    if let Some((s_items, s_bounds)) = scratch {
        assert!(
            s_items.len() >= n && s_bounds.len() >= n,
            "scratch too short"
        );
        let mut w = 0;
        for want_piece in [true, false] {
            for (l, &(a, b)) in leaves.iter().enumerate() {
                if piece[l] == want_piece {
                    if want_piece {
                        out.push((w, w + b - a));
                    }
                    copy_released(&mut s_items[w..w + b - a], &items[a..b], pages);
                    copy_released(&mut s_bounds[w..w + b - a], &bounds[a..b], pages);
                    w += b - a;
                }
            }
        }
        copy_released(items, &s_items[..n], pages);
        copy_released(bounds, &s_bounds[..n], pages);
        return kept;
    }
    // src[j]: the current index of the item that goes to position j (pieces in leaf order,
    // then the kept leaves).
    let mut src: Vec<u32> = Vec::with_capacity(n);
    for want_piece in [true, false] {
        for (l, &(a, b)) in leaves.iter().enumerate() {
            if piece[l] == want_piece {
                if want_piece {
                    out.push((src.len(), src.len() + b - a));
                }
                src.extend((a..b).map(|i| i as u32));
            }
        }
    }
    // Apply the permutation in place, one cycle at a time.
    let mut done = vec![false; n];
    for start in 0..n {
        if done[start] {
            continue;
        }
        let (item, bound) = (items[start], bounds[start]);
        let mut j = start;
        loop {
            done[j] = true;
            let k = src[j] as usize;
            if k == start {
                items[j] = item;
                bounds[j] = bound;
                break;
            }
            items[j] = items[k];
            bounds[j] = bounds[k];
            j = k;
        }
    }
    kept
}

/// `dst.copy_from_slice(src)` a piece at a time, both sides' pages released behind (mapped).
fn copy_released<U: Copy + bytemuck::Zeroable>(dst: &mut [U], src: &[U], pages: Pages) {
    for (d, s) in dst.chunks_mut(RELEASE_ITEMS).zip(src.chunks(RELEASE_ITEMS)) {
        d.copy_from_slice(s);
        pages.release(d);
        pages.release(s);
    }
}

#[cfg(test)]
mod tests;
