//! The pipeline on small scenes written here (the whole CLI is tested in `tests/tests/import.rs`).

use super::*;
use std::path::Path;
use std::sync::{Arc, Mutex};

const SCENE: &str = r#"
Camera "perspective" "float fov" 45
WorldBegin
ObjectBegin "tri"
Shape "trianglemesh" "point3 P" [0 0 0 1 0 0 0 1 0] "integer indices" [0 1 2]
ObjectEnd
AttributeBegin
  Translate 0 0 5
  ObjectInstance "tri"
AttributeEnd
AttributeBegin
  Translate 1 0 5
  ObjectInstance "tri"
AttributeEnd
"#;

fn options() -> ImportOptions {
    ImportOptions {
        levels: motu_compile::Levels::Ml,
        levels_text: "ml".into(),
        max_instances: (1 << 24) - 1,
        max_tlas_scratch_bytes: None,
        max_blas_triangles: motu_compile::DEFAULT_MAX_BLAS_TRIANGLES,
        lod_levels: None,
        lod_min_triangles: 10_000,
        zstd_level: None,
        allow_missing: false,
        pbrt_version: None,
        subset: Vec::new(),
        chunk_bytes: 1 << 20,
        parallel: false,
        curve_ribbons: false,
        texture_max: 1024,
        progress: None,
    }
}

fn write_scene(dir: &Path) -> std::path::PathBuf {
    let scene = dir.join("scene.pbrt");
    std::fs::write(&scene, SCENE).unwrap();
    scene
}

#[test]
fn imports_a_scene_into_a_package_that_opens() {
    let dir = tempfile::tempdir().unwrap();
    let scene = write_scene(dir.path());
    let out = dir.path().join("scene.motu");
    let seen = Arc::new(Mutex::new(Vec::new()));
    let log = seen.clone();
    let o = ImportOptions {
        progress: Some(Arc::new(move |p| log.lock().unwrap().push(p))),
        ..options()
    };
    let s = import(&scene, &out, &o).unwrap();
    assert_eq!((s.meshes, s.instances, s.flattened_instances), (1, 2, 2));
    assert!(s.tlas_count >= 1 && s.blas_count >= 1, "{s:?}");
    assert_eq!(s.file_bytes, std::fs::metadata(&out).unwrap().len());
    let pkg = motu_pack::ScenePackage::open(&out).unwrap();
    assert_eq!(pkg.meta().mesh_names.len(), 1);
    // Parsing reports end with `Parsed`, once.
    let seen = seen.lock().unwrap();
    assert_eq!(seen.last(), Some(&ImportProgress::Parsed));
    assert_eq!(seen.iter().filter(|p| **p == ImportProgress::Parsed).count(), 1);
    // No scratch or spill file is left beside the package.
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().flatten().collect();
    assert_eq!(left.len(), 2, "{left:?}");
}

#[test]
fn bad_paths_are_errors_that_say_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.motu");
    let e = import(&dir.path().join("nope.pbrt"), &out, &options()).unwrap_err();
    assert!(matches!(e, ImportError::SceneMissing { .. }), "{e}");
    assert!(e.to_string().contains("give the entry .pbrt (or .obj) file"), "{e}");
    let e = import(dir.path(), &out, &options()).unwrap_err();
    assert!(e.to_string().contains("is a directory, not a scene file"), "{e}");
    // The scene itself as the output: refused, and the scene is left whole.
    let scene = write_scene(dir.path());
    let e = import(&scene, &scene, &options()).unwrap_err();
    assert!(matches!(e, ImportError::OutputIsInput { .. }), "{e}");
    assert!(e.to_string().contains("never replaces an input"), "{e}");
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), SCENE);
}

#[test]
fn subsets_name_known_elements() {
    let known = ["a".to_string(), "b".to_string()];
    assert_eq!(resolve_subset(&["b".into(), "a".into()], &known).unwrap(), [1, 0]);
    let e = resolve_subset(&["c".into()], &known).unwrap_err();
    assert_eq!(e.to_string(), "unknown element(s) c: valid elements are a, b");
    let e = resolve_subset(&[" ".into()], &known).unwrap_err();
    assert!(matches!(e, ImportError::EmptySubsetName { .. }), "{e}");
}
