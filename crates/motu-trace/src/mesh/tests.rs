use super::*;

fn grid(n: usize) -> MeshGeometry {
    let mut positions = Vec::new();
    for y in 0..=n {
        for x in 0..=n {
            positions.push([x as f32, y as f32, ((x * y) % 3) as f32 * 0.1]);
        }
    }
    let mut indices = Vec::new();
    let w = n as u32 + 1;
    for y in 0..n as u32 {
        for x in 0..n as u32 {
            let i = y * w + x;
            indices.extend([i, i + 1, i + w, i + 1, i + w + 1, i + w]);
        }
    }
    MeshGeometry {
        positions,
        indices,
        normals: None,
        primitive_map: None,
        uvs: None,
    }
}

#[test]
fn bvh_matches_linear_scan() {
    let g = grid(40);
    let bvh = MeshBvh::build(&g, None, BuildParams::default()).unwrap();
    let mut stack = Vec::new();
    for i in 0..500 {
        let f = i as f32;
        let org = [(f * 0.37).fract() * 40.0, (f * 0.61).fract() * 40.0, 5.0];
        let dir = [(f * 0.13).fract() - 0.5, (f * 0.29).fract() - 0.5, -1.0];
        let ray = LocalRay::new(org, dir);
        let mut t = f32::INFINITY;
        let hit = bvh.intersect(&ray, 0.0, &mut t, false, &mut stack);
        let mut best = (f32::INFINITY, None);
        for (slot, v) in bvh.tri_verts.iter().enumerate() {
            if let Some(tt) = ray.hit_triangle(v[0], v[1], v[2], 0.0, best.0) {
                best = (tt, Some(slot as u32));
            }
        }
        assert_eq!(t == f32::INFINITY, best.1.is_none());
        if hit.is_some() {
            assert_eq!(t, best.0);
        }
    }
}

#[test]
fn rejects_bad_geometry() {
    let mut g = grid(1);
    g.indices.push(0);
    assert!(matches!(
        MeshBvh::build(&g, None, BuildParams::default()).unwrap_err(),
        MeshError::IndexCount(7)
    ));
    let mut g = grid(1);
    g.indices[0] = 99;
    assert!(matches!(
        MeshBvh::build(&g, None, BuildParams::default()),
        Err(MeshError::IndexRange { index: 99, .. })
    ));
    let g = grid(2);
    let small = Aabb::new([0.0; 3], [1.0; 3]);
    assert!(matches!(
        MeshBvh::build(&g, Some(small), BuildParams::default()),
        Err(MeshError::Bounds { .. })
    ));
}
