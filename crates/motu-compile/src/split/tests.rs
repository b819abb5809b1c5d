use super::*;

/// The partitioners before their speed-ups, as the reference these tests compare with.
mod reference;

fn check_sah(boxes: &mut [([f32; 3], [f32; 3])], cap: usize) -> Vec<(usize, usize)> {
    let mut ids: Vec<usize> = (0..boxes.len()).collect();
    let before: Vec<_> = boxes.to_vec();
    let mut out = Vec::new();
    sah_partition(&mut ids, boxes, cap, &mut out);
    let mut next = 0;
    for &(a, b) in &out {
        assert_eq!(a, next);
        assert!(b > a && b - a <= cap, "{a}..{b} over {cap}");
        next = b;
    }
    assert_eq!(next, boxes.len());
    // Items and bounds moved together, and it is a permutation.
    for (k, &id) in ids.iter().enumerate() {
        assert_eq!(boxes[k].0.map(f32::to_bits), before[id].0.map(f32::to_bits));
    }
    ids.sort_unstable();
    assert!(ids.iter().enumerate().all(|(k, &id)| k == id));
    out
}

#[test]
fn sah_separates_clusters_and_terminates_on_degenerate_input() {
    // Two clusters of unit boxes, far apart, uneven counts: the split falls between them.
    let mut boxes: Vec<([f32; 3], [f32; 3])> = (0..300)
        .map(|i| {
            let x = if i < 100 {
                i as f32 * 0.01
            } else {
                1000.0 + i as f32 * 0.01
            };
            ([x, 0.0, 0.0], [x + 1.0, 1.0, 1.0])
        })
        .collect();
    let out = check_sah(&mut boxes, 200);
    assert_eq!(out.len(), 2);
    let xs: Vec<f32> = boxes[out[0].0..out[0].1].iter().map(|b| b.0[0]).collect();
    assert!(xs.iter().all(|&x| x < 500.0) || xs.iter().all(|&x| x > 500.0));
    let mut same = vec![([1.0f32, 2.0, 3.0], [2.0f32, 3.0, 4.0]); 1000];
    check_sah(&mut same, 7);
    let mut nan = vec![([f32::NAN; 3], [f32::NAN; 3]); 33];
    check_sah(&mut nan, 2);
    let mut inf: Vec<_> = (0..50)
        .map(|i| {
            if i % 3 == 0 {
                ([f32::NEG_INFINITY; 3], [f32::INFINITY; 3])
            } else {
                ([i as f32; 3], [i as f32 + 1.0; 3])
            }
        })
        .collect();
    check_sah(&mut inf, 4);
    check_sah(&mut [], 3);
}

/// `sah_partition` one step after another on this thread, left before right: what the
/// parallel version must reproduce.
fn serial_sah(
    items: &mut [u32],
    bounds: &mut [Bounds],
    cap: usize,
    offset: usize,
    out: &mut Vec<(usize, usize)>,
) {
    let len = items.len();
    if len <= cap {
        if len > 0 {
            out.push((offset, offset + len));
        }
        return;
    }
    let mid = sah_split(items, bounds, Pages::HEAP);
    let (li, ri) = items.split_at_mut(mid);
    let (lb, rb) = bounds.split_at_mut(mid);
    serial_sah(li, lb, cap, offset, out);
    serial_sah(ri, rb, cap, offset + mid, out);
}

