//! The island generator's tests.

use super::*;
use crate::testutil::{check_scene, hash_dir};
use crate::{generate as gen, GenKind};

fn tiny(scale: f64) -> IslandOptions {
    IslandOptions {
        scale,
        max_instances_per_file: 1_500,
        max_mesh_triangles: 4_000,
        ..IslandOptions::default()
    }
}

#[test]
fn default_island_is_standard_v3_and_counts_match_the_files() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = gen(&GenKind::Island(tiny(0.0002)), dir.path(), &mut |_| {}).expect("generate");
    let p = check_scene(&s.scene_path);
    assert!(!p.nested, "island must be single-level pbrt-v3");
    assert!(!p.v4_only_syntax && p.v3_only_syntax && p.world_end);
    assert_eq!(p.object_instances, s.object_instances);
    assert_eq!(p.flattened_instances, s.flattened_instances);
    assert_eq!(p.unique_triangles, s.unique_triangles);
    assert_eq!(p.instanced_triangles, s.instanced_triangles);
    assert_eq!(p.files, s.files_written);
    assert_eq!(p.bytes, s.bytes_written);
    assert_eq!(p.cameras, 7);
    assert_eq!(p.elements, s.elements);
    assert_eq!(
        s.elements,
        ["isBeach", "isCoral", "isMountainA", "isPalmRig", "osOcean"]
    );
    let expected = INSTANCES_AT_SCALE_1 * 0.0002;
    let ratio = s.object_instances as f64 / expected;
    assert!(
        (0.8..1.2).contains(&ratio),
        "{} instances for {expected}",
        s.object_instances
    );
    // Small limits force split placement files and split meshes.
    assert!(
        std::fs::read_dir(dir.path().join("isBeach"))
            .map(|d| d.count())
            .unwrap_or(0)
            > 4
    );
}

#[test]
fn every_element_and_camera_is_written_at_full_element_count() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = IslandOptions {
        elements: Some(20),
        ..tiny(0.0001)
    };
    let s = gen(&GenKind::Island(o), dir.path(), &mut |_| {}).expect("generate");
    let p = check_scene(&s.scene_path);
    assert_eq!(s.elements.len(), 20);
    assert_eq!(p.elements.len(), 20);
    assert_eq!(p.object_instances, s.object_instances);
    for cam in ISLAND_CAMERAS {
        assert!(dir.path().join(format!("cameras/{cam}.pbrt")).is_file());
    }
    let scene = std::fs::read_to_string(&s.scene_path).unwrap_or_default();
    let shot = scene.find("shotCam").unwrap_or(0);
    assert!(
        ISLAND_CAMERAS
            .iter()
            .all(|c| scene.find(c).unwrap_or(usize::MAX) <= shot),
        "shotCam included last"
    );
}

#[test]
fn deterministic_across_thread_counts_and_scales_linearly() {
    let a = tempfile::tempdir().expect("tempdir");
    let b = tempfile::tempdir().expect("tempdir");
    let c = tempfile::tempdir().expect("tempdir");
    let sa = gen(
        &GenKind::Island(IslandOptions {
            threads: Some(1),
            ..tiny(0.0001)
        }),
        a.path(),
        &mut |_| {},
    )
    .expect("a");
    let mut reports = 0;
    let sb = gen(
        &GenKind::Island(IslandOptions {
            threads: Some(3),
            ..tiny(0.0001)
        }),
        b.path(),
        &mut |_| reports += 1,
    )
    .expect("b");
    assert!(reports >= 1);
    assert_eq!(hash_dir(a.path()), hash_dir(b.path()));
    assert_eq!(
        GenSummary {
            scene_path: sb.scene_path.clone(),
            ..sa.clone()
        },
        sb
    );
    let sc = gen(&GenKind::Island(tiny(0.0004)), c.path(), &mut |_| {}).expect("c");
    let ratio = sc.object_instances as f64 / sa.object_instances as f64;
    assert!((3.2..4.8).contains(&ratio), "instances scale: {ratio}");
    let ratio = sc.bytes_written as f64 / sa.bytes_written as f64;
    assert!((2.5..5.0).contains(&ratio), "bytes scale: {ratio}");
}

