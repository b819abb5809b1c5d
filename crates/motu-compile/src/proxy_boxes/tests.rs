use super::*;
use bytemuck::Zeroable;
use motu_abi::{GeometryRecord, MeshRecord, BLAS_AABBS};

#[test]
fn fan_grows_with_triangles_up_to_the_cap() {
    assert_eq!(fan(1), 1);
    assert_eq!(fan(127), 1);
    assert_eq!(fan(128), 2);
    assert_eq!(fan(511), 2);
    assert_eq!(fan(512), 4);
    assert_eq!(fan(4096), 8);
    assert_eq!(fan(8191), 8);
    assert_eq!(fan(8192), 16);
    assert_eq!(fan(u32::MAX), MAX_FAN);
}

#[test]
fn every_triangle_lies_in_a_leaf_of_a_top_box_that_holds_it() {
    // A 40 × 40 grid of small triangles on a tilted, curved sheet, plus far outliers.
    let mut tris = Vec::new();
    for i in 0..40 {
        for j in 0..40 {
            let (x, z) = (i as f32, j as f32);
            let y = 0.1 * x * z.sin();
            let bx = [x, y, z, x + 0.7, y + 0.3, z + 0.9];
            tris.push((std::array::from_fn(|a| 0.5 * (bx[a] + bx[3 + a])), bx));
        }
    }
    let sheet = tris.clone();
    tris.push(([1e4, 0.0, 0.0], [1e4, 0.0, 0.0, 1e4, 0.0, 0.0]));
    tris.push(([-3.0; 3], [-3.0, -3.0, -3.0, -3.0, -3.0, -3.0]));
    let mut volumes = Vec::new();
    for (fan, all) in [1usize, 2, 4, 16]
        .into_iter()
        .flat_map(|f| [(f, &tris), (f, &sheet)])
    {
        let mut work = all.clone();
        let mut leaves = Vec::new();
        split(&mut work, 2 * fan.trailing_zeros(), 0, None, &mut leaves);
        assert_eq!(leaves.len(), fan * fan);
        assert_eq!(leaves.iter().map(|r| r.len()).sum::<usize>(), all.len());
        let union = |rs: &[Range<usize>]| {
            let mut bx = EMPTY;
            for t in rs.iter().flat_map(|r| &work[r.clone()]) {
                grow(&mut bx, &t.1[..3], &t.1[3..]);
            }
            bx
        };
        let inside = |o: &Box6, t: &Box6| (0..3).all(|a| o[a] <= t[a] && t[3 + a] <= o[3 + a]);
        let mut leaf_volume = 0.0f64;
        for t in all {
            let held = (0..fan).any(|k| {
                inside(&union(&leaves[k * fan..(k + 1) * fan]), &t.1)
                    && (0..fan)
                        .any(|j| inside(&union(std::slice::from_ref(&leaves[k * fan + j])), &t.1))
            });
            assert!(
                held,
                "fan {fan}: {t:?} is in no leaf of a top box holding it"
            );
        }
        for l in &leaves {
            let b = union(std::slice::from_ref(l));
            if b[0] <= b[3] {
                leaf_volume += (0..3).map(|a| f64::from(b[3 + a] - b[a])).product::<f64>();
            }
        }
        if std::ptr::eq(all, &sheet) {
            volumes.push(leaf_volume);
        }
    }
    // Finer fans hug the sheet: the leaves' volume shrinks.
    assert!(volumes.windows(2).all(|w| w[1] < w[0]), "{volumes:?}");
    assert!(volumes[3] < 0.5 * volumes[0], "{volumes:?}");
}

