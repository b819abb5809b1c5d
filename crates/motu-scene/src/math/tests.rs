use super::*;
use glam::Quat;

#[test]
fn rotated_bounds_use_all_eight_corners() {
    let b = Aabb::from_min_max(Vec3::splat(-1.0), Vec3::splat(1.0));
    let rot = Transform34::from_mat4(Mat4::from_quat(Quat::from_rotation_z(
        std::f32::consts::FRAC_PI_4,
    )));
    let t = b.transformed(&rot);
    let s2 = std::f32::consts::SQRT_2;
    assert!((t.max[0] - s2).abs() < 1e-5, "{t:?}");
    assert!((t.min[1] + s2).abs() < 1e-5, "{t:?}");
    assert!((t.max[2] - 1.0).abs() < 1e-6);
}

#[test]
fn mat4_round_trip_and_mul_order() {
    let a = Transform34::from_translation(Vec3::new(1.0, 2.0, 3.0));
    let s = Transform34::from_mat4(Mat4::from_scale(Vec3::splat(2.0)));
    assert_eq!(Transform34::from_mat4(a.to_mat4()), a);
    // a ∘ s: scale first, then translate.
    let p = a.mul(&s).transform_point(Vec3::ONE);
    assert_eq!(p, Vec3::new(3.0, 4.0, 5.0));
    let inv = a.mul(&s).inverse().unwrap();
    assert!((inv.transform_point(p) - Vec3::ONE).length() < 1e-6);
    assert!(Transform34::from_mat4(Mat4::ZERO).inverse().is_none());
}

#[test]
fn empty_box_is_neutral() {
    let b = Aabb::from_min_max(Vec3::ZERO, Vec3::ONE);
    assert_eq!(Aabb::EMPTY.union(&b), b);
    assert!(Aabb::EMPTY.transformed(&Transform34::IDENTITY).is_empty());
    assert!(b.contains(&Aabb::EMPTY, 0.0));
}
