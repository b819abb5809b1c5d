//! Moana's JSON+OBJ base package (`motu import …/json/island.json`): the generated island
//! written both ways imports to the same package (counts and per-pixel hit records), and broken
//! inputs fail with the file and byte offset, leaving nothing behind.

use motu_tests::*;
use std::path::Path;

/// Both imports run with `--threads 1`: a parallel pbrt import loads PLY files in batches
/// after the rest, which numbers meshes differently (mesh ids are import order).
fn import_one_thread(scene: &Path, pkg: &Path) {
    import(scene, pkg, &["--threads", "1"]);
}

#[test]
fn island_written_as_json_imports_to_the_pbrt_islands_package() {
    let dir = tempfile::tempdir().unwrap();
    let (pbrt, json) = (dir.path().join("pbrt"), dir.path().join("json"));
    let scale = [
        "--scale",
        "0.0002",
        "--elements",
        "3",
        "--width",
        "64",
        "--height",
        "48",
    ];
    let mut args = vec!["gen", "island", "-o", s(&pbrt)];
    args.extend(scale);
    motu_ok(&args);
    let mut args = vec!["gen", "island", "-o", s(&json), "--format", "json"];
    args.extend(scale);
    args.push("--json");
    let summary = motu_json(&args);
    let entry = json.join("json/island.json");
    assert_eq!(summary["scene"], serde_json::json!(s(&entry)));
    let (a, b) = (dir.path().join("a.motu"), dir.path().join("b.motu"));
    import_one_thread(&pbrt.join("scene.pbrt"), &a);
    import_one_thread(&entry, &b);
    let (ia, ib) = (
        motu_json(&["info", s(&a), "--json"]),
        motu_json(&["info", s(&b), "--json"]),
    );
    for key in [
        "instances",
        "flattened_instances",
        "unique_triangles",
        "instanced_triangles",
        "meshes",
        "elements",
        "cameras",
        "tlas_count",
        "blas_count",
    ] {
        assert_eq!(ia[key], ib[key], "{key}");
    }
    assert!(ia["flattened_instances"].as_u64().unwrap() > 1000, "{ia}");
    assert_eq!(
        ib["flattened_instances"], summary["flattened_instances"],
        "the generator's count"
    );
    // Hit records per pixel from a far and a close camera.
    for camera in ["shotCam", "grassCam"] {
        let (x, y) = (
            dir.path().join(format!("a-{camera}.aov")),
            dir.path().join(format!("b-{camera}.aov")),
        );
        let extra = ["--width", "64", "--height", "48", "--camera", camera];
        render(&a, "cpu", &x, &extra);
        render(&b, "cpu", &y, &extra);
        let out = motu_ok(&["compare", s(&x), s(&y), "--max-mismatch", "0"]);
        assert!(out.contains("mismatch 0.000000"), "{camera}: {out}");
    }
    // The element folder alone is an element; the json folder the whole island.
    let beach = dir.path().join("beach.motu");
    import(&json.join("json/isBeach"), &beach, &[]);
    let info = motu_json(&["info", s(&beach), "--json"]);
    assert_eq!(
        info["elements"],
        serde_json::json!(["main", "isBeach"]),
        "{info}"
    );
}

/// A small base package: one element with ground, an archive placed twice, a curve file.
fn small_island(dir: &Path) -> std::path::PathBuf {
    let w = |rel: &str, text: &str| {
        let p = dir.join(rel);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, text).unwrap();
    };
    w(
        "island/json/isA/isA.json",
        r#"{"name": "isA", "matFile": "json/isA/materials.json", "geomObjFile": "obj/isA/isA.obj",
            "transformMatrix": [1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,1],
            "instancedPrimitiveJsonFiles": {
              "xgRock": {"type": "archive", "jsonFile": "json/isA/isA_xgRock.json",
                         "archives": ["obj/isA/archives/rock.obj"]},
              "xgHair": {"type": "curve", "jsonFile": "json/isA/isA_xgHair.json",
                         "widthRoot": 0.2, "widthTip": 0.05}}}"#,
    );
    w(
        "island/json/isA/materials.json",
        r#"{"ground": {"baseColor": [0.5, 0.4, 0.3], "assignment": ["xgHair"],
                       "colorMap": "textures/isA/Color"}}"#,
    );
    w(
        "island/json/isA/isA_xgRock.json",
        r#"{"obj/isA/archives/rock.obj": {
              "rock_0": [1,0,0,0, 0,1,0,0, 0,0,1,0, 2,0,0,1],
              "rock_1": [1,0,0,0, 0,1,0,0, 0,0,1,0, 5,0,0,1]}}"#,
    );
    w(
        "island/json/isA/isA_xgHair.json",
        "[[[0,0,0],[0,1,0],[0.1,2,0]], [[1,0,0],[1,1,0],[1,2,0.1]]]",
    );
    w(
        "island/obj/isA/isA.obj",
        "g ground\nusemtl ground\nv -9 0 -9\nv 9 0 -9\nv 9 0 9\nv -9 0 9\nf 1 2 3 4\n",
    );
    w(
        "island/obj/isA/archives/rock.obj",
        "g rock\nv 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n",
    );
    w(
        "island/json/cameras/shotCam.json",
        r#"{"eye": [0, 5, 20], "look": [0, 0, 0], "up": [0, 1, 0], "fov": 60, "ratio": 1.5}"#,
    );
    dir.join("island/json")
}

