use super::*;

fn close(a: &M64, b: &M64) -> bool {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .all(|(x, y)| (x - y).abs() < 1e-9)
}

#[test]
fn pbrt_order_is_column_major() {
    let v: [f64; 16] = [
        1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 5., 6., 7., 1.,
    ];
    let m = to_f32(&from_pbrt(&v));
    assert_eq!(m.transform_point([0.0; 3]), [5.0, 6.0, 7.0]);
    assert_eq!(m.to_cols_array().map(f64::from), v);
    assert_eq!(Mat4::from_cols_array(&m.to_cols_array()), m);
}

#[test]
fn rotate_z_90() {
    let m = to_f32(&rotate(90.0, [0.0, 0.0, 1.0]));
    let p = m.transform_point([1.0, 0.0, 0.0]);
    assert!((p[0]).abs() < 1e-6 && (p[1] - 1.0).abs() < 1e-6);
    assert_eq!(rotate(10.0, [0.0; 3]), IDENTITY);
}

#[test]
fn inverse_roundtrip() {
    let m = mul(
        &mul(&translate([1.0, 2.0, 3.0]), &rotate(33.0, [1.0, 1.0, 0.0])),
        &scale([2.0, -1.0, 0.5]),
    );
    let inv = inverse(&m).unwrap();
    assert!(close(&mul(&m, &inv), &IDENTITY));
    assert!(inverse(&scale([1.0, 0.0, 1.0])).is_none());
    assert!(to_f32(&m).swaps_handedness());
}

#[test]
fn look_at_maps_eye_to_origin_and_target_to_plus_z() {
    let cam = look_at([1.0, 2.0, 3.0], [1.0, 2.0, 10.0], [0.0, 1.0, 0.0]).unwrap();
    let m = to_f32(&cam);
    assert_eq!(m.transform_point([1.0, 2.0, 3.0]), [0.0, 0.0, 0.0]);
    let t = m.transform_point([1.0, 2.0, 10.0]);
    assert!((t[2] - 7.0).abs() < 1e-5 && t[0].abs() < 1e-6);
    assert!(look_at([0.0; 3], [0.0, 1.0, 0.0], [0.0, 1.0, 0.0]).is_none());
}