#[test]
fn sampled_medians_keep_leaves_near_even_and_ties_still_split() {
    // 20,000 scattered triangles (deterministic): the upper levels split at sampled medians.
    let scattered: Vec<TriangleBox> = (0..20_000u32)
        .map(|i| {
            let f = i as f32;
            let c = [
                (f * 0.618).fract() * 50.0,
                (f * 0.377).sin() * 3.0,
                (f * 0.123).fract(),
            ];
            (c, [c[0], c[1], c[2], c[0] + 0.1, c[1] + 0.1, c[2] + 0.1])
        })
        .collect();
    // Every centroid equal (no pivot parts them), and a few NaN among equal ones.
    let same = vec![([1.0f32; 3], [1.0f32, 1.0, 1.0, 1.0, 1.0, 1.0]); 3_000];
    let mut nan = same.clone();
    for t in nan.iter_mut().step_by(7) {
        t.0 = [f32::NAN; 3];
    }
    for (name, all) in [("scattered", &scattered), ("same", &same), ("nan", &nan)] {
        let mut work = all.clone();
        let mut leaves = Vec::new();
        split(&mut work, 8, 0, None, &mut leaves);
        assert_eq!(leaves.len(), 256, "{name}");
        // Consecutive, covering every item once.
        assert_eq!(leaves[0].start, 0, "{name}");
        assert!(leaves.windows(2).all(|w| w[0].end == w[1].start), "{name}");
        assert_eq!(leaves[255].end, all.len(), "{name}");
        let even = all.len() as f64 / 256.0;
        let (lo, hi) = leaves.iter().fold((usize::MAX, 0), |(lo, hi), r| {
            (lo.min(r.len()), hi.max(r.len()))
        });
        assert!(
            lo as f64 >= 0.5 * even && hi as f64 <= 1.6 * even,
            "{name}: leaves of {lo}..{hi} items, {even} even"
        );
    }
    // The sampled splits order the scattered set along each split's axis: a leaf's centroids
    // lie on one side of its sibling's on the root's axis (x, the widest).
    let mut work = scattered.clone();
    let mut leaves = Vec::new();
    split(&mut work, 1, 0, None, &mut leaves);
    let max_left = work[leaves[0].clone()]
        .iter()
        .map(|t| t.0[0])
        .fold(f32::MIN, f32::max);
    let min_right = work[leaves[1].clone()]
        .iter()
        .map(|t| t.0[0])
        .fold(f32::MAX, f32::min);
    assert!(max_left <= min_right, "{max_left} > {min_right}");
}

/// Two meshes, a triangle BLAS over both, an AABB BLAS and a triangle BLAS over the second.
struct Tables {
    blases: Vec<BlasRecord>,
    geometries: Vec<GeometryRecord>,
    meshes: Vec<MeshRecord>,
}

impl Tables {
    fn new() -> Tables {
        let mesh = |triangles: u32, chunk: u32| MeshRecord {
            triangle_count: triangles,
            vertex_count: 3 * triangles,
            chunk,
            ..MeshRecord::zeroed()
        };
        let blas = |kind: u32, base: u32, count: u32, prims: u32| BlasRecord {
            kind,
            item_base: base,
            item_count: count,
            primitive_count: prims,
            bounds_min: [0.0; 3],
            bounds_max: [1.0; 3],
            ..BlasRecord::zeroed()
        };
        let geometry = |m: u32| GeometryRecord {
            mesh: m,
            ..GeometryRecord::zeroed()
        };
        Tables {
            meshes: vec![mesh(300, 0), mesh(200, 1)],
            geometries: vec![geometry(0), geometry(1), geometry(1)],
            blases: vec![
                blas(BLAS_TRIANGLES, 0, 2, 500),
                blas(BLAS_AABBS, 0, 0, 0),
                blas(BLAS_TRIANGLES, 2, 1, 200),
            ],
        }
    }

    fn view(&self) -> HierarchyView<'_> {
        HierarchyView {
            blases: &self.blases,
            geometries: &self.geometries,
            meshes: &self.meshes,
            ..HierarchyView::default()
        }
    }
}

#[test]
fn a_stored_table_round_trips_and_is_used_only_for_the_records_it_was_made_for() {
    let t = Tables::new();
    let view = t.view();
    let mut stored = StoredProxyBoxes::default();
    for b in [0usize, 2] {
        let f = fan(view.blases[b].primitive_count);
        let boxes: Vec<Box6> = (0..box_count(f))
            .map(|i| [b as f32, i as f32, 0.0, 1.0, 2.0, 3.0])
            .collect();
        stored.push(b as u32, f, blas_hash(&view, b), &boxes);
    }
    let bytes = encode_section(&stored);
    let back = decode_section(&bytes).expect("decodes");
    assert_eq!(back, stored);
    assert!(matches!(back.boxes_of(&view, 0), Stored::Valid(b) if b.len() == box_count(2)));
    assert!(matches!(back.boxes_of(&view, 2), Stored::Valid(b) if b[0][0] == 2.0));
    assert_eq!(back.boxes_of(&view, 1), Stored::Absent);
    // Another mesh record under BLAS 2 (moved data), another geometry list, another triangle
    // count: stale.
    let mut moved = Tables::new();
    moved.meshes[1].positions_offset = 4096;
    assert_eq!(back.boxes_of(&moved.view(), 2), Stored::Stale);
    assert_eq!(back.boxes_of(&moved.view(), 0), Stored::Stale);
    let mut regrouped = Tables::new();
    regrouped.geometries[2].mesh = 0;
    assert_eq!(back.boxes_of(&regrouped.view(), 2), Stored::Stale);
    assert!(matches!(
        back.boxes_of(&regrouped.view(), 0),
        Stored::Valid(_)
    ));
    // Cut, long, another version, entries out of order or boxes out of range: refused.
    assert_eq!(decode_section(&bytes[..bytes.len() - 1]), None);
    let mut long = bytes.clone();
    long.push(0);
    assert_eq!(decode_section(&long), None);
    let mut v3 = bytes.clone();
    v3[13] = b'3';
    assert_eq!(decode_section(&v3), None);
    // Version 1 (exact medians, the same layout) is still read.
    let mut v1 = bytes.clone();
    v1[13] = b'1';
    assert_eq!(decode_section(&v1).as_ref(), Some(&stored));
    let mut swapped = stored.clone();
    swapped.entries.swap(0, 1);
    assert_eq!(decode_section(&encode_section(&swapped)), None);
    let mut far = stored.clone();
    far.entries[1].first_box = 1 << 40;
    assert_eq!(decode_section(&encode_section(&far)), None);
}

