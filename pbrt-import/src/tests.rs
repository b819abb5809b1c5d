//! Directive-family tests through the public API.

use std::path::Path;

use crate::*;

fn opts(version: VersionOption) -> ParseOptions {
    ParseOptions {
        version,
        ply_loading: PlyLoading::Sequential,
        ..Default::default()
    }
}

fn run_v(src: &str, version: VersionOption) -> Result<(CollectSink, ParseStats), Error> {
    let mut sink = CollectSink::default();
    let stats = parse_str(src, Path::new("/nonexistent"), &opts(version), &mut sink)?;
    Ok((sink, stats))
}

fn run(src: &str) -> (CollectSink, ParseStats) {
    run_v(src, VersionOption::Auto).unwrap_or_else(|e| panic!("{e}"))
}

/// `(line, column, token, message)` of a parse error.
fn err(src: &str, version: VersionOption) -> (u32, u32, String, String) {
    match run_v(src, version) {
        Err(Error::Parse(e)) => (e.loc.line, e.loc.column, e.token, e.kind.to_string()),
        Err(e) => panic!("unexpected error {e}"),
        Ok(_) => panic!("expected an error"),
    }
}

const TRI: &str = r#"Shape "trianglemesh" "integer indices" [0 1 2] "point P" [0 0 0 1 0 0 0 1 0]"#;

fn origin_of(m: &Mat4) -> [f32; 3] {
    m.transform_point([0.0; 3])
}

fn close3(a: [f32; 3], b: [f32; 3]) -> bool {
    a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-5)
}

#[test]
fn transforms_compose_like_pbrt() {
    let (s, _) = run(&format!(
        "WorldBegin\nTranslate 1 2 3\nScale 2 2 2\n{TRI}\nIdentity\nRotate 90 0 0 1\nTranslate 1 0 0\n{TRI}\n\
         Transform [1 0 0 0 0 1 0 0 0 0 1 0 5 6 7 1]\nConcatTransform [2 0 0 0 0 2 0 0 0 0 2 0 1 0 0 1]\n{TRI}"
    ));
    assert_eq!(s.shapes.len(), 3);
    let m0 = s.shapes[0].parent_from_shape;
    assert_eq!(m0.transform_point([1.0, 0.0, 0.0]), [3.0, 2.0, 3.0]);
    assert!(close3(
        origin_of(&s.shapes[1].parent_from_shape),
        [0.0, 1.0, 0.0]
    ));
    assert_eq!(origin_of(&s.shapes[2].parent_from_shape), [6.0, 6.0, 7.0]);
}

#[test]
fn coordinate_systems_and_active_transform() {
    let (s, _) = run(&format!(
        "WorldBegin\nTranslate 1 0 0\nCoordinateSystem \"a\"\nIdentity\nCoordSysTransform \"a\"\n{TRI}\n\
         ActiveTransform EndTime\nTranslate 0 5 0\nActiveTransform All\n{TRI}\nCoordSysTransform \"nope\"\n"
    ));
    assert_eq!(origin_of(&s.shapes[0].parent_from_shape), [1.0, 0.0, 0.0]);
    // Only the end transform moved; events carry the start transform.
    assert_eq!(origin_of(&s.shapes[1].parent_from_shape), [1.0, 0.0, 0.0]);
    assert!(s.warnings.iter().any(|w| w.message.contains("nope")));
}

#[test]
fn transform_begin_saves_only_the_transform() {
    let (s, _) = run(&format!(
        "WorldBegin\nMakeNamedMaterial \"red\" \"string type\" \"matte\" \"rgb Kd\" [1 0 0]\n\
         TransformBegin\nTranslate 1 0 0\nNamedMaterial \"red\"\nReverseOrientation\nTransformEnd\n{TRI}"
    ));
    let sh = &s.shapes[0];
    assert_eq!(origin_of(&sh.parent_from_shape), [0.0; 3]);
    assert_eq!(sh.material.name.as_deref(), Some("red"));
    assert!(sh.reverse_orientation);
}

#[test]
fn attribute_block_restores_everything() {
    let (s, _) = run(&format!(
        "WorldBegin\nAttributeBegin\nTranslate 1 0 0\nMaterial \"matte\" \"rgb Kd\" [0 1 0]\n\
         AreaLightSource \"diffuse\" \"rgb L\" [2 2 2] \"float scale\" 3\n{TRI}\nAttributeEnd\n{TRI}"
    ));
    assert_eq!(s.shapes[0].material.base_color, Some([0.0, 1.0, 0.0]));
    assert_eq!(
        s.shapes[0].area_light.as_ref().and_then(|a| a.radiance),
        Some([6.0; 3])
    );
    assert_eq!(s.shapes[1].material.id, MaterialId(0));
    assert!(s.shapes[1].area_light.is_none());
    assert_eq!(origin_of(&s.shapes[1].parent_from_shape), [0.0; 3]);
}

#[test]
fn v3_object_may_close_after_attribute_end() {
    let src = format!("WorldBegin\nAttributeBegin\nObjectBegin \"o\"\n{TRI}\nAttributeEnd\nObjectEnd\nObjectInstance \"o\"\n");
    let (s, stats) = run_v(&src, VersionOption::V3).unwrap();
    assert_eq!((stats.objects, stats.instances), (1, 1));
    assert_eq!(s.shapes[0].object, Some(ObjectId(0)));
    let (line, col, tok, msg) = err(&src, VersionOption::V4);
    assert_eq!((line, col, tok.as_str()), (5, 1, "AttributeEnd"));
    assert!(msg.contains("closes ObjectBegin"), "{msg}");
}

