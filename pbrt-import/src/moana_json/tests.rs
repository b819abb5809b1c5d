use super::*;
use crate::events::Geometry;
use crate::CollectSink;

const QUAD_OBJ: &str = "g leaf\nusemtl green\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";

/// A two-element island: `isA` with geometry, an archive placed twice and a curve file, copied
/// once; `isB` with only geometry under a translation; one camera.
fn island(dir: &Path) {
    let w = |rel: &str, text: &str| {
        let p = dir.join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    };
    w(
        "json/isA/isA.json",
        r#"{"name": "isA", "matFile": "json/isA/materials.json",
            "geomObjFile": "obj/isA/isA.obj",
            "transformMatrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1],
            "instancedCopies": {"isA_copy": {"transformMatrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 100,0,0,1]}},
            "instancedPrimitiveJsonFiles": {
                "xgLeaf": {"type": "archive", "jsonFile": "json/isA/isA_xgLeaf.json",
                           "archives": ["obj/isA/archives/leaf.obj"]},
                "xgHair": {"type": "curve", "jsonFile": "json/isA/isA_xgHair.json",
                           "widthRoot": 0.2, "widthTip": 0.1}}}"#,
    );
    w(
        "json/isA/materials.json",
        r#"{"green": {"baseColor": [0.1, 0.6, 0.2], "roughness": 0.4, "assignment": ["xgHair"]}}"#,
    );
    w(
        "json/isA/isA_xgLeaf.json",
        r#"{"obj/isA/archives/leaf.obj": {"leaf_0": [2,0,0,0, 0,2,0,0, 0,0,2,0, 1,2,3,1],
                                          "leaf_1": [1,0,0,0, 0,1,0,0, 0,0,1,0, 5,0,0,1]}}"#,
    );
    w(
        "json/isA/isA_xgHair.json",
        "[[[0,0,0],[0,1,0],[0,2,0]], [[1,0,0],[1,1,0]]]",
    );
    w(
        "obj/isA/isA.obj",
        "g ground\nusemtl green\nv 0 0 0\nv 9 0 0\nv 0 0 9\nf 1 2 3\n",
    );
    w("obj/isA/archives/leaf.obj", QUAD_OBJ);
    w(
        "json/isB/isB.json",
        r#"{"geomObjFile": "obj/isB/isB.obj",
            "transformMatrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,7,0,1]}"#,
    );
    w("obj/isB/isB.obj", "v 0 0 0\nv 1 0 0\nv 0 0 1\nf 1 2 3\n");
    w(
        "json/cameras/shotCam.json",
        r#"{"eye": [0, 10, 50], "look": [0, 0, 0], "up": [0, 1, 0], "fov": 60, "ratio": 2.0}"#,
    );
}

fn parse(path: &Path, allow_missing: bool) -> Result<(CollectSink, ParseStats), Error> {
    let mut sink = CollectSink::default();
    let opts = ParseOptions {
        allow_missing,
        ..ParseOptions::default()
    };
    let stats = parse_moana_json(path, &opts, &mut sink)?;
    Ok((sink, stats))
}

