//! The adapter on the real scenes in `shared/scenes` (skipped loudly when that folder is absent).

use motu_ingest::{ingest_file, IngestOptions};
use motu_scene::{InMemoryGeometry, Scene};
use std::path::PathBuf;

fn scene(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/scenes")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        eprintln!(
            "SKIPPED: {} not found (shared/scenes is not beside the checkout)",
            p.display()
        );
        None
    }
}

fn load(rel: &str, allow_missing: bool) -> Option<Scene> {
    let path = scene(rel)?;
    let opts = IngestOptions {
        allow_missing,
        ..Default::default()
    };
    Some(
        ingest_file(&path, &opts, Box::new(InMemoryGeometry::new()))
            .expect("import")
            .0,
    )
}

#[test]
fn buddha_fractal_counts_elements_and_camera() {
    let Some(s) = load("buddha-fractal/buddha-fractal.pbrt", false) else {
        return;
    };
    let st = s.stats();
    assert_eq!(st.instances, 25_250);
    assert_eq!(st.flattened_instances, 25_250);
    assert_eq!(st.unique_triangles, 29_890 + 2);
    assert_eq!(st.instanced_triangles, 25_250 * 29_890 + 2);
    let names: Vec<&str> = s.elements().iter().map(|e| e.name.as_str()).collect();
    assert_eq!(names, ["main", "geometry"]);
    let geometry = s.element_by_name("geometry").unwrap();
    assert!(s.root_edge_elements().iter().all(|&e| e == geometry));
    let cam = &s.cameras()[0];
    assert_eq!(cam.name, "buddha-fractal");
    assert_eq!((cam.width, cam.height), (750, 1200));
    // `Scale -1 1 1` before LookAt mirrors pbrt's image.
    assert!(cam.mirror_x);
    assert!((cam.fov_deg - 30.2642).abs() < 1e-4);
    let floor = s.materials().iter().find(|m| m.name == "Floor").unwrap();
    assert!((floor.base_color[0] - 0.701_961).abs() < 1e-6);
}

#[test]
fn ecosys_needs_allow_missing() {
    let Some(path) = scene("ecosys/ecosys.pbrt") else {
        return;
    };
    let err = ingest_file(
        &path,
        &IngestOptions::default(),
        Box::new(InMemoryGeometry::new()),
    )
    .expect_err("missing PLYs must fail");
    let msg = err.to_string();
    assert!(msg.contains(".ply"), "{msg}");
    let s = load("ecosys/ecosys.pbrt", true).unwrap();
    assert_eq!(s.stats().instances, 4_817);
}

#[test]
fn kroken_v4_structure() {
    let Some(s) = load("kroken-v4/camera-1.pbrt", true) else {
        return;
    };
    assert_eq!(s.cameras()[0].name, "camera-1");
    let names: Vec<&str> = s.elements().iter().map(|e| e.name.as_str()).collect();
    assert!(names.contains(&"geometry"), "{names:?}");
    assert!(s.stats().instances > 0);
}