/// The files left in `dir` besides the inputs: an import that failed leaves none.
fn leftovers(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| {
            let n = e.ok()?.file_name().to_string_lossy().into_owned();
            (n != "island").then_some(n)
        })
        .collect()
}

#[test]
fn small_base_package_imports_archives_curves_and_camera() {
    let dir = tempfile::tempdir().unwrap();
    let entry = small_island(dir.path());
    let pkg = dir.path().join("a.motu");
    import(&entry, &pkg, &[]);
    let info = motu_json(&["info", s(&pkg), "--json"]);
    // Two rock placements; 2 ground + 2 × 4 rock triangles, plus the curves' ribbons.
    assert_eq!(info["flattened_instances"], 2, "{info}");
    assert_eq!(
        info["elements"],
        serde_json::json!(["main", "isA"]),
        "{info}"
    );
    assert_eq!(info["cameras"], serde_json::json!(["shotCam"]), "{info}");
    // The ground's Ptex file (`<colorMap>/<group>.ptx`) is kept; the rock has none.
    assert_eq!(info["ptex_materials"], 1, "{info}");
    assert_eq!(info["curves"], 2, "{info}");
    assert_eq!(info["curve_ribbons"], 2, "{info}");
    let aov = dir.path().join("a.aov");
    let stats = render(&pkg, "cpu", &aov, &["--width", "32", "--height", "32"]);
    assert_eq!(stats["width"], 32, "{stats}");
}

#[test]
fn broken_base_packages_fail_with_file_and_offset_and_write_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let entry = small_island(dir.path());
    let archive = entry.join("isA/isA_xgRock.json");
    let good = std::fs::read_to_string(&archive).unwrap();
    let pkg = dir.path().join("out.motu");
    let cases = [
        (good[..good.len() - 30].to_string(), "truncated"),
        (
            good.replacen("\"rock_1\":", "\"rock_1\"", 1),
            "expected `:`",
        ),
        (good.replacen("5,0,0,1", "NaN,0,0,1", 1), "non-finite"),
    ];
    for (text, needle) in cases {
        std::fs::write(&archive, &text).unwrap();
        let out = motu(&["import", s(&entry), "-o", s(&pkg)]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{needle}");
        assert!(err.contains("isA_xgRock.json: byte "), "{needle}: {err}");
        assert!(err.contains(needle), "{needle}: {err}");
        assert!(
            leftovers(dir.path()).is_empty(),
            "{needle}: {:?}",
            leftovers(dir.path())
        );
    }
    std::fs::write(&archive, &good).unwrap();
    // A missing archive OBJ: an error naming it and where it was named, or with
    // --allow-missing a warning and a package without its placements.
    let rock = dir.path().join("island/obj/isA/archives/rock.obj");
    std::fs::remove_file(&rock).unwrap();
    let out = motu(&["import", s(&entry), "-o", s(&pkg)]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        err.contains("rock.obj") && err.contains("isA.json:"),
        "{err}"
    );
    assert!(
        leftovers(dir.path()).is_empty(),
        "{:?}",
        leftovers(dir.path())
    );
    import(&entry, &pkg, &["--allow-missing"]);
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert_eq!(info["flattened_instances"], 0, "{info}");
    assert!(info["warnings"].as_u64().unwrap() > 0, "{info}");
    let text = motu_ok(&["info", s(&pkg)]);
    assert!(text.contains("rock.obj"), "{text}");
}