#[test]
fn object_redefinition_v3_warns_v4_errors() {
    let src = format!("WorldBegin\nObjectBegin \"o\"\n{TRI}\nObjectEnd\nObjectBegin \"o\"\nObjectEnd\nObjectInstance \"o\"\n");
    let (s, _) = run_v(&src, VersionOption::V3).unwrap();
    assert_eq!(
        s.objects.iter().map(|o| o.0).collect::<Vec<_>>(),
        [ObjectId(0), ObjectId(1)]
    );
    assert_eq!(s.instances[0].0, ObjectId(1), "later definition wins");
    assert!(s.warnings.iter().any(|w| w.message.contains("redefined")));
    let (line, col, tok, _) = err(&src, VersionOption::V4);
    assert_eq!((line, col, tok.as_str()), (5, 13, "\"o\""));
}

#[test]
fn instances_nested_and_forward() {
    let src = format!(
        "WorldBegin\nObjectBegin \"leaf\"\n{TRI}\nObjectEnd\nObjectBegin \"tree\"\nTranslate 0 1 0\nObjectInstance \"leaf\"\nObjectEnd\n\
         Translate 5 0 0\nObjectInstance \"tree\"\n"
    );
    let (s, _) = run(&src);
    assert_eq!(s.instances.len(), 2);
    let (leaf, _, m, inside) = &s.instances[0];
    assert_eq!((*leaf, *inside), (ObjectId(0), Some(ObjectId(1))));
    assert_eq!(origin_of(m), [0.0, 1.0, 0.0]);
    assert_eq!(origin_of(&s.instances[1].2), [5.0, 0.0, 0.0]);
    // pbrt-v4 resolves instances at the end; pbrt-v3 requires definition first.
    let fwd =
        format!("WorldBegin\nObjectInstance \"later\"\nObjectBegin \"later\"\n{TRI}\nObjectEnd\n");
    assert!(run_v(&fwd, VersionOption::V4).is_ok());
    assert_eq!(err(&fwd, VersionOption::V3).0, 2);
    let (line, col, tok, msg) = err("WorldBegin\nObjectInstance \"never\"\n", VersionOption::V4);
    assert_eq!(
        (line, col, tok.as_str(), msg.as_str()),
        (2, 16, "\"never\"", "unknown object name")
    );
    assert!(err(
        "WorldBegin\nObjectBegin \"a\"\nObjectBegin \"b\"\n",
        VersionOption::V3
    )
    .3
    .contains("inside"));
}

#[test]
fn v3_shape_level_material_override() {
    let src = format!(
        "WorldBegin\nMaterial \"matte\" \"rgb Kd\" [1 0 0]\n{TRI} \"rgb Kd\" [0 0 1]\n{TRI}\n"
    );
    let (s, _) = run_v(&src, VersionOption::V3).unwrap();
    assert_eq!(s.shapes[0].material.base_color, Some([0.0, 0.0, 1.0]));
    assert_ne!(s.shapes[0].material.id, s.shapes[1].material.id);
    assert_eq!(s.shapes[1].material.base_color, Some([1.0, 0.0, 0.0]));
    let (s, _) = run_v(&src, VersionOption::V4).unwrap();
    assert_eq!(s.shapes[0].material.base_color, Some([1.0, 0.0, 0.0]));
}

#[test]
fn textures_reduce_to_constants() {
    let src = format!(
        "WorldBegin\nTexture \"c\" \"color\" \"constant\" \"rgb value\" [0.2 0.4 0.6]\n\
         Texture \"s\" \"color\" \"scale\" \"texture tex1\" \"c\" \"float tex2\" 0.5\n\
         Texture \"img\" \"spectrum\" \"imagemap\" \"string filename\" \"missing.png\"\n\
         Texture \"a\" \"float\" \"imagemap\" \"string filename\" \"alpha.png\"\n\
         Material \"matte\" \"texture Kd\" \"s\"\n{TRI} \"texture alpha\" \"a\"\n\
         Material \"diffuse\" \"texture reflectance\" \"img\"\n{TRI}\n"
    );
    let (s, _) = run_v(&src, VersionOption::V3).unwrap();
    assert_eq!(s.shapes[0].material.base_color, Some([0.1, 0.2, 0.3]));
    assert_eq!(
        s.shapes[0].material.base_color_texture.as_deref(),
        Some("s")
    );
    assert_eq!(s.shapes[0].alpha_texture.as_deref(), Some("a"));
    assert_eq!(s.shapes[1].material.base_color, Some([0.5; 3]));
    assert!(s.warnings.iter().any(|w| w.message.contains("missing.png")));
    // Redefinition: v3 warns (later wins), v4 errors.
    let redef =
        "WorldBegin\nTexture \"t\" \"float\" \"constant\"\nTexture \"t\" \"float\" \"constant\"\n";
    assert!(run_v(redef, VersionOption::V3).is_ok());
    assert_eq!(err(redef, VersionOption::V4).0, 3);
}

#[test]
fn colour_parameter_types() {
    let src = format!(
        "WorldBegin\nMakeNamedMaterial \"x\" \"string type\" \"diffuse\" \"xyz reflectance\" [0.95047 1 1.08883]\n\
         MakeNamedMaterial \"s\" \"string type\" \"diffuse\" \"spectrum reflectance\" [300 .3 800 .3]\n\
         MakeNamedMaterial \"m\" \"string type\" \"mix\" \"string materials\" [\"x\" \"s\"] \"float amount\" 0.5\n\
         LightSource \"point\" \"blackbody I\" 2700 \"float scale\" 2\n\
         LightSource \"infinite\" \"rgb L\" [1 2 3] \"rgb scale\" [2 2 2]\n{TRI}"
    );
    let (s, _) = run(&src);
    let by = |n: &str| {
        s.materials
            .iter()
            .find(|m| m.name.as_deref() == Some(n))
            .and_then(|m| m.base_color)
            .unwrap()
    };
    assert!(close3(by("x"), [1.0; 3]));
    assert!(close3(by("s"), [0.3; 3]));
    // mix takes its dominant side whole (amount ≥ 0.5: the second material).
    assert!(close3(by("m"), [0.3; 3]));
    let bb = s.lights[0].color.unwrap();
    assert_eq!(bb[0], 2.0);
    assert!(bb[2] < bb[0]);
    assert_eq!(s.lights[1].color, Some([2.0, 4.0, 6.0]));
}

