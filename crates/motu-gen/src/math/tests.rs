use super::*;

fn close(a: Vec3, b: Vec3) -> bool {
    (0..3).all(|i| (a[i] - b[i]).abs() < 1e-9)
}

#[test]
fn rotation_arc_maps_from_onto_to() {
    for (from, to) in [
        ([0.0, 1.0, 0.0], normalize([1.0, 2.0, -3.0])),
        ([0.0, 1.0, 0.0], [0.0, -1.0, 0.0]),
        ([0.0, 1.0, 0.0], [0.0, 1.0, 0.0]),
    ] {
        let r = Affine::rotation_arc(from, to);
        assert!(close(r.transform_vector(from), to), "{from:?} -> {to:?}");
    }
}

#[test]
fn composition_applies_right_first() {
    let t = Affine::translation([1.0, 0.0, 0.0]);
    let r = Affine::rotation_y(std::f64::consts::FRAC_PI_2);
    // Rotate (1,0,0) about y by 90° -> (0,0,-1), then translate.
    let p = t.mul(&r).transform_point([1.0, 0.0, 0.0]);
    assert!(close(p, [1.0, 0.0, -1.0]), "{p:?}");
    let s = Affine::uniform_scale(2.0).mul(&t);
    assert!(close(s.transform_point([0.0; 3]), [2.0, 0.0, 0.0]));
}