#[test]
fn plants_stand_on_land_and_patches_respect_the_mesh_limit() {
    let terrain = Terrain::new(1);
    let o = IslandOptions::default();
    for c in 0..50 {
        let m = plant_transform(&o, &terrain, 2, c);
        let [x, y, z] = m.translation;
        assert!((y - (terrain.height(x, z) - 0.2)).abs() < 1e-9);
    }
    let rect = Rect {
        x0: 0.0,
        z0: 0.0,
        x1: 10.0,
        z1: 10.0,
    };
    let (inline, ply) = split_region(&[rect], Surface::Land, 50_000.0, 30_000.0, 4_000);
    assert!(inline.iter().chain(&ply).all(|p| p.triangles() <= 4_200));
    let total: u64 = inline.iter().chain(&ply).map(Patch::triangles).sum();
    assert!((60_000..100_000).contains(&total), "{total}");
    assert!(!ply.is_empty() && !inline.is_empty());
}

#[test]
fn terrain_objects_instance_each_patch_once_and_counts_still_match() {
    let dir = tempfile::tempdir().expect("tempdir");
    let plain = tempfile::tempdir().expect("tempdir");
    let o = tiny(0.0002);
    let a = gen(&GenKind::Island(o.clone()), plain.path(), &mut |_| {}).expect("plain");
    let s = gen(
        &GenKind::Island(IslandOptions {
            terrain_objects: true,
            ..o.clone()
        }),
        dir.path(),
        &mut |_| {},
    )
    .expect("objects");
    let p = check_scene(&s.scene_path);
    assert!(!p.nested, "still single-level pbrt-v3");
    assert_eq!(p.object_instances, s.object_instances);
    assert_eq!(p.flattened_instances, s.flattened_instances);
    assert_eq!(p.unique_triangles, s.unique_triangles);
    assert_eq!(p.instanced_triangles, s.instanced_triangles);
    // One instance per terrain geometry file, the same triangles.
    let files: usize = plan(&o)
        .iter()
        .map(|e| e.inline_files.len() + e.ply_patches.len())
        .sum();
    assert!(files > 8, "{files}");
    assert_eq!(s.object_instances, a.object_instances + files as u64);
    assert_eq!(s.unique_triangles, a.unique_triangles);
    assert_eq!(s.instanced_triangles, a.instanced_triangles);
    let beach =
        std::fs::read_to_string(dir.path().join("isBeach/isBeach.pbrt")).unwrap_or_default();
    assert!(
        beach.contains("ObjectBegin \"isBeach_terrain_00000\""),
        "{beach}"
    );
}

#[test]
fn close_up_cameras_look_down_at_the_ground_nearby() {
    let terrain = Terrain::new(1);
    for (name, c) in cameras(&terrain) {
        if !["grassCam", "rootsCam", "palmsCam"].contains(&name) {
            continue;
        }
        let d = [
            c.target[0] - c.eye[0],
            c.target[1] - c.eye[1],
            c.target[2] - c.eye[2],
        ];
        let horizontal = (d[0] * d[0] + d[2] * d[2]).sqrt();
        // Pitched down by more than half the field of view: no ray reaches the horizon.
        let pitch_down = (-d[1]).atan2(horizontal).to_degrees();
        assert!(pitch_down > 0.5 * c.fov_deg + 10.0, "{name}: {pitch_down}");
        let above = c.eye[1] - terrain.height(c.eye[0], c.eye[2]).max(0.0);
        assert!((1.0..=150.0).contains(&above), "{name}: {above}");
    }
}

#[test]
fn rejects_bad_options() {
    let dir = tempfile::tempdir().expect("tempdir");
    for o in [
        IslandOptions {
            scale: 0.0,
            ..IslandOptions::default()
        },
        IslandOptions {
            scale: f64::NAN,
            ..IslandOptions::default()
        },
        IslandOptions {
            elements: Some(21),
            ..IslandOptions::default()
        },
        IslandOptions {
            max_instances_per_file: 0,
            ..IslandOptions::default()
        },
    ] {
        assert!(matches!(
            gen(&GenKind::Island(o), dir.path(), &mut |_| {}),
            Err(GenError::InvalidOption { .. })
        ));
    }
}
