use super::*;
use crate::testutil::{check_scene, hash_dir};
use crate::{generate as gen, GenKind};

fn small(flat: bool) -> ForestOptions {
    ForestOptions {
        levels: 2,
        grid: GridSize::new(3, 2),
        leaves: 40,
        trunk_segments: 6,
        flat,
        ..ForestOptions::default()
    }
}

#[test]
fn nested_counts_match_the_files_and_the_thesis_formula() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = small(false);
    let s = gen(&GenKind::Forest(o.clone()), dir.path(), &mut |_| {}).expect("generate");
    let parsed = check_scene(&s.scene_path);
    assert_eq!(parsed.object_instances, s.object_instances);
    assert_eq!(parsed.flattened_instances, s.flattened_instances);
    assert_eq!(parsed.unique_triangles, s.unique_triangles);
    assert_eq!(parsed.instanced_triangles, s.instanced_triangles);
    assert_eq!(parsed.files, s.files_written);
    assert_eq!(parsed.bytes, s.bytes_written);
    assert!(parsed.nested);
    // (W·H)·levels + leaves instance edges; (W·H)^levels·(leaves+1) flattened.
    assert_eq!(s.object_instances, 6 * 2 + 40);
    assert_eq!(s.flattened_instances, 36 * 41);
}

#[test]
fn flat_writes_the_flattened_nested_forest() {
    let nested_dir = tempfile::tempdir().expect("tempdir");
    let flat_dir = tempfile::tempdir().expect("tempdir");
    let nested = gen(
        &GenKind::Forest(small(false)),
        nested_dir.path(),
        &mut |_| {},
    )
    .expect("nested");
    let flat = gen(&GenKind::Forest(small(true)), flat_dir.path(), &mut |_| {}).expect("flat");
    let parsed = check_scene(&flat.scene_path);
    assert!(!parsed.nested);
    assert_eq!(parsed.object_instances, flat.object_instances);
    assert_eq!(flat.object_instances, nested.flattened_instances);
    assert_eq!(flat.flattened_instances, nested.flattened_instances);
    assert_eq!(flat.instanced_triangles, nested.instanced_triangles);
    assert_eq!(parsed.instanced_triangles, nested.instanced_triangles);
}

#[test]
fn deterministic_and_seed_sensitive() {
    let a = tempfile::tempdir().expect("tempdir");
    let b = tempfile::tempdir().expect("tempdir");
    let c = tempfile::tempdir().expect("tempdir");
    let o = small(false);
    gen(&GenKind::Forest(o.clone()), a.path(), &mut |_| {}).expect("a");
    gen(&GenKind::Forest(o.clone()), b.path(), &mut |_| {}).expect("b");
    gen(
        &GenKind::Forest(ForestOptions { seed: 2, ..o }),
        c.path(),
        &mut |_| {},
    )
    .expect("c");
    assert_eq!(hash_dir(a.path()), hash_dir(b.path()));
    assert_ne!(hash_dir(a.path()), hash_dir(c.path()));
}

#[test]
fn rejects_bad_options() {
    let dir = tempfile::tempdir().expect("tempdir");
    for o in [
        ForestOptions {
            levels: 0,
            ..ForestOptions::default()
        },
        ForestOptions {
            levels: 40,
            ..ForestOptions::default()
        },
        ForestOptions {
            levels: 6,
            flat: true,
            ..ForestOptions::default()
        },
    ] {
        assert!(gen(&GenKind::Forest(o), dir.path(), &mut |_| {}).is_err());
    }
}
