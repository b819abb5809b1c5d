use super::*;
use crate::testutil::grid_mesh;

fn centroid(m: &MeshData, t: usize) -> [f32; 3] {
    let p = |k: usize| m.positions[m.indices[3 * t + k] as usize];
    std::array::from_fn(|a| (p(0)[a] + p(1)[a] + p(2)[a]) / 3.0)
}

/// The automatic bound: 2^16 on big scenes, whole/256 on small ones (at least 2^12), raised
/// where splitting would multiply a heavily instanced mesh's placements.
#[test]
fn the_automatic_bound_is_a_256th_of_a_small_build_unless_splitting_multiplies_instances() {
    // Moana-sized, and just at the keep threshold: 2^16; just under it: a 256th.
    assert_eq!(auto_bound(1_180_000_000, 27_800_000, &[]), 1 << 16);
    assert_eq!(auto_bound(128 << 16, 0, &[]), 1 << 16);
    assert_eq!(auto_bound((128 << 16) - 256, 0, &[]), (1 << 15) - 1);
    // The default `gen island`: 521,130 triangles, 13,958 instances (a 256th: 2,145, at
    // least 4,096); its palm trunk (37,950 triangles) placed 40 times adds 15 × 40
    // records: allowed.
    assert_eq!(
        auto_bound(521_130, 13_958, &[(57_600, 1), (37_950, 40)]),
        4_096
    );
    // One 2M-triangle mesh: a 256th of it.
    assert_eq!(auto_bound(2_000_000, 0, &[(2_000_000, 1)]), 7_813);
    assert_eq!(
        auto_bound(1_000, 10, &[(1_000, 10)]),
        MIN_AUTO_MAX_BLAS_TRIANGLES
    );
    // A fractal: one 29,892-triangle mesh placed 25,250 times is never split (the bound
    // doubles until it holds the mesh whole).
    assert_eq!(auto_bound(29_892, 25_250, &[(29_892, 25_250)]), 32_768);
    assert_eq!(auto_bound(u64::MAX, u64::MAX, &[]), 1 << 16);
}

/// Bounds respected, every source triangle in exactly one cluster with its own vertices,
/// maps ascending; clusters spatially coherent (disjoint centroid boxes along some axis).
#[test]
fn clusters_cover_every_triangle_once_within_the_bound() {
    let grid = grid_mesh(64, true); // 2 × 64² triangles
    let n = grid.triangle_count();
    for bound in [1u32, 7, 1000, 4096, 8192, 10_000] {
        let mut seen = vec![0u32; n];
        let mut clusters = Vec::new();
        partition_mesh(&grid, bound, &mut |c: Cluster| -> Result<(), ()> {
            clusters.push(c);
            Ok(())
        })
        .unwrap();
        assert_eq!(clusters.len() as u64, cluster_count(n as u64, bound));
        for c in &clusters {
            let t = c.data.triangle_count();
            assert!(t >= 1 && t <= bound as usize, "{t} over {bound}");
            assert!(
                t * 2 >= (bound as usize).min(n),
                "a median split keeps ≥ half"
            );
            c.data.validate().unwrap();
            assert_eq!(c.primitive_map.len(), t);
            assert!(c.primitive_map.windows(2).all(|w| w[0] < w[1]));
            assert_eq!(
                c.data.normals.as_ref().map(Vec::len),
                Some(c.data.positions.len())
            );
            for (local, &src) in c.primitive_map.iter().enumerate() {
                seen[src as usize] += 1;
                for k in 0..3 {
                    let a = c.data.positions[c.data.indices[3 * local + k] as usize];
                    let b = grid.positions[grid.indices[3 * src as usize + k] as usize];
                    assert_eq!(a, b, "cluster triangle {local} is source {src}");
                }
            }
            assert!(grid.bounds().contains(&c.bounds, 0.0));
            assert_eq!(c.bounds, c.data.bounds());
        }
        assert!(seen.iter().all(|&s| s == 1), "bound {bound}: coverage");
        if bound >= 1000 {
            // Spatial coherence: the clusters' areas sum to about the grid's (a split along
            // the largest axis of a plane gives tiles; a random split would give overlaps).
            let area = |b: &Aabb| (b.max[0] - b.min[0]) * (b.max[1] - b.min[1]);
            let sum: f32 = clusters.iter().map(|c| area(&c.bounds)).sum();
            let whole = area(&grid.bounds());
            assert!(sum <= whole * 1.3, "clusters overlap: {sum} vs {whole}");
            // Centroid boxes of any two clusters are disjoint on some axis.
            let cbox = |c: &Cluster| {
                let mut b = Aabb::EMPTY;
                for &t in &c.primitive_map {
                    let p = centroid(&grid, t as usize);
                    b = b.union(&Aabb { min: p, max: p });
                }
                b
            };
            let boxes: Vec<Aabb> = clusters.iter().map(cbox).collect();
            for i in 0..boxes.len() {
                for j in i + 1..boxes.len() {
                    let (a, b) = (&boxes[i], &boxes[j]);
                    assert!(
                        (0..3).any(|k| a.max[k] <= b.min[k] || b.max[k] <= a.min[k]),
                        "clusters {i} and {j} interleave"
                    );
                }
            }
        }
    }
}