#[test]
fn the_parallel_partition_equals_the_serial_one() {
    // Clustered boxes of varied sizes (an LCG: no dependency), a few of them huge and one
    // with a NaN corner: several parallel levels above PARALLEL_ITEMS.
    let n = 5 * PARALLEL_ITEMS + 123;
    let mut x = 0x2545_f491_4f6c_dd1du64;
    let mut next = || {
        x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        (x >> 40) as f32 / (1u64 << 24) as f32
    };
    let boxes: Vec<Bounds> = (0..n)
        .map(|i| {
            let cluster = (i % 7) as f32 * 100.0;
            let c = [cluster + next() * 30.0, next() * 50.0, next() * 10.0];
            let r = if i % 997 == 0 { 400.0 } else { next() * 2.0 };
            let mut min = c.map(|v| v - r);
            if i == 4242 {
                min[1] = f32::NAN;
            }
            (min, c.map(|v| v + r))
        })
        .collect();
    let cap = 5000;
    let (mut ids_p, mut b_p) = ((0..n as u32).collect::<Vec<_>>(), boxes.clone());
    let mut out_p = Vec::new();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(4)
        .build()
        .expect("thread pool");
    pool.install(|| sah_partition(&mut ids_p, &mut b_p, cap, &mut out_p));
    let (mut ids_s, mut b_s) = ((0..n as u32).collect::<Vec<_>>(), boxes);
    let mut out_s = Vec::new();
    serial_sah(&mut ids_s, &mut b_s, cap, 0, &mut out_s);
    assert!(out_s.len() > 16, "{} ranges", out_s.len());
    assert_eq!(out_p, out_s);
    assert_eq!(ids_p, ids_s);
}

#[test]
fn the_densest_leaves_become_pieces_and_the_rest_stays_within_the_room() {
    // 1000 tiny boxes packed in a unit cube, 1000 unit boxes spread over a 1000-wide line.
    let dense = |i: usize| {
        let x = (i % 10) as f32 * 0.1;
        let y = (i / 10 % 10) as f32 * 0.1;
        let z = (i / 100) as f32 * 0.1;
        ([x, y, z], [x + 0.05, y + 0.05, z + 0.05])
    };
    let sparse = |i: usize| {
        let x = 10.0 + i as f32;
        ([x, 0.0, 0.0], [x + 1.0, 1.0, 1.0])
    };
    let mut boxes: Vec<([f32; 3], [f32; 3])> = (0..2000)
        .map(|i| {
            if i % 2 == 0 {
                dense(i / 2)
            } else {
                sparse(i / 2)
            }
        })
        .collect();
    let before = boxes.clone();
    let mut ids: Vec<usize> = (0..boxes.len()).collect();
    let (cap, per_group) = (1200usize, 4usize);
    let room = |pieces: usize| cap - pieces.div_ceil(per_group);
    let mut out = Vec::new();
    let kept = split_keeping_direct(&mut ids, &mut boxes, cap, room, &mut out);
    // Pieces first, contiguous and within the cap, then the kept items, which fit.
    let mut next = 0;
    for &(a, b) in &out {
        assert_eq!(a, next);
        assert!(b > a && b - a <= cap);
        next = b;
    }
    assert_eq!(next + kept, boxes.len());
    assert!(
        kept <= room(out.len()) && kept >= 800,
        "kept {kept} of 2000"
    );
    // A permutation that moved bounds with items.
    for (k, &id) in ids.iter().enumerate() {
        assert_eq!(boxes[k].0.map(f32::to_bits), before[id].0.map(f32::to_bits));
    }
    let mut sorted = ids.clone();
    sorted.sort_unstable();
    assert!(sorted.iter().enumerate().all(|(k, &id)| k == id));
    // Only the dense cluster went to pieces: the whole sparse line stays.
    assert!(
        ids[..next].iter().all(|&id| id % 2 == 0),
        "a sparse item in a piece"
    );
    assert_eq!(ids[next..].iter().filter(|&&id| id % 2 == 1).count(), 1000);

    // No room at all: everything becomes pieces, none over the cap.
    let mut ids: Vec<usize> = (0..boxes.len()).collect();
    let mut out = Vec::new();
    assert_eq!(
        split_keeping_direct(&mut ids, &mut boxes, 300, |_| 0, &mut out),
        0
    );
    assert_eq!(out.last().map(|r| r.1), Some(2000));
    assert!(out.iter().all(|&(a, b)| b > a && b - a <= 300));
    // Degenerate input terminates.
    let mut nan = vec![([f32::NAN; 3], [f32::NAN; 3]); 40];
    let mut ids: Vec<usize> = (0..40).collect();
    let mut out = Vec::new();
    let kept = split_keeping_direct(
        &mut ids,
        &mut nan,
        8,
        |p| 20usize.saturating_sub(p),
        &mut out,
    );
    assert!(kept <= 20usize.saturating_sub(out.len()));
    assert_eq!(out.iter().map(|r| r.1 - r.0).sum::<usize>() + kept, 40);
}

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

