use super::*;

fn curve(points: &[[f32; 3]], basis: &str) -> Curve {
    Curve {
        basis: basis.into(),
        curve_type: "flat".into(),
        degree: 3,
        control_points: points.to_vec(),
        width0: 0.2,
        width1: 0.0,
        normals: None,
    }
}

#[test]
fn a_straight_bezier_becomes_a_tapering_strip_along_it() {
    let c = curve(
        &[
            [0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [0.0, 2.0, 0.0],
            [0.0, 3.0, 0.0],
        ],
        "bezier",
    );
    let m = ribbon(&c).unwrap();
    assert_eq!(m.triangle_count(), 2 * RIBBON_STEPS);
    let b = m.bounds();
    assert!(
        (b.min[1] - 0.0).abs() < 1e-6 && (b.max[1] - 3.0).abs() < 1e-5,
        "{b:?}"
    );
    // Width 0.2 at the root, 0 at the tip, perpendicular to the tangent (y).
    let w0 = (Vec3::from_array(m.positions[0]) - Vec3::from_array(m.positions[1])).length();
    let last = m.positions.len();
    let w1 = (Vec3::from_array(m.positions[last - 2]) - Vec3::from_array(m.positions[last - 1]))
        .length();
    assert!((w0 - 0.2).abs() < 1e-6 && w1 < 1e-6, "{w0} {w1}");
}

#[test]
fn multi_segment_and_bspline_curves_and_degenerate_ones() {
    let seven = [
        [0.0, 0.0, 0.0],
        [1.0, 0.0, 0.0],
        [2.0, 0.0, 0.0],
        [3.0, 0.0, 0.0],
        [4.0, 0.0, 0.0],
        [5.0, 0.0, 0.0],
        [6.0, 0.0, 0.0],
    ];
    assert_eq!(
        ribbon(&curve(&seven, "bezier")).unwrap().triangle_count(),
        2 * 2 * RIBBON_STEPS
    );
    assert_eq!(
        ribbon(&curve(&seven, "bspline")).unwrap().triangle_count(),
        4 * 2 * RIBBON_STEPS
    );
    assert!(ribbon(&curve(&[[1.0; 3]; 4], "bezier")).is_none());
    assert!(ribbon(&curve(&[[0.0; 3]], "bezier")).is_none());
}
