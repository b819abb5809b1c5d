//! Median partitioning for TLAS and AABB-BLAS splits. Each step splits a range at its middle
//! *index* after `select_nth_unstable_by` along the largest axis of the centres' bounds (O(n)
//! per step), so both halves are strictly smaller: it terminates on any input, coincident or
//! NaN centres included (the thesis's position-median split looped forever on those).

/// Partitions `items` in place into consecutive ranges of at most `cap` items (`cap ≥ 1`),
/// appended to `out` as `(begin, end)` in spatial order (left half before right half).
pub(crate) fn median_partition<T>(
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

#[cfg(test)]
mod tests {
    use super::*;

    fn check(items: &mut [[f32; 3]], cap: usize) -> Vec<(usize, usize)> {
        let before: Vec<[u32; 3]> = items.iter().map(|c| c.map(f32::to_bits)).collect();
        let mut out = Vec::new();
        median_partition(items, |c| *c, cap, &mut out);
        // Covers every item exactly once, contiguously, each range within the cap.
        let mut next = 0;
        for &(a, b) in &out {
            assert_eq!(a, next);
            assert!(b > a && b - a <= cap, "{a}..{b} over {cap}");
            next = b;
        }
        assert_eq!(next, items.len());
        let mut after: Vec<[u32; 3]> = items.iter().map(|c| c.map(f32::to_bits)).collect();
        let mut before = before;
        before.sort_unstable();
        after.sort_unstable();
        assert_eq!(before, after, "a permutation");
        out
    }

    #[test]
    fn splits_spatially_at_the_median() {
        let mut items: Vec<[f32; 3]> = (0..100).rev().map(|i| [i as f32, 0.0, 0.5]).collect();
        let out = check(&mut items, 50);
        assert_eq!(out, vec![(0, 50), (50, 100)]);
        assert!(items[..50].iter().all(|c| c[0] < 50.0));
    }

    #[test]
    fn coincident_and_nan_centres_terminate() {
        let mut same = vec![[1.0f32, 2.0, 3.0]; 1000];
        assert!(check(&mut same, 7).len() >= 1000 / 7);
        let mut nan = vec![[f32::NAN; 3]; 33];
        check(&mut nan, 2);
        let mut mixed: Vec<[f32; 3]> = (0..50)
            .map(|i| {
                if i % 3 == 0 {
                    [f32::INFINITY, 0.0, 0.0]
                } else {
                    [i as f32, 0.0, 0.0]
                }
            })
            .collect();
        check(&mut mixed, 4);
        check(&mut [], 3);
    }
}
