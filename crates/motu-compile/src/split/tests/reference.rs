//! The partitioners as they were before their speed-ups, serial: what `split.rs` must still
//! compute exactly (tests only).

use crate::split::*;

pub(crate) fn median_partition_serial<T>(
    items: &mut [T],
    centre: impl Fn(&T) -> [f32; 3],
    cap: usize,
    out: &mut Vec<(usize, usize)>,
) {
    let cap = cap.max(1);
    let mut stack = vec![(0usize, items.len())];
    while let Some((begin, end)) = stack.pop() {
        let len = end - begin;
        if len <= cap {
            if len > 0 {
                out.push((begin, end));
            }
            continue;
        }
        let slice = &mut items[begin..end];
        let (mut lo, mut hi) = ([f32::INFINITY; 3], [f32::NEG_INFINITY; 3]);
        for item in slice.iter() {
            let c = centre(item);
            for k in 0..3 {
                lo[k] = lo[k].min(c[k]);
                hi[k] = hi[k].max(c[k]);
            }
        }
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
        // Right first so the left half is popped (and emitted) first.
        stack.push((begin + mid, end));
        stack.push((begin, begin + mid));
    }
}

/// The SAH bins of `bs` along `axis` (`bin_of` gives an item's bin).
fn old_fill_bins(bs: &[Bounds], bin_of: impl Fn(&Bounds) -> usize + Sync) -> [Bin; SAH_BINS] {
    // A loop over one array in place (a fold moving the 32 bins per item took twice the time).
    let fill = |chunk: &[Bounds]| {
        let mut bins = [Bin::EMPTY; SAH_BINS];
        for b in chunk {
            bins[bin_of(b)].grow(b.0, b.1, 1);
        }
        bins
    };
    if bs.len() < PARALLEL_ITEMS {
        return fill(bs);
    }
    use rayon::prelude::*;
    bs.par_chunks(PARALLEL_ITEMS / 4).map(fill).reduce(
        || [Bin::EMPTY; SAH_BINS],
        |mut a, b| {
            for (x, y) in a.iter_mut().zip(&b) {
                x.grow(y.min, y.max, y.count);
            }
            a
        },
    )
}

/// One step of [`sah_partition`] over a range of more than `cap` items: reorders `items` and
/// `bounds` so the split's left side comes first and returns its length (`0 < mid < len`).
pub(crate) fn old_sah_split<T>(items: &mut [T], bounds: &mut [Bounds]) -> usize {
    let len = items.len();
    let (lo, hi) = centroid_bounds(bounds);
    let min_side = (len / SAH_MIN_SIDE_FRACTION).max(1);
    // (cost, axis, first bin of the right side)
    let mut best: Option<(f32, usize, usize)> = None;
    for axis in 0..3 {
        let extent = hi[axis] - lo[axis];
        if !(extent > 0.0 && extent.is_finite()) {
            continue;
        }
        let scale = SAH_BINS as f32 / extent;
        // NaN and out-of-range centroids clamp (a saturating cast), so every item has a bin.
        let bins = old_fill_bins(bounds, |b| {
            (((centroid(b, axis) - lo[axis]) * scale) as usize).min(SAH_BINS - 1)
        });
        let mut right = [(0.0f32, 0usize); SAH_BINS];
        let mut acc = Bin::EMPTY;
        for i in (1..SAH_BINS).rev() {
            acc.grow(bins[i].min, bins[i].max, bins[i].count);
            right[i] = (surface_area(acc.min, acc.max), acc.count);
        }
        let mut left = Bin::EMPTY;
        for i in 1..SAH_BINS {
            left.grow(bins[i - 1].min, bins[i - 1].max, bins[i - 1].count);
            let (r_area, r_count) = right[i];
            if left.count < min_side || r_count < min_side {
                continue;
            }
            let cost =
                surface_area(left.min, left.max) * left.count as f32 + r_area * r_count as f32;
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, i));
            }
        }
    }
    let Some((_, axis, split)) = best else {
        return len / 2;
    };
    let scale = SAH_BINS as f32 / (hi[axis] - lo[axis]);
    let bin_of = |b: &Bounds| (((centroid(b, axis) - lo[axis]) * scale) as usize).min(SAH_BINS - 1);
    // Hoare-style partition of both arrays: bins < split to the left.
    let (mut i, mut j) = (0, len);
    while i < j {
        if bin_of(&bounds[i]) < split {
            i += 1;
        } else {
            j -= 1;
            items.swap(i, j);
            bounds.swap(i, j);
        }
    }
    i
}

/// The old `sah_partition`, serial.
pub(crate) fn sah_partition_serial<T>(
    items: &mut [T],
    bounds: &mut [Bounds],
    cap: usize,
    out: &mut Vec<(usize, usize)>,
) {
    let cap = cap.max(1);
    let mut stack = vec![(0usize, items.len())];
    while let Some((begin, end)) = stack.pop() {
        if end - begin <= cap {
            if end > begin {
                out.push((begin, end));
            }
            continue;
        }
        let mid = begin + old_sah_split(&mut items[begin..end], &mut bounds[begin..end]);
        stack.push((mid, end));
        stack.push((begin, mid));
    }
}
