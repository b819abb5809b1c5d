use super::*;

#[test]
fn regression_meta_writer_cannot_write_what_reader_refuses() {
    let mut meta = PackageMeta {
        schema: SCHEMA.into(),
        ..Default::default()
    };
    meta.cameras.push(motu_scene::Camera {
        name: "cam".into(),
        world_eye: [0.0; 3],
        world_forward: [0.0, 0.0, 1.0],
        world_up: [0.0, 1.0, 0.0],
        fov_deg: 45.0,
        width: 8,
        height: 8,
        mirror_x: false,
    });
    let good = serialise_meta(&meta).unwrap();
    assert_eq!(parse_meta(&good).unwrap(), meta);
    meta.cameras[0].fov_deg = f32::NAN;
    let e = serialise_meta(&meta).unwrap_err();
    assert!(e.to_string().contains("not finite"), "{e}");
    assert!(
        std::error::Error::source(&e).is_some(),
        "the parse error is kept: {e:?}"
    );
    meta.cameras[0].fov_deg = f32::INFINITY;
    assert!(serialise_meta(&meta).is_err());
}
