use super::*;
use crate::testutil::{check_scene, hash_dir};
use crate::{generate as gen, GenKind};

#[test]
fn counts_match_files_and_distance_varies() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = LodGridOptions {
        grid: GridSize::new(4, 20),
        triangles: 2_000,
        ..LodGridOptions::default()
    };
    let s = gen(&GenKind::LodGrid(o.clone()), dir.path(), &mut |_| {}).expect("generate");
    let p = check_scene(&s.scene_path);
    assert_eq!(p.object_instances, 80);
    assert_eq!(p.flattened_instances, 80);
    assert_eq!(p.instanced_triangles, s.instanced_triangles);
    assert!(
        s.unique_triangles >= 1_800 && s.unique_triangles <= 2_400,
        "{}",
        s.unique_triangles
    );
    assert!(!p.nested);
    // Nearest row at 1 spacing, farthest at `height` spacings.
    let (_, ez) = extent(&o);
    assert!(ez / o.spacing >= 20.0);
}

#[test]
fn deterministic_and_default_is_dense() {
    let a = tempfile::tempdir().expect("tempdir");
    let b = tempfile::tempdir().expect("tempdir");
    let o = GenKind::LodGrid(LodGridOptions {
        grid: GridSize::new(2, 3),
        triangles: 500,
        ..LodGridOptions::default()
    });
    gen(&o, a.path(), &mut |_| {}).expect("a");
    gen(&o, b.path(), &mut |_| {}).expect("b");
    assert_eq!(hash_dir(a.path()), hash_dir(b.path()));
    assert!(dense_mesh(&LodGridOptions::default()).triangle_count() >= 100_000);
}