#[test]
fn blas_boxes_of_meshes_equal_boxes_from_their_triangles() {
    let t = Tables::new();
    let view = t.view();
    // Meshes of scattered triangles (deterministic), some indices out of range.
    let mesh = |m: u32| -> (Vec<[f32; 3]>, Vec<u32>) {
        let n = view.meshes[m as usize].triangle_count;
        let positions: Vec<[f32; 3]> = (0..3 * n)
            .map(|i| {
                let x = (i as f32 * 0.37 + m as f32).sin() * 10.0;
                [x, (i as f32 * 1.3).cos(), i as f32 * 0.01]
            })
            .collect();
        let mut indices: Vec<u32> = (0..3 * n).rev().collect();
        indices[5] = 1 << 30;
        (positions, indices)
    };
    for b in [0usize, 2] {
        let f = fan(view.blases[b].primitive_count) as usize;
        let runtime = blas_boxes(&view, b, f, |m| {
            let (p, i) = mesh(m);
            Ok::<_, ()>((Cow::Owned(p), Cow::Owned(i)))
        });
        let r = &view.blases[b];
        let mut tris = Vec::new();
        for g in &view.geometries[r.item_base as usize..][..r.item_count as usize] {
            let (p, i) = mesh(g.mesh);
            push_triangle_boxes(&p, &i, &mut tris);
        }
        let stored = boxes_from_triangles(&tris, f);
        assert_eq!(
            bytemuck::cast_slice::<Box6, u32>(&runtime),
            bytemuck::cast_slice::<Box6, u32>(&stored)
        );
        assert!(runtime.iter().all(|b| b[0] <= b[3]), "{runtime:?}");
    }
    // A mesh that cannot be read: the padded bounds as the only top box and leaf.
    let failed = blas_boxes(&view, 2, 1, |_| Err::<MeshSlices<'_>, _>("gone"));
    assert_eq!(failed, vec![padded([0.0, 0.0, 0.0, 1.0, 1.0, 1.0]); 2]);
}

/// The boxes made by splitting the triangles themselves (each triangle's centroid and box
/// reordered in place): the splits see the same centroids in the same order either way.
fn boxes_moving_triangles(tris: &mut [TriangleBox], fan: usize) -> Vec<Box6> {
    let mut out = vec![EMPTY; fan + fan * fan];
    let mut leaves = Vec::with_capacity(fan * fan);
    split(tris, 2 * fan.trailing_zeros(), 0, None, &mut leaves);
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

#[test]
fn splitting_keys_makes_the_boxes_splitting_the_triangles_made() {
    // A terrain-like grid (many centroids tied along each axis: the median falls inside runs of
    // equal keys, where which triangle goes left depends on the selection's moves), a jittered
    // cloud, a flat sheet and a degenerate pile, at every fan.
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let mut jitter = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    let tri = |x: f32, y: f32, z: f32, w: f32| {
        let bx = [x, y, z, x + w, y + 0.5 * w, z + w];
        (std::array::from_fn(|a| 0.5 * (bx[a] + bx[3 + a])), bx)
    };
    let grid: Vec<TriangleBox> = (0..9000)
        .map(|i| {
            tri(
                (i % 97) as f32,
                ((i / 97) % 3) as f32,
                (i / 291) as f32,
                1.0,
            )
        })
        .collect();
    let cloud: Vec<TriangleBox> = (0..20_000)
        .map(|_| tri(100.0 * jitter(), 10.0 * jitter(), 50.0 * jitter(), jitter()))
        .collect();
    let sheet: Vec<TriangleBox> = (0..3000)
        .map(|i| tri((i % 50) as f32 * 0.5, 0.0, (i / 50) as f32 * 0.5, 0.0))
        .collect();
    let pile: Vec<TriangleBox> = (0..700).map(|_| tri(1.0, 2.0, 3.0, 0.0)).collect();
    for tris in [&grid, &cloud, &sheet, &pile] {
        for fan in [1usize, 2, 4, 8, 16] {
            let before = tris.clone();
            let keyed = boxes_from_triangles(tris, fan);
            assert_eq!(*tris, before, "the triangles are left as they were");
            let moved = boxes_moving_triangles(&mut tris.clone(), fan);
            assert_eq!(
                bytemuck::cast_slice::<Box6, u32>(&keyed),
                bytemuck::cast_slice::<Box6, u32>(&moved),
                "fan {fan}, {} triangles",
                tris.len()
            );
        }
    }
}

mod reference;

/// Deterministic xorshift numbers in [0, 1).
fn unit_numbers(mut seed: u64) -> impl FnMut() -> f32 {
    move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// A coordinate that is often tied, sometimes a zero of either sign, now and then NaN or
/// infinite: what the splits must treat exactly as before.
fn awkward(r: &mut impl FnMut() -> f32, spread: f32) -> f32 {
    match (r() * 40.0) as u32 {
        0 => f32::NAN,
        1 => -0.0,
        2 => 0.0,
        3 => f32::INFINITY,
        4..=15 => (r() * 6.0).floor(),
        _ => (r() - 0.3) * spread,
    }
}

#[test]
fn the_one_write_partition_moves_items_as_the_two_write_partition_did() {
    let mut r = unit_numbers(0x2545_f491_4f6c_dd1d);
    for n in [513usize, 514, 700, 1023, 4096, 9999] {
        let src: Vec<SplitKey> = (0..n as u32)
            .map(|i| SplitKey(std::array::from_fn(|_| awkward(&mut r, 50.0)), i))
            .collect();
        for axis in 0..3 {
            let mut new = vec![SplitKey([0.0; 3], u32::MAX); n];
            let mut old = new.clone();
            let made = sampled_partition_into(&src, &mut new, axis);
            let was = reference::sampled_partition_into(&src, &mut old, axis);
            let bits = |o: &Option<(usize, Box6, Box6)>| {
                o.map(|(m, l, r)| (m, l.map(f32::to_bits), r.map(f32::to_bits)))
            };
            assert_eq!(bits(&made), bits(&was), "n {n} axis {axis}");
            let ids = |v: &[SplitKey]| v.iter().map(|k| k.1).collect::<Vec<_>>();
            assert_eq!(ids(&new), ids(&old), "n {n} axis {axis}");
        }
    }
}

#[test]
fn boxes_from_meshes_are_main_s_boxes_bit_for_bit() {
    let mut r = unit_numbers(0x9e37_79b9_7f4a_7c15);
    // Meshes of awkward positions (ties, signed zeros, NaN, infinities), one with indices out
    // of range, at sizes that reach every fan and the sampled splits.
    for (tris, spread, out_of_range) in [
        (40usize, 1.0f32, false),
        (300, 10.0, true),
        (2_000, 100.0, false),
        (9_000, 0.01, true),
        (20_000, 1e4, false),
    ] {
        let verts = tris + 7;
        let mut mesh = |m: u32| -> (Vec<[f32; 3]>, Vec<u32>) {
            let positions: Vec<[f32; 3]> = (0..verts)
                .map(|_| std::array::from_fn(|_| awkward(&mut r, spread)))
                .collect();
            let mut indices: Vec<u32> = (0..3 * tris)
                .map(|_| (r() * verts as f32) as u32 % verts as u32)
                .collect();
            if out_of_range && m == 1 {
                indices[4] = verts as u32;
                indices[9] = u32::MAX;
            }
            (positions, indices)
        };
        let meshes = [mesh(0), mesh(1)];
        let slices: Vec<(&[[f32; 3]], &[u32])> =
            meshes.iter().map(|(p, i)| (&p[..], &i[..])).collect();
        for fan in [1usize, 2, 4, 8, 16] {
            let new = boxes_from_meshes(&slices, fan);
            let old = reference::boxes_from_meshes(&slices, fan);
            let bits = |b: &[Box6]| b.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&new), bits(&old), "{tris} triangles, fan {fan}");
            let mut each = Vec::new();
            for (p, i) in &slices {
                push_triangle_boxes(p, i, &mut each);
            }
            let stored = boxes_from_triangles(&each, fan);
            assert_eq!(bits(&stored), bits(&old), "{tris} triangles, fan {fan}");
        }
    }
}