#[test]
fn cameras_and_film() {
    let src = "Scale -1 1 1\nLookAt 0 0 5  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" 45 \
               \"float screenwindow\" [-1 1 -0.5 0.5]\nFilm \"image\" \"integer xresolution\" 64 \"integer yresolution\" 32\n\
               WorldBegin\n";
    let (s, stats) = run(src);
    assert_eq!(stats.cameras, 1);
    let (stem, c) = &s.cameras[0];
    assert_eq!(stem, "<input>");
    assert_eq!(
        (c.fov_deg, c.resolution, c.screen_window),
        (Some(45.0), [64, 32], Some([-1.0, 1.0, -0.5, 0.5]))
    );
    assert!(close3(
        c.world_from_camera.transform_point([0.0; 3]),
        [0.0, 0.0, 5.0]
    ));
    assert!(close3(
        c.camera_from_world.transform_point([0.0; 3]),
        [0.0, 0.0, 5.0]
    ));
}

#[test]
fn quadrics_curves_and_unsupported_are_counted() {
    let src = "WorldBegin\nShape \"sphere\" \"float radius\" 2\nShape \"disk\"\nShape \"cylinder\"\n\
               Shape \"curve\" \"point P\" [0 0 0 1 0 0 2 0 0 3 0 0] \"float width\" 0.1\n\
               Shape \"nurbs\"\nShape \"loopsubdiv\" \"integer indices\" [0 1 2] \"point P\" [0 0 0 1 0 0 0 1 0]\n\
               Shape \"bilinearmesh\" \"point3 P\" [0 0 0 1 0 0 0 1 0 1 1 0]";
    let (s, stats) = run(src);
    assert_eq!(
        (stats.shapes, stats.curves, stats.unsupported_shapes),
        (7, 1, 1)
    );
    assert!(matches!(s.shapes[3].geometry, Geometry::Curve(ref c) if c.control_points.len() == 4));
    assert_eq!(
        stats.version,
        Some(PbrtVersion::V4),
        "bilinearmesh and point3 are v4"
    );
    // Invalid meshes are skipped with a warning, like pbrt.
    let (_, stats) = run("WorldBegin\nShape \"trianglemesh\" \"integer indices\" [0 1 7] \"point P\" [0 0 0 1 0 0 0 1 0]");
    assert_eq!((stats.shapes, stats.skipped_shapes), (0, 1));
}

#[test]
fn ignored_directives_are_validated() {
    let src = "Option \"bool disablepixeljitter\" true\nColorSpace \"srgb\"\nSampler \"halton\" \"integer pixelsamples\" 4\n\
               Integrator \"path\"\nAccelerator \"bvh\"\nPixelFilter \"box\"\nTransformTimes 0 1\nWorldBegin\n\
               MakeNamedMedium \"fog\" \"string type\" \"homogeneous\"\nMediumInterface \"fog\" \"\"\nMediumInterface \"fog\"\n\
               Attribute \"shape\" \"float radius\" 2\nWorldEnd\n";
    let (_, stats) = run(src);
    assert_eq!(stats.version, Some(PbrtVersion::V4));
    assert!(err(
        "Sampler \"halton\" \"integer pixelsamples\" \"x\"",
        VersionOption::Auto
    )
    .3
    .contains("integer"));
}

#[test]
fn errors_have_exact_positions() {
    let e = err("WorldBegin\n  Shapo \"sphere\"\n", VersionOption::Auto);
    assert_eq!(e, (2, 3, "Shapo".into(), "unknown directive".into()));
    let e = err(
        "WorldBegin\nShape \"sphere\" \"float radius\" \"big\"\n",
        VersionOption::Auto,
    );
    assert_eq!((e.0, e.1, e.2.as_str()), (2, 31, "\"big\""));
    let e = err("WorldBegin\nAttributeEnd\n", VersionOption::Auto);
    assert_eq!((e.0, e.1, e.2.as_str()), (2, 1, "AttributeEnd"));
    assert!(e.3.starts_with("unbalanced block"));
    let e = err("WorldBegin\nAttributeBegin\n", VersionOption::Auto);
    assert_eq!(
        (e.0, e.1, e.3.as_str()),
        (2, 1, "unbalanced block: AttributeBegin never closed")
    );
    let e = err("WorldBegin\nObjectInstance \"ghost\"\n", VersionOption::V3);
    assert_eq!((e.0, e.1, e.3.as_str()), (2, 16, "unknown object name"));
    let e = err(
        "WorldBegin\nShape \"sphere\" \"float radius\" [ 1 2x ]\n",
        VersionOption::Auto,
    );
    assert_eq!((e.0, e.1, e.2.as_str()), (2, 35, "2x ]"));
    let e = err("Translate 1 2\n", VersionOption::Auto);
    assert_eq!((e.0, e.2.as_str()), (1, "Translate"));
    let e = err("WorldBegin\nShape \"sphere\n", VersionOption::Auto);
    assert_eq!((e.0, e.1), (2, 7));
    let e = err("[ 1 ]", VersionOption::Auto);
    assert_eq!(e.3, "expected a directive");
    // Display form is file:line:column.
    let full = run_v("Bogus", VersionOption::Auto).unwrap_err().to_string();
    assert_eq!(
        full,
        "/nonexistent/<input>:1:1: unknown directive (at `Bogus`)"
    );
}