/// Random boxes with clusters, duplicates, flat axes and NaN: the fast splits equal the
/// reference (the code before the speed-ups, serial) range for range and item for item,
/// on inputs large enough for the parallel paths.
#[test]
fn fast_partitions_equal_the_reference() {
    use self::reference::{median_partition_serial, sah_partition_serial};
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    for (n, cap) in [
        (200_000usize, 16usize),
        (150_000, 1_000),
        (3_000, 16),
        (40, 3),
    ] {
        let boxes: Vec<Bounds> = (0..n)
            .map(|i| {
                let c = if i % 97 == 0 {
                    [5.0, 5.0, 0.0] // duplicates
                } else if i % 1013 == 0 {
                    [f32::NAN, 1.0, 0.0]
                } else {
                    let k = (i % 7) as f32 * 100.0;
                    [k + rnd() * 10.0, rnd() * 1000.0, 0.0] // z flat
                };
                let h = rnd() * 3.0;
                ([c[0] - h, c[1] - h, c[2]], [c[0] + h, c[1] + 0.5 * h, c[2]])
            })
            .collect();
        let (mut a_items, mut a_bounds) = ((0..n as u32).collect::<Vec<_>>(), boxes.clone());
        let (mut b_items, mut b_bounds) = (a_items.clone(), boxes.clone());
        let (mut a, mut b) = (Vec::new(), Vec::new());
        sah_partition(&mut a_items, &mut a_bounds, cap, &mut a);
        sah_partition_serial(&mut b_items, &mut b_bounds, cap, &mut b);
        assert_eq!(a, b, "sah ranges, n {n} cap {cap}");
        assert_eq!(a_items, b_items, "sah order, n {n} cap {cap}");

        let centres: Vec<(u32, [f32; 3])> = boxes
            .iter()
            .enumerate()
            .map(|(i, b)| (i as u32, std::array::from_fn(|k| centroid(b, k))))
            .collect();
        let (mut x, mut y) = (centres.clone(), centres);
        let (mut a, mut b) = (Vec::new(), Vec::new());
        median_partition(&mut x, |c| c.1, cap, &mut a);
        median_partition_serial(&mut y, |c| c.1, cap, &mut b);
        assert_eq!(a, b, "median ranges, n {n} cap {cap}");
        let ids = |v: &[(u32, [f32; 3])]| v.iter().map(|c| c.0).collect::<Vec<_>>();
        assert_eq!(ids(&x), ids(&y), "median order, n {n} cap {cap}");
    }
}

