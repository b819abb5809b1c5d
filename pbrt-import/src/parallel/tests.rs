use super::*;

fn snap(version: PbrtVersion) -> Snapshot {
    Snapshot {
        version,
        ctm: math::IDENTITY,
        material: Arc::new(Material {
            id: crate::MaterialId(0),
            name: None,
            kind: "matte".into(),
            base_color: None,
            base_color_texture: None,
            opacity: None,
            base_color_image: None,
            ptex: None,
            roughness: None,
            metallic: None,
            loc: Loc::default(),
        }),
        reverse_orientation: false,
        area_light: None,
        tessellation_segments: 8,
    }
}

/// What the old byte prescan let through, the worker parses.
#[test]
fn worker_accepts_placements_and_shapes() {
    let v3 = snap(PbrtVersion::V3);
    let yes: &[&str] = &[
        "AttributeBegin Transform [1 0 0 0 0 1 0 0 0 0 1 0 5 6 7 1] ObjectInstance \"a\" AttributeEnd\n",
        "# c\nShape \"sphere\" \"float radius\" 2\nObjectInstance \"Material\"",
        "TransformBegin Translate 1 2 3 Shape \"trianglemesh\" \"point P\" [0 0 0 1 0 0 0 1 0] TransformEnd",
        "AttributeBegin ReverseOrientation Scale 1E5 1 1 Shape \"disk\" AttributeEnd",
        "Shape \"trianglemesh\" \"point P\" [0.5 1e-3 2 3 4 5 6 7 8 9 10 11 12 13 14]",
    ];
    for t in yes {
        assert!(
            matches!(parse_neutral(t.as_bytes(), &v3), Outcome::Parsed(_)),
            "{t}"
        );
    }
}

/// What the old byte prescan rejected, the worker falls back on: state changes, definitions,
/// unbalanced blocks, malformed text, and pieces with no shape or instance.
#[test]
fn worker_rejects_state_changes_and_definitions() {
    let v3 = snap(PbrtVersion::V3);
    let no: &[&str] = &[
        "Material \"matte\" Shape \"sphere\"",
        "AttributeBegin Material \"matte\" Shape \"sphere\" AttributeEnd",
        "NamedMaterial \"x\" Shape \"sphere\"",
        "ObjectBegin \"a\" Shape \"sphere\" ObjectEnd",
        "Translate 1 2 3 Shape \"sphere\"",
        "Transform [1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1] ObjectInstance \"a\"",
        "ReverseOrientation Shape \"sphere\"",
        "AttributeBegin Shape \"sphere\"",
        "AttributeEnd Shape \"sphere\"",
        "Include \"x.pbrt\"",
        "AttributeBegin LightSource \"point\" AttributeEnd Shape \"sphere\"",
        "AttributeBegin AreaLightSource \"diffuse\" Shape \"sphere\" AttributeEnd",
        "Camera \"perspective\" Shape \"sphere\"",
        "MakeNamedMaterial \"m\" \"string type\" \"matte\" Shape \"sphere\"",
        "Texture \"t\" \"color\" \"constant\" Shape \"sphere\"",
        "CoordinateSystem \"c\" Shape \"sphere\"",
        "Shape \"sphere\" WorldEnd",
        "Shape \"sphere\" \"string x\" \"unterminated\n",
        "# only a comment\n",
        "AttributeBegin Translate 1 2 3 AttributeEnd",
        "",
    ];
    for t in no {
        assert!(
            matches!(parse_neutral(t.as_bytes(), &v3), Outcome::Fallback),
            "{t}"
        );
    }
}

#[test]
fn split_points_cut_at_directive_lines() {
    let text = "AttributeBegin\n  Translate 1 2 3\n  Shape \"sphere\"\nAttributeEnd\n\
                    Shape \"disk\"\n# Comment\nObjectInstance \"a\"\n";
    let cuts = split_points(text.as_bytes(), 1, |_, _| {});
    let lines: Vec<&str> = cuts[1..]
        .iter()
        .map(|&c| text[c..].lines().next().unwrap_or(""))
        .collect();
    assert_eq!(cuts[0], 0);
    assert_eq!(lines, ["Shape \"disk\"", "ObjectInstance \"a\""]);
    assert_eq!(split_points(text.as_bytes(), 1 << 20, |_, _| {}), [0]);
    assert_eq!(split_points(b"", 4, |_, _| {}), [0]);
}

#[test]
fn split_points_release_what_they_scan() {
    // One huge shape, then another: the scan reads line by line from `target` to the second.
    let mut text = String::from("Shape \"trianglemesh\" \"integer indices\" [\n");
    for i in 0..400_000 {
        text.push_str(&format!("  {i} {i} {i}\n"));
    }
    text.push_str("]\nShape \"disk\"\n");
    let mut ranges = Vec::new();
    let cuts = split_points(text.as_bytes(), 100, |a, b| ranges.push((a, b)));
    assert_eq!(cuts.len(), 2);
    assert!(text[cuts[1]..].starts_with("Shape \"disk\""));
    // Released in order, within the file, covering everything from `target` to the cut.
    let mut at = 100;
    for &(a, b) in &ranges {
        assert!(a >= at && a <= b && b <= text.len(), "{a}..{b} after {at}");
        at = b;
    }
    assert_eq!(ranges.first().map(|r| r.0), Some(100));
    assert!(at >= cuts[1], "released up to {at}, cut at {}", cuts[1]);
    assert!(ranges.len() >= 2, "{ranges:?}");
}

#[test]
fn worker_falls_back_on_what_needs_shared_state() {
    let v3 = snap(PbrtVersion::V3);
    let fallback: &[&str] = &[
        "Shape \"plymesh\" \"string filename\" \"a.ply\"",
        "Shape \"nurbs\"",
        "Shape \"bilinearmesh\" \"point P\" [0 0 0 1 0 0 0 1 0 1 1 0]",
        "Shape \"trianglemesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0]",
        "Shape \"sphere\" \"rgb Kd\" [1 0 0]",
        "AttributeBegin Translate 1 2 AttributeEnd Shape \"sphere\"",
        "TransformBegin AttributeEnd Shape \"sphere\"",
        "ObjectInstance 3",
    ];
    for t in fallback {
        assert!(
            matches!(parse_neutral(t.as_bytes(), &v3), Outcome::Fallback),
            "{t}"
        );
    }
    let text = "AttributeBegin Translate 1 2 3 ObjectInstance \"a\" AttributeEnd \
                    ObjectInstance \"b\" ObjectInstance \"a\" Shape \"sphere\"";
    let Outcome::Parsed(p) = parse_neutral(text.as_bytes(), &v3) else {
        panic!("neutral file not parsed");
    };
    assert_eq!(p.names, ["a", "b"]);
    assert_eq!(p.events.len(), 4);
    match &p.events[0] {
        Buffered::Instance {
            name,
            parent_from_instance,
            loc,
            ..
        } => {
            assert_eq!(*name, 0);
            assert_eq!(
                parent_from_instance.to_cols_array()[12..15],
                [1.0, 2.0, 3.0]
            );
            assert_eq!((loc.line, loc.column), (1, 32));
        }
        _ => panic!("expected an instance"),
    }
    match &p.events[1] {
        Buffered::Instance {
            parent_from_instance,
            ..
        } => assert_eq!(*parent_from_instance, crate::Mat4::IDENTITY),
        _ => panic!("expected an instance"),
    }
    assert!(matches!(&p.events[3], Buffered::Shape(s) if s.kind == "sphere"));
}