#[test]
fn includes_imports_elements_and_missing_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    std::fs::create_dir_all(d.join("isBeach")).unwrap();
    std::fs::write(
        d.join("isBeach/isBeach.pbrt"),
        format!("Include \"geo.pbrt\"\nImport \"imp.pbrt\"\n{TRI}\n"),
    )
    .unwrap();
    std::fs::write(
        d.join("isBeach/geo.pbrt"),
        format!("Translate 1 0 0\n{TRI}\n"),
    )
    .unwrap();
    std::fs::write(
        d.join("isBeach/imp.pbrt"),
        format!("Translate 0 9 0\n{TRI}\n"),
    )
    .unwrap();
    std::fs::write(
        d.join("main.pbrt"),
        "Include \"cam.pbrt\"\nWorldBegin\nInclude \"isBeach/isBeach.pbrt\"\nInclude \"gone1.pbrt\"\n\
         Shape \"plymesh\" \"string filename\" \"gone2.ply\"\n",
    )
    .unwrap();
    std::fs::write(d.join("cam.pbrt"), "Camera \"perspective\"\n").unwrap();
    let main = d.join("main.pbrt");
    let Err(Error::MissingFiles { files }) =
        parse_file(&main, &ParseOptions::default(), &mut CollectSink::default())
    else {
        panic!("expected missing files")
    };
    let names: Vec<_> = files
        .iter()
        .map(|f| f.path.file_name().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["gone1.pbrt", "gone2.ply"]);
    assert_eq!(
        (files[1].referenced_at.line, files[1].referenced_at.column),
        (5, 7)
    );
    let mut s = CollectSink::default();
    let o = ParseOptions {
        allow_missing: true,
        ..Default::default()
    };
    let stats = parse_file(&main, &o, &mut s).unwrap();
    assert_eq!(stats.missing.len(), 2);
    assert_eq!(stats.skipped_shapes, 1);
    let files: Vec<_> = s.files.iter().map(|f| (f.1, f.2, f.3.clone())).collect();
    assert_eq!(
        files,
        [
            (0, Via::Entry, None),
            (1, Via::Include, None),
            (1, Via::Include, Some("isBeach".into())),
            (2, Via::Include, Some("isBeach".into())),
            (2, Via::Import, Some("isBeach".into())),
        ]
    );
    // Include shares state (the Translate leaks), Import restores it.
    let origins: Vec<_> = s
        .shapes
        .iter()
        .map(|x| origin_of(&x.parent_from_shape))
        .collect();
    assert_eq!(origins, [[1.0, 0.0, 0.0], [1.0, 9.0, 0.0], [1.0, 0.0, 0.0]]);
    assert!(s.shapes.iter().all(|x| x.element == Some(ElementId(0))));
    assert_eq!(s.cameras[0].0, "cam");
}

#[test]
fn regression_nonfinite_camera_light_and_transforms_are_errors() {
    let (line, col, token, msg) = err(
        "Camera \"perspective\" \"float fov\" [ nan ]\nWorldBegin\n",
        VersionOption::Auto,
    );
    assert_eq!((line, col, token.as_str()), (1, 22, "fov"), "{msg}");
    assert!(msg.contains("finite"), "{msg}");
    let (line, _, _, msg) = err(
        "WorldBegin\nLightSource \"distant\" \"rgb L\" [inf 1 1]\n",
        VersionOption::Auto,
    );
    assert_eq!(line, 2, "{msg}");
    let (line, col, _, msg) = err("WorldBegin\nRotate 30 nan 0 1\n", VersionOption::Auto);
    assert_eq!((line, col), (2, 1), "{msg}");
    assert!(
        msg.contains("value 2 of `Rotate`") || msg.contains("value 2 of"),
        "{msg}"
    );
    // A zero axis is warned about (with its location) and ignored.
    let (sink, stats) = run(&format!("WorldBegin\nRotate 30 0 0 0\n{TRI}\n"));
    assert_eq!(stats.warnings, 1);
    assert!(sink
        .warnings
        .iter()
        .any(|w| w.message.contains("zero axis")));
}

#[test]
fn regression_include_cycle_detected_at_first_repeat() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("root.pbrt"),
        "WorldBegin\nInclude \"root.pbrt\"\n",
    )
    .unwrap();
    let mut sink = CollectSink::default();
    let e = parse_file(
        &dir.path().join("root.pbrt"),
        &ParseOptions::default(),
        &mut sink,
    )
    .unwrap_err();
    assert!(e.to_string().contains("root.pbrt:2:9"), "{e}");
    assert!(e.to_string().contains("recursive"), "{e}");
    // The root was entered once, not parsed a second time.
    assert_eq!(sink.files.len(), 1, "{:?}", sink.files);
}

#[test]
fn include_cycles_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("a.pbrt"), "Include \"b.pbrt\"\n").unwrap();
    std::fs::write(dir.path().join("b.pbrt"), "Include \"a.pbrt\"\n").unwrap();
    let e = parse_file(
        &dir.path().join("a.pbrt"),
        &ParseOptions::default(),
        &mut CollectSink::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("recursive"), "{e}");
}

