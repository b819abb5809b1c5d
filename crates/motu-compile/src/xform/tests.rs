use super::*;
use glam::{Mat4, Quat, Vec3};

#[test]
fn compose_and_inverse_match_glam() {
    let a = Transform34::from_mat4(Mat4::from_scale_rotation_translation(
        Vec3::new(2.0, 0.5, 3.0),
        Quat::from_rotation_y(0.7),
        Vec3::new(1.0, -2.0, 5.0),
    ));
    let b = Transform34::from_mat4(Mat4::from_rotation_translation(
        Quat::from_rotation_x(-1.1),
        Vec3::new(0.0, 4.0, -1.0),
    ));
    let ab = compose(&a, &b);
    let expect = a.mul(&b);
    for (x, y) in ab.rows.iter().flatten().zip(expect.rows.iter().flatten()) {
        assert!((x - y).abs() < 1e-5, "{ab:?} vs {expect:?}");
    }
    let inv = inverse(&ab).unwrap();
    let id = compose(&ab, &inv);
    assert!(id.is_identity(1e-5), "{id:?}");
    assert_eq!(from_array(&to_array(&ab)), ab);
    let mut flat = Transform34::IDENTITY;
    flat.rows[2][2] = 0.0;
    assert!(inverse(&flat).is_none());
}
