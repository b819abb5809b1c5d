use super::*;
use crate::testutil::grid_mesh;

#[test]
fn chain_on_a_dense_grid_divides_by_about_four() {
    let grid = grid_mesh(96, true);
    let n0 = grid.triangle_count();
    let mut counts = vec![n0];
    build_chain(MeshId(0), grid.clone(), 4, &mut |lod, m| {
        m.validate().unwrap();
        assert_eq!(lod as usize, counts.len());
        assert!(m
            .normals
            .as_ref()
            .is_some_and(|n| n.len() == m.positions.len()));
        // Simplification only moves vertices onto existing ones: bounds cannot grow.
        assert!(grid.bounds().contains(&m.bounds(), 0.0));
        counts.push(m.triangle_count());
        Ok(())
    })
    .unwrap();
    assert!(counts.len() >= 3, "{counts:?}");
    for w in counts.windows(2) {
        let ratio = w[0] as f64 / w[1] as f64;
        assert!((2.5..=6.0).contains(&ratio), "÷{ratio} in {counts:?}");
    }
}

#[test]
fn tiny_mesh_makes_no_levels() {
    let tri = MeshData {
        positions: vec![[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        indices: vec![0, 1, 2],
        ..Default::default()
    };
    let mut n = 0;
    build_chain(MeshId(0), tri, 5, &mut |_, _| {
        n += 1;
        Ok(())
    })
    .unwrap();
    assert_eq!(n, 0);
}