#[test]
fn ply_shapes_parallel_and_sequential_agree() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = Mesh {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [0.0, 1.0, 0.0],
            [1.0, 1.0, 0.0],
        ],
        normals: None,
        uvs: None,
        indices: vec![0, 1, 2, 2, 1, 3],
        face_ids: None,
    };
    std::fs::write(dir.path().join("m.ply"), ply::write_ply_binary_le(&mesh)).unwrap();
    std::fs::write(
        dir.path().join("bad.ply"),
        b"ply\nformat ascii 1.0\nend_header\n",
    )
    .unwrap();
    let mut src = String::from(
        "WorldBegin\nMakeNamedMaterial \"g\" \"string type\" \"matte\" \"rgb Kd\" [0 1 0]\n",
    );
    for i in 0..10 {
        src.push_str(&format!("AttributeBegin\nTranslate {i} 0 0\nNamedMaterial \"g\"\nShape \"plymesh\" \"string filename\" \"m.ply\"\nAttributeEnd\n{TRI}\n"));
    }
    let run_with = |ply_loading| {
        let mut s = CollectSink::default();
        let o = ParseOptions {
            ply_loading,
            ..Default::default()
        };
        parse_str(&src, dir.path(), &o, &mut s).unwrap();
        let mut plys: Vec<_> = s
            .shapes
            .iter()
            .filter(|x| x.kind == "plymesh")
            .map(|x| (x.seq, origin_of(&x.parent_from_shape), x.material.id))
            .collect();
        plys.sort_by_key(|p| p.0);
        (plys, s.shapes.iter().map(|x| x.seq).collect::<Vec<_>>())
    };
    let (seq_plys, seq_order) = run_with(PlyLoading::Sequential);
    let (par_plys, par_order) = run_with(PlyLoading::Parallel {
        batch_bytes: 1 << 20,
    });
    assert_eq!(seq_plys, par_plys);
    assert_eq!(seq_plys.len(), 10);
    assert_eq!(seq_plys[3].1, [3.0, 0.0, 0.0]);
    assert!(seq_order.windows(2).all(|w| w[0] < w[1]));
    assert_ne!(
        seq_order, par_order,
        "parallel mode delivers PLY shapes later"
    );
    let e = parse_str(
        "WorldBegin\n\nShape \"plymesh\" \"string filename\" \"bad.ply\"",
        dir.path(),
        &ParseOptions::default(),
        &mut CollectSink::default(),
    )
    .unwrap_err();
    assert!(
        matches!(e, Error::Ply { ref referenced_at, .. } if referenced_at.line == 3),
        "{e}"
    );
}

#[test]
fn sink_errors_stop_the_parse() {
    struct Stop;
    impl SceneSink for Stop {
        fn shape(&mut self, _s: ShapeEvent) -> Result<(), SinkError> {
            Err(SinkError::new("full"))
        }
    }
    let e = parse_str(
        &format!("WorldBegin\n{TRI}"),
        Path::new("."),
        &ParseOptions::default(),
        &mut Stop,
    )
    .unwrap_err();
    assert!(matches!(e, Error::Sink(_)));
}

mod props {
    use super::*;
    use proptest::prelude::*;

    fn finite() -> impl Strategy<Value = f32> {
        prop_oneof![-1.0e6f32..1.0e6, Just(0.0), Just(-0.0), 1.0e-30f32..1.0e-20]
    }

    fn mesh() -> impl Strategy<Value = Mesh> {
        (1usize..6, any::<bool>(), any::<bool>()).prop_flat_map(|(n_tris, with_n, with_uv)| {
            let nv = n_tris + 2;
            (
                proptest::collection::vec([finite(), finite(), finite()], nv),
                proptest::collection::vec(0..nv as u32, n_tris * 3),
                proptest::collection::vec([finite(), finite(), finite()], nv),
                proptest::collection::vec([finite(), finite()], nv),
            )
                .prop_map(move |(positions, indices, normals, uvs)| Mesh {
                    positions,
                    normals: with_n.then_some(normals),
                    uvs: with_uv.then_some(uvs),
                    indices,
                    face_ids: None,
                })
        })
    }

    fn matrix() -> impl Strategy<Value = Mat4> {
        proptest::array::uniform16(-100.0f32..100.0).prop_map(|mut v| {
            v[3] = 0.0;
            v[7] = 0.0;
            v[11] = 0.0;
            v[15] = 1.0;
            Mat4::from_cols_array(&v)
        })
    }

    #[derive(Debug, Clone)]
    struct Scene {
        colors: Vec<[f32; 3]>,
        objects: Vec<(usize, Mesh, Mat4)>,
        instances: Vec<(usize, Mat4)>,
        loose: Vec<(usize, Mesh, Mat4)>,
    }

    fn scene() -> impl Strategy<Value = Scene> {
        (
            proptest::collection::vec([0.0f32..1.0, 0.0f32..1.0, 0.0f32..1.0], 1..4),
            proptest::collection::vec((0usize..4, mesh(), matrix()), 0..4),
            proptest::collection::vec((0usize..8, matrix()), 0..8),
            proptest::collection::vec((0usize..4, mesh(), matrix()), 0..4),
        )
            .prop_map(|(colors, objects, instances, loose)| Scene {
                colors,
                objects,
                instances,
                loose,
            })
    }

