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
        chunk_bytes: 1 << 20,
        parallel: false,
        ..Default::default()
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
    assert_eq!(
        seen.iter()
            .filter(|p| **p == ImportProgress::Parsed)
            .count(),
        1
    );
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
    assert!(
        e.to_string()
            .contains("give the entry .pbrt (or .obj) file"),
        "{e}"
    );
    let e = import(dir.path(), &out, &options()).unwrap_err();
    assert!(
        e.to_string().contains("is a directory, not a scene file"),
        "{e}"
    );
    // The scene itself as the output: refused, and the scene is left whole.
    let scene = write_scene(dir.path());
    let e = import(&scene, &scene, &options()).unwrap_err();
    assert!(matches!(e, ImportError::OutputIsInput { .. }), "{e}");
    assert!(e.to_string().contains("never replaces an input"), "{e}");
    assert_eq!(std::fs::read_to_string(&scene).unwrap(), SCENE);
}

/// The defaults are the CLI's (`motu import` with no options).
#[test]
fn defaults_are_the_cli_defaults() {
    let o = ImportOptions::default();
    assert_eq!(
        (o.levels, o.levels_text.as_str()),
        (motu_compile::Levels::Ml, "ml")
    );
    assert_eq!(o.max_instances, (1 << 24) - 1);
    assert_eq!(o.max_blas_triangles, None, "chosen from the scene's size");
    assert_eq!((o.lod_levels, o.lod_min_triangles), (None, 10_000));
    assert_eq!(
        (o.chunk_bytes, o.zstd_level, o.texture_max),
        (64 << 20, None, 1024)
    );
    assert!(o.parallel && !o.allow_missing && o.curve_ribbons && o.subset.is_empty());
}

#[test]
fn subsets_name_known_elements() {
    let known = ["a".to_string(), "b".to_string()];
    assert_eq!(
        resolve_subset(&["b".into(), "a".into()], &known).unwrap(),
        [1, 0]
    );
    let e = resolve_subset(&["c".into()], &known).unwrap_err();
    assert_eq!(
        e.to_string(),
        "unknown element(s) c: valid elements are a, b"
    );
    let e = resolve_subset(&[" ".into()], &known).unwrap_err();
    assert!(matches!(e, ImportError::EmptySubsetName { .. }), "{e}");
}

#[test]
fn the_heap_is_trimmed_once_per_step_of_scene_text() {
    let trim = crate::memory::TrimEvery::new(100);
    // Before the first mark: no trim; at each mark passed, one trim, however far past it.
    let trims: Vec<bool> = [0, 99, 100, 150, 199, 450, 460, 500]
        .iter()
        .map(|&b| trim.at(b))
        .collect();
    assert_eq!(trims, [false, false, true, false, false, true, false, true]);
}

#[test]
fn malloc_arenas_are_capped_where_glibc_takes_the_cap_and_the_user_chose_none() {
    // 0 is no cap. With glibc (and no arena count of the user's), mallopt accepts the cap:
    // a wrong parameter number would make it refuse, and the import's peak would be glibc's.
    assert!(!crate::cap_malloc_arenas(0));
    let user_chose = std::env::var_os("MALLOC_ARENA_MAX").is_some()
        || std::env::var("GLIBC_TUNABLES").is_ok_and(|t| t.contains("arena_max"));
    let glibc = cfg!(all(target_os = "linux", target_env = "gnu"));
    assert_eq!(
        crate::cap_malloc_arenas(crate::IMPORT_MALLOC_ARENAS),
        glibc && !user_chose
    );
}