#[test]
fn cluster_counts_halve() {
    assert_eq!(cluster_count(0, 10), 1);
    assert_eq!(cluster_count(10, 10), 1);
    assert_eq!(cluster_count(11, 10), 2);
    assert_eq!(cluster_count(2_000_000, 1 << 19), 4);
    assert_eq!(cluster_count(2_200_000, 1 << 19), 8);
    assert_eq!(cluster_count(2_000_000, DEFAULT_MAX_BLAS_TRIANGLES), 32);
}

fn item(index: u32, x: f32, triangles: u64) -> Item {
    Item {
        index,
        centre: [x, 0.0, 0.0],
        triangles,
    }
}

#[test]
fn small_meshes_group_by_location_under_the_bound() {
    // 100 meshes of 10 triangles along x, shuffled: groups of ≤ 250 triangles, contiguous
    // in x, and no more groups than needed twice over.
    let mut items: Vec<Item> = (0..100u32)
        .map(|i| item(i, ((i * 37) % 100) as f32, 10))
        .collect();
    let mut out = Vec::new();
    group_by_location(&mut items, 250, &mut out);
    let mut next = 0;
    let mut last_max = f32::NEG_INFINITY;
    for &(a, b) in &out {
        assert_eq!(a, next);
        next = b;
        let g = &items[a..b];
        let tris: u64 = g.iter().map(|i| i.triangles).sum();
        assert!(tris <= 250, "{tris}");
        let min = g.iter().map(|i| i.centre[0]).fold(f32::INFINITY, f32::min);
        let max = g
            .iter()
            .map(|i| i.centre[0])
            .fold(f32::NEG_INFINITY, f32::max);
        assert!(min > last_max, "groups are spatially ordered and disjoint");
        last_max = max;
    }
    assert_eq!(next, 100);
    assert!(out.len() >= 4 && out.len() <= 8, "{} groups", out.len());
    let mut ids: Vec<u32> = items.iter().map(|i| i.index).collect();
    ids.sort_unstable();
    assert_eq!(ids, (0..100).collect::<Vec<_>>());

    // Within the bound: one group; weighted: one heavy item splits off alone.
    let mut few = vec![item(0, 0.0, 5), item(1, 1.0, 5)];
    out.clear();
    group_by_location(&mut few, 10, &mut out);
    assert_eq!(out, vec![(0, 2)]);
    let mut heavy = vec![item(0, 0.0, 90), item(1, 1.0, 5), item(2, 2.0, 5)];
    out.clear();
    group_by_location(&mut heavy, 50, &mut out);
    assert_eq!(out, vec![(0, 1), (1, 3)]);
    // An item over the bound alone, coincident centres and NaN terminate.
    let mut same = vec![item(0, 1.0, 30); 40];
    out.clear();
    group_by_location(&mut same, 100, &mut out);
    assert!(out.iter().all(|&(a, b)| (b - a) * 30 <= 100));
    let mut nan = vec![item(0, f32::NAN, 30); 9];
    out.clear();
    group_by_location(&mut nan, 31, &mut out);
    assert_eq!(out.len(), 9);
}