    fn write(s: &Scene) -> String {
        let mut w = writer::Writer::new();
        w.look_at([0.0, 0.0, 5.0], [0.0; 3], [0.0, 1.0, 0.0]);
        w.perspective_camera(40.0);
        w.world_begin();
        for (i, c) in s.colors.iter().enumerate() {
            w.named_diffuse(&format!("m \"{i}\""), *c);
        }
        for (i, (m, mesh, xf)) in s.objects.iter().enumerate() {
            w.object_begin(&format!("obj{i}"));
            w.attribute_begin();
            w.named_material(&format!("m \"{}\"", m % s.colors.len()));
            w.transform(xf);
            w.triangle_mesh(mesh);
            w.attribute_end();
            w.object_end();
        }
        if !s.objects.is_empty() {
            for (o, xf) in &s.instances {
                w.attribute_begin();
                w.transform(xf);
                w.object_instance(&format!("obj{}", o % s.objects.len()));
                w.attribute_end();
            }
        }
        for (m, mesh, xf) in &s.loose {
            w.attribute_begin();
            w.transform(xf);
            w.named_material(&format!("m \"{}\"", m % s.colors.len()));
            w.triangle_mesh(mesh);
            w.attribute_end();
        }
        w.finish()
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

        #[test]
        fn write_parse_round_trip(s in scene()) {
            let text = write(&s);
            let (sink, stats) = run(&text);
            let expected_instances = if s.objects.is_empty() { 0 } else { s.instances.len() };
            prop_assert_eq!(stats.instances as usize, expected_instances);
            prop_assert_eq!(sink.shapes.len(), s.objects.len() + s.loose.len());
            let all: Vec<_> = s.objects.iter().map(|o| (o, true)).chain(s.loose.iter().map(|o| (o, false))).collect();
            for (shape, ((m, mesh, xf), in_obj)) in sink.shapes.iter().zip(all) {
                prop_assert_eq!(&shape.geometry, &Geometry::Mesh(mesh.clone()));
                prop_assert_eq!(shape.object.is_some(), in_obj);
                prop_assert_eq!(shape.material.base_color, Some(s.colors[m % s.colors.len()]));
                for (a, b) in shape.parent_from_shape.to_cols_array().iter().zip(xf.to_cols_array()) {
                    prop_assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0));
                }
            }
            for ((o, _, m, inside), (oi, xf)) in sink.instances.iter().zip(&s.instances) {
                prop_assert_eq!(o.0 as usize, oi % s.objects.len());
                prop_assert!(inside.is_none());
                prop_assert_eq!(m.to_cols_array(), xf.to_cols_array());
            }
            prop_assert_eq!(sink.cameras.len(), 1);
        }

        #[test]
        fn never_panics_on_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..256)) {
            let _ = parse_bytes(&bytes, Path::new("/nonexistent"), &ParseOptions::default(), &mut CollectSink::default());
            let _ = ply::parse_ply(&bytes);
        }

        #[test]
        fn never_panics_on_token_soup(words in proptest::collection::vec(prop_oneof![
            Just("WorldBegin"), Just("AttributeBegin"), Just("AttributeEnd"), Just("ObjectBegin \"a\""), Just("ObjectEnd"),
            Just("ObjectInstance \"a\""), Just("TransformBegin"), Just("TransformEnd"), Just("Shape \"sphere\""),
            Just("Shape \"trianglemesh\""), Just("\"integer indices\" [0 1 2]"), Just("\"point P\" [0 0 0 1 0 0 0 1 0]"),
            Just("Translate 1 2 3"), Just("Material \"matte\""), Just("\"rgb Kd\" [1 0"), Just("]"), Just("["),
            Just("Import \"x\""), Just("Texture \"t\" \"color\" \"mix\""), Just("LookAt 0 0 0 0 0 0 0 0 0"), Just("Camera \"perspective\""),
            Just("\"float fov\""), Just("\""), Just("#"), Just("\n"), Just("-1e999"), Just("NaN"),
        ], 0..40)) {
            let text = words.join(" ");
            for version in [VersionOption::V3, VersionOption::V4] {
                let _ = parse_str(&text, Path::new("/nonexistent"), &opts(version), &mut CollectSink::default());
            }
        }
    }
}

/// Fuzz finding (parse target): `Shape "sphere" "float radius" nan` panicked in
/// `f32::clamp` (NaN bounds). Non-finite quadric parameters now skip the shape with a warning.
#[test]
fn regression_sphere_nan_radius_clamp_panic() {
    for shape in [
        r#"Shape "sphere" "float radius" nan"#,
        r#"Shape "sphere" "float radius" 1 "float zmin" inf"#,
        r#"Shape "disk" "float innerradius" -inf"#,
        r#"Shape "cylinder" "float phimax" nan"#,
    ] {
        let (sink, stats) = run(&format!("WorldBegin\n{shape}\n"));
        assert_eq!(stats.skipped_shapes, 1, "{shape}");
        assert!(sink.shapes.is_empty(), "{shape}");
        assert!(
            sink.warnings
                .iter()
                .any(|w| w.message.contains("not a finite number")),
            "{shape}: {:?}",
            sink.warnings
        );
    }
    // A zero radius is finite: a degenerate but valid mesh, no NaN normals.
    let (sink, _) = run("WorldBegin\nShape \"sphere\" \"float radius\" 0\n");
    let Geometry::Mesh(m) = &sink.shapes[0].geometry else {
        panic!("sphere is a mesh")
    };
    assert!(m.positions.iter().flatten().all(|v| v.is_finite()));
    assert!(m.normals.iter().flatten().flatten().all(|v| v.is_finite()));
}

// ---- shared prototypes for repeated includes ---------------------------------------------

/// World-space triangles of a parse: shapes outside objects directly, shapes of objects
/// once per instance (one level, as the shared-include objects are).
fn world_triangles(sink: &CollectSink) -> Vec<[[f32; 3]; 3]> {
    let mut out = Vec::new();
    let tris = |s: &ShapeEvent, world_from_parent: Option<&Mat4>, out: &mut Vec<_>| {
        let Geometry::Mesh(m) = &s.geometry else {
            return;
        };
        for t in m.indices.chunks_exact(3) {
            out.push(std::array::from_fn(|k| {
                let p = s
                    .parent_from_shape
                    .transform_point(m.positions[t[k] as usize]);
                world_from_parent.map_or(p, |w| w.transform_point(p))
            }));
        }
    };
    for s in &sink.shapes {
        match s.object {
            None => tris(s, None, &mut out),
            Some(o) => {
                for (id, _, world_from_instance, inside) in &sink.instances {
                    assert!(inside.is_none(), "test scenes have one instancing level");
                    if *id == o {
                        tris(s, Some(world_from_instance), &mut out);
                    }
                }
            }
        }
    }
    out.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
    out
}

