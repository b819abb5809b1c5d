use super::*;
use crate::lexer::Lexer;
use crate::FileId;

fn params(src: &str) -> ParamList<'_> {
    let mut lx = Lexer::new(src.as_bytes(), FileId(0));
    ParamList::parse(&mut lx).unwrap_or_else(|_| panic!("bad test params"))
}

#[test]
fn trianglemesh_basic_and_errors() {
    let mut notes = Vec::new();
    let mut p =
        params(r#""point3 P" [0 0 0 1 0 0 0 1 0] "normal N" [0 0 1] "float uv" [0 0 1 0 0 1]"#);
    let m = triangle_mesh(&mut p, &mut notes).unwrap();
    assert_eq!(m.indices, [0, 1, 2]);
    assert!(m.normals.is_none() && notes.len() == 1);
    assert_eq!(m.uvs.unwrap()[1], [1.0, 0.0]);
    let mut p = params(r#""integer indices" [0 1 5] "point P" [0 0 0 1 0 0 0 1 0]"#);
    assert!(triangle_mesh(&mut p, &mut notes)
        .unwrap_err()
        .contains("out of range"));
    let mut p = params(r#""integer indices" [0 1 2 3] "point P" [0 0 0 1 0 0 0 1 0 1 1 1]"#);
    assert!(triangle_mesh(&mut p, &mut notes)
        .unwrap_err()
        .contains("multiple of 3"));
}

#[test]
fn bilinear_to_triangles() {
    let mut p = params(r#""point3 P" [0 0 0 1 0 0 0 1 0 1 1 0]"#);
    let m = bilinear_mesh(&mut p, &mut Vec::new()).unwrap();
    assert_eq!(m.indices, [0, 1, 3, 0, 3, 2]);
    // The patch is one Ptex face, its second triangle the second half.
    let half = crate::events::FACE_SECOND_HALF;
    assert_eq!(m.face_ids.as_deref(), Some(&[0, half][..]));
    let mut p = params(r#""point3 P" [0 0 0 1 0 0 0 1 0 1 1 0] "integer faceIndices" [7]"#);
    let m = bilinear_mesh(&mut p, &mut Vec::new()).unwrap();
    assert_eq!(m.face_ids.as_deref(), Some(&[7, 7 | half][..]));
}

#[test]
fn face_indices_are_kept_per_triangle() {
    let mut notes = Vec::new();
    let mut p = params(
        r#""point P" [0 0 0 1 0 0 0 1 0 1 1 0] "integer indices" [0 1 2 2 1 3] "integer faceIndices" [4 4]"#,
    );
    let m = triangle_mesh(&mut p, &mut notes).unwrap();
    assert_eq!(m.face_ids.as_deref(), Some(&[4, 4][..]));
    let mut p = params(
        r#""point P" [0 0 0 1 0 0 0 1 0 1 1 0] "integer indices" [0 1 2 2 1 3] "integer faceIndices" [4]"#,
    );
    let m = triangle_mesh(&mut p, &mut notes).unwrap();
    assert_eq!(m.face_ids, None);
    assert!(notes.iter().any(|n| n.contains("faceIndices")), "{notes:?}");
}

#[test]
fn quadrics_are_valid_and_sized() {
    let s = sphere(&params(r#""float radius" 2"#), 16).unwrap();
    assert!(valid(&s));
    for p in &s.positions {
        let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
        assert!((r - 2.0).abs() < 1e-4);
    }
    let d = disk(&params(r#""float radius" 3 "float height" 1"#), 8).unwrap();
    assert!(valid(&d) && d.positions.iter().all(|p| p[2] == 1.0));
    let c = cylinder(&params(r#""float zmax" 5"#), 8).unwrap();
    assert_eq!(c.triangle_count(), 16);
}

#[test]
fn curves() {
    let mut p =
        params(r#""point3 P" [0 0 0 1 0 0 2 0 0 3 0 0] "float width" 0.1 "string type" "ribbon""#);
    let c = curve(&mut p).unwrap();
    assert_eq!(
        (c.control_points.len(), c.width0, c.curve_type.as_str()),
        (4, 0.1, "ribbon")
    );
    let mut p = params(r#""point3 P" [0 0 0 1 0 0]"#);
    assert!(curve(&mut p).is_err());
}

#[test]
fn index_errors_name_the_first_offending_index() {
    assert_eq!(checked_indices(vec![0, 2, 1], 3), Ok(vec![0, 2, 1]));
    assert_eq!(checked_indices(Vec::new(), 0), Ok(Vec::new()));
    // The first bad index in document order, not the smallest or largest one.
    let e = checked_indices(vec![0, 7, -1, 9], 3).unwrap_err();
    assert_eq!(e, "vertex index 7 out of range (3 vertices)");
    let e = checked_indices(vec![0, -4, 7], 3).unwrap_err();
    assert_eq!(e, "vertex index -4 out of range (3 vertices)");
    assert!(checked_indices(vec![3], 3).is_err());
}

/// The vertex arrays become tuples in their own allocation (no second copy of a mesh's
/// vertices), in order, whatever spare capacity the lexer left; a length that is not a
/// multiple of the tuple drops its tail, as the copy did.
#[test]
fn vertex_arrays_become_tuples_in_place() {
    let v: Vec<f32> = (0..12).map(|i| i as f32).collect();
    let (ptr, v) = (v.as_ptr() as usize, v);
    let t = to3(v);
    assert_eq!(t.as_ptr() as usize, ptr, "copied instead of reinterpreted");
    assert_eq!(
        t,
        [
            [0.0, 1.0, 2.0],
            [3.0, 4.0, 5.0],
            [6.0, 7.0, 8.0],
            [9.0, 10.0, 11.0]
        ]
    );
    let mut spare = Vec::with_capacity(64);
    spare.extend((0..6).map(|i| i as f32));
    assert_eq!(to2(spare), [[0.0, 1.0], [2.0, 3.0], [4.0, 5.0]]);
    assert_eq!(to3(vec![1.0, 2.0, 3.0, 4.0]), [[1.0, 2.0, 3.0]]);
    let mut notes = Vec::new();
    let mut p = params(r#""integer indices" [0 1 2] "point P" [0 0 0 1 0 0 0 1 0]"#);
    let m = triangle_mesh(&mut p, &mut notes).unwrap();
    assert_eq!(
        m.positions,
        [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]
    );
}
