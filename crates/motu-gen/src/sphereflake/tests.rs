use super::*;
use crate::testutil::{check_scene, hash_dir};
use crate::{generate as gen, GenKind};

#[test]
fn nested_and_flat_agree_with_the_files() {
    for depth in [0, 1, 3] {
        let nested_dir = tempfile::tempdir().expect("tempdir");
        let flat_dir = tempfile::tempdir().expect("tempdir");
        let o = SphereflakeOptions {
            depth,
            sphere_segments: 8,
            ..SphereflakeOptions::default()
        };
        let nested = gen(
            &GenKind::Sphereflake(o.clone()),
            nested_dir.path(),
            &mut |_| {},
        )
        .expect("nested");
        let flat = gen(
            &GenKind::Sphereflake(SphereflakeOptions { flat: true, ..o }),
            flat_dir.path(),
            &mut |_| {},
        )
        .expect("flat");
        let spheres: u64 = (0..=depth).map(|k| 9u64.pow(k)).sum();
        for (s, dir) in [(&nested, &nested_dir), (&flat, &flat_dir)] {
            let p = check_scene(&dir.path().join("scene.pbrt"));
            assert_eq!(p.object_instances, s.object_instances);
            assert_eq!(p.flattened_instances, spheres);
            assert_eq!(p.instanced_triangles, s.instanced_triangles);
            assert_eq!(p.unique_triangles, s.unique_triangles);
            assert_eq!(p.bytes, s.bytes_written);
            assert!(!p.v3_only_syntax);
        }
        assert_eq!(nested.object_instances, 10 * u64::from(depth) + 1);
        assert_eq!(flat.object_instances, spheres);
    }
}

#[test]
fn children_touch_the_parent_without_overlapping_it() {
    for c in child_transforms(5) {
        let center = c.transform_point([0.0; 3]);
        let dist = crate::math::dot(center, center).sqrt();
        assert!((dist - 4.0 / 3.0).abs() < 1e-9);
        let r = crate::math::dot(c.cols[0], c.cols[0]).sqrt();
        assert!((r - 1.0 / 3.0).abs() < 1e-9);
        assert!(center[1] >= -1e-9, "children sit on the upper half");
    }
}

#[test]
fn deterministic() {
    let a = tempfile::tempdir().expect("tempdir");
    let b = tempfile::tempdir().expect("tempdir");
    let o = GenKind::Sphereflake(SphereflakeOptions {
        depth: 2,
        flat: true,
        ..SphereflakeOptions::default()
    });
    gen(&o, a.path(), &mut |_| {}).expect("a");
    gen(&o, b.path(), &mut |_| {}).expect("b");
    assert_eq!(hash_dir(a.path()), hash_dir(b.path()));
}