fn parse_dir(dir: &Path, share: bool) -> (CollectSink, ParseStats) {
    let mut sink = CollectSink::default();
    let options = ParseOptions {
        share_repeated_includes: share,
        ..opts(VersionOption::Auto)
    };
    let stats = parse_file(&dir.join("main.pbrt"), &options, &mut sink).unwrap();
    (sink, stats)
}

fn write(dir: &Path, name: &str, text: &str) {
    std::fs::write(dir.join(name), text).unwrap();
}

const COPY: &str = r#"AttributeBegin
  Translate 0 0 2
  Rotate 30 0 1 0
  Shape "trianglemesh" "point P" [0 0 0 1 0 0 0 1 0] "integer indices" [0 1 2]
AttributeEnd
Shape "trianglemesh" "point P" [0 0 0 0 0 1 1 0 0] "integer indices" [0 1 2]
"#;

#[test]
fn repeated_include_becomes_one_prototype_and_an_edge_per_inclusion() {
    let dir = tempfile::tempdir().unwrap();
    write(dir.path(), "copy.pbrt", COPY);
    write(
        dir.path(),
        "main.pbrt",
        r#"WorldBegin
AttributeBegin
  Translate 10 0 0
  Include "copy.pbrt"
AttributeEnd
AttributeBegin
  Rotate 90 0 0 1
  Scale 2 2 2
  Include "copy.pbrt"
AttributeEnd
Include "copy.pbrt"
"#,
    );
    let (copied, copy_stats) = parse_dir(dir.path(), false);
    assert_eq!((copy_stats.shared_includes, copied.shapes.len()), (0, 6));
    let (shared, stats) = parse_dir(dir.path(), true);
    assert_eq!(stats.shared_includes, 1);
    assert_eq!(stats.include_instances, 3);
    assert_eq!(shared.objects.len(), 1, "one prototype");
    assert_eq!(shared.objects[0].1, "copy");
    assert_eq!(shared.shapes.len(), 2, "the file's shapes once");
    assert!(shared
        .shapes
        .iter()
        .all(|s| s.object == Some(shared.objects[0].0)));
    assert_eq!(shared.instances.len(), 3, "an edge per inclusion");
    assert_eq!(origin_of(&shared.instances[0].2), [10.0, 0.0, 0.0]);
    // The file is read once.
    assert_eq!(stats.files.len(), 2);
    let (a, b) = (world_triangles(&copied), world_triangles(&shared));
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        for k in 0..3 {
            assert!(close3(x[k], y[k]), "{x:?} vs {y:?}");
        }
    }
}

#[test]
fn include_sharing_is_conservative() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // An absolute transform, a leaking material and a definition each disqualify a file.
    write(
        d,
        "absolute.pbrt",
        &format!(
            "AttributeBegin\nTransform [1 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1]\n{TRI}\nAttributeEnd\n"
        ),
    );
    write(d, "leak.pbrt", &format!("Material \"matte\"\n{TRI}\n"));
    write(
        d,
        "defines.pbrt",
        &format!("MakeNamedMaterial \"m\" \"string type\" \"matte\"\n{TRI}\n"),
    );
    write(d, "ok.pbrt", &format!("{TRI}\n"));
    write(d, "once.pbrt", &format!("{TRI}\n"));
    write(
        d,
        "main.pbrt",
        r#"WorldBegin
Include "absolute.pbrt"
Include "absolute.pbrt"
Include "leak.pbrt"
Include "leak.pbrt"
Include "defines.pbrt"
Include "once.pbrt"
Include "ok.pbrt"
AttributeBegin
  Material "plastic"
  Include "ok.pbrt"
AttributeEnd
Include "ok.pbrt"
"#,
    );
    let (sink, stats) = parse_dir(d, true);
    // Only ok.pbrt is shared; its repeat under another material is parsed as a copy.
    assert_eq!(stats.shared_includes, 1);
    assert_eq!(stats.include_instances, 2);
    assert_eq!(sink.objects.len(), 1);
    assert_eq!(sink.objects[0].1, "ok");
    let world_shapes = sink.shapes.iter().filter(|s| s.object.is_none()).count();
    assert_eq!(world_shapes, 2 + 2 + 1 + 1 + 1);
    let (copied, _) = parse_dir(d, false);
    assert_eq!(world_triangles(&copied).len(), world_triangles(&sink).len());
}

#[test]
fn materials_resolve_colour_roughness_metalness_textures_and_mix() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("wood.png"), b"not decoded by the parser").unwrap();
    let src = r#"WorldBegin
