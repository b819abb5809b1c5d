use super::*;

#[test]
fn defaults_are_small_valid_scenes() {
    for kind in [
        GenKind::Forest(ForestOptions::default()),
        GenKind::Sphereflake(SphereflakeOptions::default()),
        GenKind::LodGrid(LodGridOptions::default()),
        GenKind::Island(IslandOptions::default()),
    ] {
        let dir = tempfile::tempdir().expect("tempdir");
        let s = generate(&kind, dir.path(), &mut |_| {}).expect("generate");
        let p = testutil::check_scene(&s.scene_path);
        assert_eq!(p.object_instances, s.object_instances, "{}", kind.name());
        assert_eq!(
            p.flattened_instances,
            s.flattened_instances,
            "{}",
            kind.name()
        );
        assert_eq!(
            p.instanced_triangles,
            s.instanced_triangles,
            "{}",
            kind.name()
        );
        assert_eq!(p.nested, s.nested_instancing, "{}", kind.name());
        // Small enough for lavapipe: a few MB, well under a million leaf instances.
        assert!(
            s.bytes_written < 32 << 20,
            "{}: {} bytes",
            kind.name(),
            s.bytes_written
        );
        assert!(s.flattened_instances < 1_000_000, "{}", kind.name());
        assert!(s.unique_triangles < 1_000_000, "{}", kind.name());
    }
}

#[test]
fn grid_parses_and_rejects() {
    assert_eq!("4x3".parse::<GridSize>().ok(), Some(GridSize::new(4, 3)));
    assert_eq!(
        "16X64".parse::<GridSize>().ok(),
        Some(GridSize::new(16, 64))
    );
    for bad in ["4", "0x3", "ax3", "4x", "-1x2"] {
        assert!(bad.parse::<GridSize>().is_err(), "{bad}");
    }
    assert_eq!(GridSize::new(4, 3).to_string(), "4x3");
    assert_eq!(GridSize::new(4, 3).count(), 12);
}