#[test]
fn reads_elements_archives_copies_curves_and_cameras() {
    let dir = tempfile::tempdir().unwrap();
    island(dir.path());
    for entry in [dir.path().to_path_buf(), dir.path().join("json")] {
        let (sink, stats) = parse(&entry, false).unwrap();
        // isA: one object for the element (copied), one for the leaf archive.
        assert_eq!(sink.objects.len(), 2, "{entry:?}");
        assert_eq!(stats.objects, 2);
        // Leaf placements inside isA (2), isA at its transform and at its copy (2).
        assert_eq!(sink.instances.len(), 4);
        let leaf_object = sink.objects[1].0;
        let leaf: Vec<_> = sink
            .instances
            .iter()
            .filter(|i| i.0 == leaf_object)
            .collect();
        assert_eq!(leaf.len(), 2);
        assert!(leaf.iter().all(|i| i.3 == Some(sink.objects[0].0)));
        assert_eq!(leaf[0].2.to_cols_array()[12..15], [1.0, 2.0, 3.0]);
        let copy = sink.instances.last().unwrap();
        assert_eq!(copy.2.to_cols_array()[12], 100.0);
        // Shapes in pbrt order: the archive's quad, isA's ground, 2 curves, then isB.
        let kinds: Vec<_> = sink.shapes.iter().map(|s| s.kind.as_str()).collect();
        assert_eq!(kinds, ["objmesh", "objmesh", "curve", "curve", "objmesh"]);
        let Geometry::Mesh(quad) = &sink.shapes[0].geometry else {
            panic!("mesh")
        };
        assert_eq!(quad.triangle_count(), 2);
        assert_eq!(sink.shapes[0].material.base_color, Some([0.1, 0.6, 0.2]));
        let Geometry::Curve(c) = &sink.shapes[2].geometry else {
            panic!("curve")
        };
        assert_eq!(c.control_points.len(), 7);
        assert_eq!((c.width0, c.width1), (0.2, 0.1));
        assert_eq!(sink.shapes[2].material.name.as_deref(), Some("isA/green"));
        // isB is placed without an object: its transform is the shape's.
        let b = &sink.shapes[4];
        assert_eq!(b.object, None);
        assert_eq!(b.parent_from_shape.to_cols_array()[13], 7.0);
        let elements: Vec<_> = sink.files.iter().filter_map(|f| f.3.clone()).collect();
        assert!(elements.contains(&"isA".to_string()) && elements.contains(&"isB".to_string()));
        // The camera: mirrored LookAt, fov over the shorter (vertical) side.
        assert_eq!(sink.cameras.len(), 1);
        let cam = &sink.cameras[0].1;
        let expect = 2.0 * ((30f64.to_radians()).tan() / 2.0).atan().to_degrees();
        assert!((f64::from(cam.fov_deg.unwrap()) - expect).abs() < 1e-4);
        assert!(cam.camera_from_world.swaps_handedness());
        assert_eq!(cam.resolution, [1024, 512]);
    }
}

#[test]
fn a_single_element_file_or_folder_is_one_element() {
    let dir = tempfile::tempdir().unwrap();
    island(dir.path());
    for entry in [
        dir.path().join("json/isB/isB.json"),
        dir.path().join("json/isB"),
    ] {
        let (sink, _) = parse(&entry, false).unwrap();
        assert_eq!(sink.shapes.len(), 1, "{entry:?}");
        assert!(sink.cameras.is_empty());
    }
}

#[test]
fn a_scene_list_names_elements_and_cameras() {
    let dir = tempfile::tempdir().unwrap();
    island(dir.path());
    let list = dir.path().join("json/island.json");
    std::fs::write(
        &list,
        r#"{"elements": ["json/isB/isB.json"], "cameras": ["json/cameras/shotCam.json"]}"#,
    )
    .unwrap();
    let (sink, stats) = parse(&list, false).unwrap();
    assert_eq!(sink.shapes.len(), 1);
    assert_eq!(sink.cameras.len(), 1);
    assert!(stats.files.contains(&list));
    assert_eq!(sink.files[0].2, Via::Entry);
}

#[test]
fn truncated_malformed_and_nan_json_name_file_and_offset() {
    let dir = tempfile::tempdir().unwrap();
    island(dir.path());
    let archive = dir.path().join("json/isA/isA_xgLeaf.json");
    let good = std::fs::read_to_string(&archive).unwrap();
    let cases = [
        (good[..good.len() - 20].to_string(), "truncated"),
        (good.replacen("\"leaf_1\":", "\"leaf_1\"", 1), "`:`"),
        (good.replacen("5,0,0,1", "NaN,0,0,1", 1), "non-finite"),
        (good.replacen("5,0,0,1", "5,0,1", 1), "not 16"),
    ];
    for (text, needle) in cases {
        std::fs::write(&archive, &text).unwrap();
        let e = parse(dir.path(), false).unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, Error::Json { .. }), "{msg}");
        assert!(msg.contains("isA_xgLeaf.json: byte "), "{msg}");
        assert!(msg.contains(needle), "{needle}: {msg}");
    }
    std::fs::write(&archive, &good).unwrap();
    // A NaN in an element's own transform.
    let el = dir.path().join("json/isB/isB.json");
    let text = r#"{"geomObjFile": "obj/isB/isB.obj", "transformMatrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,NaN,0,1]}"#;
    std::fs::write(&el, text).unwrap();
    let msg = parse(dir.path(), false).unwrap_err().to_string();
    let offset = text.find("[1,0").unwrap();
    let at = format!("isB.json: byte {offset} (line 1, column {})", offset + 1);
    assert!(msg.contains(&at) && msg.contains("non-finite"), "{msg}");
}