/// Arrays in mapped files, their pages released behind every pass, moved through mapped
/// scratch: the same split, order and bounds as on the heap (the keyed split's mapped path).
#[test]
fn mapped_arrays_split_as_on_the_heap() {
    use crate::instance_table::ScratchArray;
    let n = 3 * PARALLEL_ITEMS + 12_345;
    let mut seed = 0x9e37_79b9u32;
    let mut next = move || {
        seed ^= seed << 13;
        seed ^= seed >> 17;
        seed ^= seed << 5;
        (seed % 100_000) as f32 / 100.0
    };
    let boxes: Vec<Bounds> = (0..n)
        .map(|i| {
            let c = [next(), next() * if i % 3 == 0 { 0.1 } else { 1.0 }, next()];
            let r = next() / 200.0;
            (c.map(|x| x - r), c.map(|x| x + r))
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let (cap, per_group) = (40_000usize, 64usize);
    let room = |pieces: usize| cap - pieces.div_ceil(per_group);

    let mut heap_ids: Vec<u32> = (0..n as u32).collect();
    let mut heap_bounds = boxes.clone();
    let mut heap_out = Vec::new();
    let heap_kept = split_keeping_direct(&mut heap_ids, &mut heap_bounds, cap, room, &mut heap_out);

    let mut ids = ScratchArray::<u32>::zeroed(n, Some(dir.path())).unwrap();
    let mut bounds = ScratchArray::<Bounds>::zeroed(n, Some(dir.path())).unwrap();
    let mut s_ids = ScratchArray::<u32>::zeroed(n, Some(dir.path())).unwrap();
    let mut s_bounds = ScratchArray::<Bounds>::zeroed(n, Some(dir.path())).unwrap();
    assert!(ids.is_mapped() && bounds.is_mapped());
    for (k, id) in ids.iter_mut().enumerate() {
        *id = k as u32;
    }
    bounds.copy_from_slice(&boxes);
    // Every array is a mapped `ScratchArray`.
    let pages = bounds.pages();
    let mut out = Vec::new();
    let kept = split_keeping_direct_paged(
        &mut ids,
        &mut bounds,
        cap,
        room,
        &mut out,
        pages,
        Some((&mut s_ids, &mut s_bounds)),
    );
    assert_eq!((kept, &out), (heap_kept, &heap_out));
    assert!(!out.is_empty() && kept > 0);
    assert_eq!(&ids[..], &heap_ids[..]);
    let bits = |b: &[Bounds]| -> Vec<[u32; 6]> {
        b.iter()
            .map(|(l, h)| [l[0], l[1], l[2], h[0], h[1], h[2]].map(f32::to_bits))
            .collect()
    };
    assert_eq!(bits(&bounds), bits(&heap_bounds));

    // Later rounds: the plain SAH partition of mapped arrays.
    let mut heap_out = Vec::new();
    sah_partition(&mut heap_ids, &mut heap_bounds, 5_000, &mut heap_out);
    let mut out = Vec::new();
    sah_partition_paged(&mut ids, &mut bounds, 5_000, &mut out, pages);
    assert_eq!(out, heap_out);
    assert_eq!(&ids[..], &heap_ids[..]);
    assert_eq!(bits(&bounds), bits(&heap_bounds));
}

/// The median splits' bounds are made with selects, not `f32::min`/`max` folds: on centres
/// drawn from signed zeros, infinities, NaN and ties (flat and zero-extent axes included) the
/// ranges and the order equal the reference's, which folds; the bounds equal the folds' but
/// for the sign of a zero.
#[test]
fn select_bounds_split_as_the_min_max_folds() {
    use self::reference::median_partition_serial;
    const VALUES: [f32; 9] = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        2.5,
        f32::INFINITY,
        f32::NEG_INFINITY,
        f32::NAN,
        1e30,
    ];
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut pick = move |n: usize| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 33) as usize % n
    };
    for (len, spread, cap) in [
        (5_000usize, 9usize, 7usize),
        (3_000, 2, 5),
        (70_000, 9, 300),
    ] {
        let centres: Vec<(u32, [f32; 3])> = (0..len as u32)
            .map(|i| {
                // `spread` 2: only the zeros, so every axis is flat or signed-zero-wide.
                (i, std::array::from_fn(|_| VALUES[pick(spread)]))
            })
            .collect();
        let (mut x, mut y) = (centres.clone(), centres.clone());
        let (mut a, mut b) = (Vec::new(), Vec::new());
        median_partition(&mut x, |c| c.1, cap, &mut a);
        median_partition_serial(&mut y, |c| c.1, cap, &mut b);
        assert_eq!(a, b, "ranges, len {len} spread {spread}");
        let ids = |v: &[(u32, [f32; 3])]| v.iter().map(|c| c.0).collect::<Vec<_>>();
        assert_eq!(ids(&x), ids(&y), "order, len {len} spread {spread}");

        let (lo, hi) = centre_bounds(&centres, &|c: &(u32, [f32; 3])| c.1);
        for k in 0..3 {
            let fold_lo = centres.iter().fold(f32::INFINITY, |m, c| m.min(c.1[k]));
            let fold_hi = centres.iter().fold(f32::NEG_INFINITY, |m, c| m.max(c.1[k]));
            // Equal as numbers (0.0 == -0.0), never NaN.
            assert!(
                lo[k] == fold_lo && hi[k] == fold_hi,
                "axis {k}: {lo:?} {hi:?}"
            );
        }
    }
}