Texture "wood" "spectrum" "imagemap" "string filename" "wood.png"
Texture "dim" "spectrum" "scale" "texture tex1" "wood" "rgb tex2" [0.5 0.5 0.5]
Texture "gone" "spectrum" "imagemap" "string filename" "missing.png"
Texture "half" "float" "constant" "float value" 0.25
MakeNamedMaterial "red" "string type" "matte" "rgb Kd" [0.8 0.1 0.1]
MakeNamedMaterial "gold" "string type" "metal" "spectrum eta" "metal-Au-eta" "spectrum k" "metal-Au-k" "float roughness" 0.3
MakeNamedMaterial "mostlygold" "string type" "mix" "string namedmaterial1" "red" "string namedmaterial2" "gold" "float amount" 0.8
MakeNamedMaterial "plank" "string type" "plastic" "texture Kd" "dim"
MakeNamedMaterial "lost" "string type" "matte" "texture Kd" "gone"
MakeNamedMaterial "glass" "string type" "glass"
NamedMaterial "plank"
Shape "trianglemesh" "integer indices" [0 1 2] "point P" [0 0 0 1 0 0 0 1 0] "texture alpha" "half"
"#;
    let main = dir.path().join("main.pbrt");
    std::fs::write(&main, src).unwrap();
    let mut sink = CollectSink::default();
    parse_file(&main, &opts(VersionOption::V3), &mut sink).unwrap();
    let by = |n: &str| {
        sink.materials
            .iter()
            .find(|m| m.name.as_deref() == Some(n))
            .unwrap_or_else(|| panic!("material {n}"))
            .clone()
    };
    let red = by("red");
    assert_eq!(red.base_color, Some([0.8, 0.1, 0.1]));
    assert_eq!((red.roughness, red.metallic), (Some(1.0), Some(0.0)));
    let gold = by("gold");
    assert_eq!((gold.roughness, gold.metallic), (Some(0.3), Some(1.0)));
    assert_eq!(gold.base_color, Some([1.0, 0.766, 0.336]));
    // mix: the dominant side (amount 0.8 → the second), whole.
    let mix = by("mostlygold");
    assert_eq!(mix.base_color, gold.base_color);
    assert_eq!((mix.roughness, mix.metallic), (Some(0.3), Some(1.0)));
    // A scaled image texture: the image, times the constant factor.
    let plank = by("plank");
    assert_eq!(
        plank.base_color_image.as_deref(),
        Some(dir.path().join("wood.png").as_path())
    );
    assert_eq!(plank.base_color, Some([0.5; 3]));
    assert_eq!(plank.roughness, Some(0.1));
    // A missing image: no image, the material's constant colour, and a warning.
    let lost = by("lost");
    assert!(lost.base_color_image.is_none());
    assert!(sink
        .warnings
        .iter()
        .any(|w| w.message.contains("missing.png") && w.message.contains("texture file missing")));
    let glass = by("glass");
    assert_eq!(glass.metallic, Some(0.0));
    assert!(glass.base_color.unwrap()[0] < 0.5);
    // A constant float texture as alpha is a constant coverage.
    assert_eq!(sink.shapes[0].alpha, Some(0.25));
    assert!(sink.shapes[0].alpha_image.is_none());
}

/// Issue 49: material and area-light values that were taken without a word.
#[test]
fn regression_nonfinite_material_and_area_light_values_have_locations() {
    let (line, col, token, msg) = err(
        "WorldBegin\nMaterial \"matte\" \"color Kd\" [nan 0 0]\n",
        VersionOption::Auto,
    );
    assert_eq!((line, col, token.as_str()), (2, 18, "Kd"), "{msg}");
    assert!(msg.contains("finite"), "{msg}");
    // 1e400 is past f32: infinite.
    let (line, _, token, msg) = err(
        "WorldBegin\nMakeNamedMaterial \"m\" \"string type\" \"diffuse\" \"rgb reflectance\" [-5 1e400 0]\n",
        VersionOption::Auto,
    );
    assert_eq!((line, token.as_str()), (2, "reflectance"), "{msg}");
    let (line, col, token, msg) = err(
        "WorldBegin\nAreaLightSource \"diffuse\" \"rgb L\" [nan 1 1]\n",
        VersionOption::Auto,
    );
    assert_eq!((line, col, token.as_str()), (2, 27, "L"), "{msg}");
    // Negative reflectance (pbrt-v3 takes it) and an unknown type are counted warnings.
    let (sink, stats) = run(&format!(
        "WorldBegin\nMaterial \"matte\" \"rgb Kd\" [-5 1 0]\nMaterial \"velvet\"\n{TRI}\n"
    ));
    assert_eq!(stats.warnings, 2, "{:?}", sink.warnings);
    assert!(sink
        .warnings
        .iter()
        .any(|w| w.message.contains("negative value -5") && w.loc.is_some()));
    assert!(sink
        .warnings
        .iter()
        .any(|w| w.message.contains("unknown material type \"velvet\"")));
}

#[test]
fn regression_zero_fov_is_an_error_at_the_parameter() {
    for fov in ["0", "180", "-3"] {
        let (line, col, token, msg) = err(
            &format!("Camera \"perspective\" \"float fov\" [ {fov} ]\nWorldBegin\n"),
            VersionOption::Auto,
        );
        assert_eq!((line, col, token.as_str()), (1, 22, "fov"), "{msg}");
        assert!(msg.contains("more than 0 and less than 180"), "{msg}");
    }
    run(&format!(
        "Camera \"perspective\" \"float fov\" [ 179 ]\nWorldBegin\n{TRI}\n"
    ));
}

#[test]
fn regression_utf16_scene_names_its_encoding() {
    let text = "WorldBegin\n";
    let mut utf16 = vec![0xFF, 0xFE];
    for u in text.encode_utf16() {
        utf16.extend_from_slice(&u.to_le_bytes());
    }
    let mut sink = CollectSink::default();
    let e = parse_bytes(
        &utf16,
        Path::new("/nonexistent"),
        &opts(VersionOption::Auto),
        &mut sink,
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains(":1:1") && e.contains("UTF-16"), "{e}");
    assert!(!e.contains("unknown directive"), "{e}");
}

#[test]
fn regression_negative_loopsubdiv_levels_are_warned() {
    let (sink, stats) = run(
        "WorldBegin\nShape \"loopsubdiv\" \"integer levels\" [-3] \"integer indices\" [0 1 2] \"point P\" [0 0 0 1 0 0 0 1 0]\n",
    );
    assert_eq!(stats.warnings, 1, "{:?}", sink.warnings);
    assert!(
        sink.warnings[0].message.contains("is -3"),
        "{:?}",
        sink.warnings
    );
    assert_eq!(sink.shapes.len(), 1);
}