#[test]
fn a_missing_obj_is_an_error_unless_allowed() {
    let dir = tempfile::tempdir().unwrap();
    island(dir.path());
    std::fs::remove_file(dir.path().join("obj/isA/archives/leaf.obj")).unwrap();
    let e = parse(dir.path(), false).unwrap_err();
    assert!(matches!(e, Error::MissingFiles { .. }), "{e}");
    assert!(e.to_string().contains("leaf.obj (from "), "{e}");
    assert!(e.to_string().contains("isA.json:"), "{e}");
    let (sink, stats) = parse(dir.path(), true).unwrap();
    assert_eq!(stats.missing.len(), 1);
    // The leaf's placements go with it; the element and its copy stay.
    assert_eq!(sink.instances.len(), 2);
    assert!(sink.warnings.iter().any(|w| w.message.contains("leaf.obj")));
}

#[test]
fn a_malformed_obj_names_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    island(dir.path());
    std::fs::write(dir.path().join("obj/isB/isB.obj"), "v 0 0 0\nf 1 2 3\n").unwrap();
    let e = parse(dir.path(), false).unwrap_err();
    assert!(e.to_string().contains("isB.obj:2: "), "{e}");
}

#[test]
fn ptex_paths_are_kept_per_material_on_both_routes() {
    let dir = tempfile::tempdir().unwrap();
    island(dir.path());
    std::fs::write(
        dir.path().join("json/isA/materials.json"),
        r#"{"green": {"baseColor": [0.1, 0.6, 0.2], "colorMap": "textures/isA/Color"}}"#,
    )
    .unwrap();
    let (sink, _) = parse(dir.path(), false).unwrap();
    let ptex: Vec<_> = sink
        .shapes
        .iter()
        .filter_map(|s| s.material.ptex.clone())
        .collect();
    let root = dir.path();
    assert_eq!(
        ptex,
        [
            root.join("textures/isA/Color/leaf.ptx"),
            root.join("textures/isA/Color/ground.ptx")
        ]
    );
    // Each textured group has a material of its own, with the base material's colour.
    assert_ne!(sink.shapes[0].material.id, sink.shapes[1].material.id);
    assert_eq!(sink.shapes[1].material.base_color, Some([0.1, 0.6, 0.2]));
    // pbrt: a `ptex` texture behind the base colour, also through a shape-level override.
    let text = r#"WorldBegin
Texture "c" "spectrum" "ptex" "string filename" "tex/a.ptx"
Material "diffuse" "texture reflectance" "c"
Shape "trianglemesh" "integer indices" [0 1 2] "point3 P" [0 0 0 1 0 0 0 1 0]
Texture "f" "float" "ptex" "string filename" "tex/alpha.ptx"
Material "diffuse" "texture reflectance" "f"
Shape "trianglemesh" "integer indices" [0 1 2] "point3 P" [0 0 0 1 0 0 0 1 0]
"#;
    let mut sink = CollectSink::default();
    crate::parse_str(text, root, &ParseOptions::default(), &mut sink).unwrap();
    assert_eq!(sink.shapes[0].material.ptex, Some(root.join("tex/a.ptx")));
    assert_eq!(
        sink.shapes[1].material.ptex, None,
        "float textures are no colour"
    );
}

#[test]
fn a_json_file_that_is_no_element_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("path.json");
    std::fs::write(&p, r#"{"frames": []}"#).unwrap();
    let e = parse(&p, false).unwrap_err().to_string();
    assert!(
        e.contains("path.json: byte 0") && e.contains("not a Moana element"),
        "{e}"
    );
}
