use super::*;

fn check_indices(mesh: &dyn TriangleSource) {
    let mut used = vec![false; mesh.vertex_count() as usize];
    for t in 0..mesh.triangle_count() {
        let tri = mesh.triangle(t);
        assert!(
            tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2],
            "degenerate {tri:?}"
        );
        for i in tri {
            assert!(i < mesh.vertex_count());
            used[i as usize] = true;
        }
    }
    assert!(used.iter().all(|&u| u), "every vertex is referenced");
}

#[test]
fn grids_and_spheres_are_well_formed() {
    let flat = ParamGrid::new(5, 4, false, |u, v| [u, 0.0, v]);
    assert_eq!(flat.vertex_count(), 20);
    assert_eq!(flat.triangle_count(), 2 * 4 * 3);
    check_indices(&flat);
    let tube = ParamGrid::new(8, 3, true, |u, v| [(u * TAU).cos(), v, (u * TAU).sin()]);
    assert_eq!(tube.triangle_count(), 2 * 8 * 2);
    check_indices(&tube);
    let sphere = UvSphere::new(12, 6, |d| d);
    assert_eq!(sphere.triangle_count(), 2 * 12 * 5);
    check_indices(&sphere);
    for v in 0..sphere.vertex_count() {
        let p = sphere.vertex(v);
        assert!((crate::math::dot(p, p) - 1.0).abs() < 1e-9);
    }
}

#[test]
fn sphere_is_closed_every_edge_shared_twice() {
    let sphere = UvSphere::new(7, 5, |d| d);
    let mut edges = std::collections::HashMap::new();
    for t in 0..sphere.triangle_count() {
        let [a, b, c] = sphere.triangle(t);
        for (x, y) in [(a, b), (b, c), (c, a)] {
            *edges.entry((x.min(y), x.max(y))).or_insert(0) += 1;
        }
    }
    assert!(edges.values().all(|&n| n == 2));
}

#[test]
fn mesh_append_offsets_indices() {
    let mut m = Mesh::default();
    let quad = ParamGrid::new(2, 2, false, |u, v| [u, v, 0.0]);
    m.append(&quad, &Affine::IDENTITY);
    m.append(&quad, &Affine::translation([5.0, 0.0, 0.0]));
    assert_eq!(m.vertex_count(), 8);
    assert_eq!(m.triangle_count(), 4);
    assert!(m.triangle(2).iter().all(|&i| i >= 4));
    assert_eq!(m.vertex(4)[0], 5.0);
}

#[test]
fn value_noise_is_bounded_continuous_and_deterministic() {
    let n = ValueNoise2::new(9, 4, 0.1);
    let m = ValueNoise2::new(9, 4, 0.1);
    let mut prev = n.at(-50.0, 3.0);
    for i in 0..2000 {
        let x = -50.0 + f64::from(i) * 0.05;
        let v = n.at(x, 3.0);
        assert_eq!(v, m.at(x, 3.0));
        assert!(v.abs() <= 1.0);
        assert!((v - prev).abs() < 0.1, "continuous at {x}");
        prev = v;
    }
    assert_ne!(ValueNoise2::new(10, 4, 0.1).at(1.3, 2.7), n.at(1.3, 2.7));
}

#[test]
fn noise_is_bounded_and_deterministic() {
    let a = SineNoise::new(3, 4, 1.0);
    let b = SineNoise::new(3, 4, 1.0);
    for i in 0..100 {
        let p = [f64::from(i) * 0.37, 1.0, -f64::from(i) * 0.11];
        assert_eq!(a.at(p), b.at(p));
        assert!(a.at(p).abs() <= 1.0);
    }
}
