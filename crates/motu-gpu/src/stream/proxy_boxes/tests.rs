use super::*;

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
        split(&mut work, 2 * fan.trailing_zeros(), 0, &mut leaves);
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
