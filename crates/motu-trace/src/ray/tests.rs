use super::*;

#[test]
fn invert_and_compose_round_trip() {
    let m = [2.0, 0.5, 0.0, 3.0, 0.0, 1.0, -1.0, 4.0, 0.3, 0.0, 1.5, -2.0];
    let inv = invert(&m).unwrap();
    let id = compose(&m, &inv);
    for (a, b) in id.iter().zip(IDENTITY_3X4.iter()) {
        assert!((a - b).abs() < 1e-5, "{id:?}");
    }
    assert!(invert(&[0.0; 12]).is_none());
}

#[test]
fn triangle_hit_distance_and_miss() {
    let r = LocalRay::new([0.2, 0.2, -5.0], [0.0, 0.0, 1.0]);
    let t = r
        .hit_triangle(
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            0.0,
            f32::MAX,
        )
        .unwrap();
    assert!((t - 5.0).abs() < 1e-6);
    // Double-sided: reversed winding hits too.
    assert!(r
        .hit_triangle(
            [0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 0.0, 0.0],
            0.0,
            f32::MAX
        )
        .is_some());
    // Outside, behind t_max, behind the origin.
    let far = LocalRay::new([2.0, 2.0, -5.0], [0.0, 0.0, 1.0]);
    assert!(far
        .hit_triangle(
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            0.0,
            f32::MAX
        )
        .is_none());
    assert!(r
        .hit_triangle([0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], 0.0, 4.0)
        .is_none());
    let back = LocalRay::new([0.2, 0.2, 5.0], [0.0, 0.0, 1.0]);
    assert!(back
        .hit_triangle(
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            0.0,
            f32::MAX
        )
        .is_none());
}

#[test]
fn scaled_space_keeps_world_distance() {
    // A ray mapped into a space scaled by 2 meets the scaled triangle at the same t.
    let s = [2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0];
    let world = LocalRay::new([0.2, 0.2, -5.0], [0.0, 0.0, 1.0]);
    let local = world.transformed(&s);
    let t = local
        .hit_triangle(
            [0.0, 0.0, 0.0],
            [2.0, 0.0, 0.0],
            [0.0, 2.0, 0.0],
            0.0,
            f32::MAX,
        )
        .unwrap();
    assert!((t - 5.0).abs() < 1e-5);
    assert!(local
        .hit_box(&[0.0; 3], &[2.0, 2.0, 0.0], 0.0, f32::MAX)
        .is_some());
}
