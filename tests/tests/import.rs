//! Import, info, verify on real and generated scenes (issues 3, 4, 11).

use motu_tests::{gen_forest, motu, motu_json, motu_ok, s, shared_scene};

#[test]
fn buddha_fractal_counts() {
    let Some(scene) = shared_scene("buddha-fractal/buddha-fractal.pbrt") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("buddha.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert_eq!(info["instances"], 25_250);
    assert_eq!(info["flattened_instances"], 25_250);
    assert_eq!(info["unique_triangles"], 29_890 + 2);
    assert_eq!(info["instanced_triangles"], 25_250u64 * 29_890 + 2);
    assert_eq!(info["cameras"][0], "buddha-fractal");
    for key in [
        "format_version",
        "meshes",
        "nodes",
        "levels",
        "tlas_count",
        "blas_count",
        "max_instances_per_tlas",
        "chunks",
        "file_bytes",
        "elements",
    ] {
        assert!(!info[key].is_null(), "info --json lacks {key}");
    }
    let elements = motu_json(&["info", s(&pkg), "--elements", "--json"]);
    let geometry = elements["elements"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["name"] == "geometry")
        .unwrap();
    assert_eq!(geometry["instances"], 25_250);
    motu_ok(&["verify", s(&pkg)]);
}

#[test]
fn buddha_fractal_split_at_1000_instances() {
    let Some(scene) = shared_scene("buddha-fractal/buddha-fractal.pbrt") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("b1000.motu");
    motu_ok(&[
        "import",
        s(&scene),
        "-o",
        s(&pkg),
        "--max-instances",
        "1000",
    ]);
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert!(info["tlas_count"].as_u64().unwrap() >= 26, "{info}");
    assert!(
        info["max_instances_per_tlas"].as_u64().unwrap() <= 1000,
        "{info}"
    );
    assert_eq!(info["flattened_instances"], 25_250);
}

#[test]
fn missing_files_fail_unless_allowed() {
    for (scene, what) in [
        ("ecosys/ecosys.pbrt", ".ply"),
        ("kroken-v4/camera-1.pbrt", ".ply"),
    ] {
        let Some(scene) = shared_scene(scene) else {
            return;
        };
        let dir = tempfile::tempdir().unwrap();
        let pkg = dir.path().join("x.motu");
        let out = motu(&["import", s(&scene), "-o", s(&pkg)]);
        assert!(!out.status.success());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(what) && err.contains("missing"), "{err}");
        assert!(!pkg.exists(), "a failed import must leave no package");
        assert!(
            std::fs::read_dir(dir.path()).unwrap().next().is_none(),
            "a failed import must leave no temp file"
        );
        motu_ok(&["import", s(&scene), "-o", s(&pkg), "--allow-missing"]);
        motu_ok(&["verify", s(&pkg)]);
    }
}

#[test]
fn bmw_m6_imports() {
    let Some(scene) = shared_scene("bmw-m6/bmw-m6.pbrt") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("bmw.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg), "--zstd", "3"]);
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert!(
        info["unique_triangles"].as_u64().unwrap() > 100_000,
        "{info}"
    );
    assert!(
        info["chunk_stored_bytes"].as_u64() < info["chunk_raw_bytes"].as_u64(),
        "zstd: {info}"
    );
    motu_ok(&["verify", s(&pkg)]);
}

#[test]
fn corruption_and_truncation_are_detected() {
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("flake");
    let pkg = dir.path().join("flake.motu");
    motu_ok(&["gen", "sphereflake", "-o", s(&gen), "--depth", "2"]);
    motu_ok(&["import", s(&gen.join("scene.pbrt")), "-o", s(&pkg)]);
    motu_ok(&["verify", s(&pkg)]);
    let good = std::fs::read(&pkg).unwrap();
    let bad = dir.path().join("bad.motu");
    // Sample positions across header, chunk data, padding, sections, manifest and trailer.
    let n = good.len();
    let mut positions: Vec<usize> = (0..64).map(|i| i * n / 64).collect();
    positions.extend([0, 8, n - 1, n - 24, n - 48, 4096, 4097]);
    for &at in &positions {
        let mut b = good.clone();
        b[at] ^= 0x5a;
        std::fs::write(&bad, &b).unwrap();
        let out = motu(&["verify", s(&bad)]);
        assert!(
            !out.status.success(),
            "flipping byte {at} of {n} went unnoticed"
        );
    }
    for cut in [0, 10, 4096, n / 2, n - 1] {
        std::fs::write(&bad, &good[..cut]).unwrap();
        assert!(
            !motu(&["verify", s(&bad)]).status.success(),
            "truncation at {cut} went unnoticed"
        );
    }
}

#[test]
fn subset_import_and_unknown_names() {
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("island");
    motu_ok(&["gen", "island", "-o", s(&gen)]);
    let scene = gen.join("scene.pbrt");
    let full = dir.path().join("full.motu");
    let beach = dir.path().join("beach.motu");
    motu_ok(&["import", s(&scene), "-o", s(&full)]);
    let out = motu(&[
        "import",
        s(&scene),
        "-o",
        s(&beach),
        "--subset",
        "isBeach,isNowhere",
    ]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("isNowhere") && err.contains("isBeach") && err.contains("osOcean"),
        "{err}"
    );
    motu_ok(&["import", s(&scene), "-o", s(&beach), "--subset", "isBeach"]);
    let f = motu_json(&["info", s(&full), "--json"]);
    let b = motu_json(&["info", s(&beach), "--json"]);
    assert_eq!(b["elements"], serde_json::json!(["isBeach"]));
    assert!(b["file_bytes"].as_u64() < f["file_bytes"].as_u64());
    assert!(b["instances"].as_u64() < f["instances"].as_u64());
    let el = motu_json(&["info", s(&full), "--elements", "--json"]);
    let want = el["elements"]
        .as_array()
        .unwrap()
        .iter()
        .find(|e| e["name"] == "isBeach")
        .unwrap()
        .clone();
    assert_eq!(b["instances"], want["instances"]);
}

#[test]
fn levels_and_caps_keep_the_flattened_count() {
    let dir = tempfile::tempdir().unwrap();
    let scene = gen_forest(
        dir.path(),
        &["--levels", "2", "--grid", "2x2", "--leaves", "50"],
    );
    let mut flattened = Vec::new();
    for (name, extra) in [
        ("ml", vec![]),
        ("sl", vec!["--levels", "sl"]),
        ("l2", vec!["--levels", "2"]),
        ("cap", vec!["--max-instances", "7"]),
    ] {
        let pkg = dir.path().join(format!("{name}.motu"));
        let mut args = vec!["import", s(&scene), "-o", s(&pkg)];
        args.extend(extra);
        motu_ok(&args);
        let info = motu_json(&["info", s(&pkg), "--json"]);
        flattened.push(info["flattened_instances"].as_u64().unwrap());
        if name == "sl" {
            assert_eq!(info["levels"], 1, "{info}");
        }
        if name == "cap" {
            assert!(
                info["max_instances_per_tlas"].as_u64().unwrap() <= 7,
                "{info}"
            );
        }
    }
    assert!(flattened.windows(2).all(|w| w[0] == w[1]), "{flattened:?}");
}

#[test]
fn obj_with_mtl_imports_and_renders() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("m.mtl"),
        "newmtl red\nKd 0.8 0.1 0.1\nnewmtl blue\nKd 0.1 0.1 0.9\n",
    )
    .unwrap();
    let obj = dir.path().join("model.obj");
    std::fs::write(
        &obj,
        "mtllib m.mtl\n\
         o quad\nusemtl red\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n\
         o tri\nusemtl blue\nv 0 0 1\nv 1 0 1\nv 0 1 1\nf 5 6 7\n",
    )
    .unwrap();
    let pkg = dir.path().join("model.motu");
    motu_ok(&["import", s(&obj), "-o", s(&pkg)]);
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert_eq!(info["meshes"], 2);
    assert_eq!(
        info["unique_triangles"], 3,
        "the quad is split into two triangles: {info}"
    );
    assert_eq!(info["instances"], 0);
    motu_ok(&["verify", s(&pkg)]);
    // No camera in an OBJ: render frames the bounds.
    let aov = dir.path().join("m.aov");
    motu_ok(&[
        "render",
        s(&pkg),
        "-o",
        s(&dir.path().join("m.png")),
        "--backend",
        "cpu",
        "--width",
        "32",
        "--aov",
        s(&aov),
    ]);
    let bytes = std::fs::read(&aov).unwrap();
    let hits = bytes[32..]
        .chunks_exact(16)
        .filter(|r| u32::from_le_bytes([r[0], r[1], r[2], r[3]]) != u32::MAX)
        .count();
    assert!(hits > 0, "the model is in view");
}

#[test]
fn tlas_scratch_budget_splits_tlases() {
    let Some(scene) = shared_scene("buddha-fractal/buddha-fractal.pbrt") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("b.motu");
    // 128 B of estimated scratch per instance: 256 KiB allows 2,048 instances per TLAS.
    motu_ok(&[
        "import",
        s(&scene),
        "-o",
        s(&pkg),
        "--max-tlas-scratch",
        "256KiB",
    ]);
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert!(
        info["max_instances_per_tlas"].as_u64().unwrap() <= 2048,
        "{info}"
    );
    assert!(info["tlas_count"].as_u64().unwrap() >= 13, "{info}");
    assert_eq!(info["flattened_instances"], 25_250);
}

#[test]
fn curves_are_counted_or_tessellated_into_ribbons() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("grass.pbrt");
    let mut text = String::from(
        "LookAt 0 1 -5  0 1 0  0 1 0\nCamera \"perspective\" \"float fov\" [40]\nWorldBegin\n",
    );
    for i in 0..50 {
        let x = i as f32 * 0.1 - 2.5;
        text += &format!(
            "Shape \"curve\" \"point P\" [{x} 0 0 {x} 0.6 0.1 {x} 1.2 0.1 {x} 1.8 0] \"float width0\" 0.05 \"float width1\" 0.0\n"
        );
    }
    text += "Shape \"trianglemesh\" \"integer indices\" [0 1 2 0 2 3] \"point P\" [-5 0 -5 5 0 -5 5 0 5 -5 0 5]\n";
    std::fs::write(&scene, text).unwrap();
    let skip = dir.path().join("skip.motu");
    let ribbons = dir.path().join("ribbons.motu");
    let out = motu_ok(&["import", s(&scene), "-o", s(&skip), "--curves", "skip"]);
    assert!(out.contains("50 curve shapes were counted"), "{out}");
    let a = motu_json(&["info", s(&skip), "--json"]);
    assert_eq!(a["unique_triangles"], 2);
    assert_eq!(
        (&a["curves"], &a["curve_ribbons"]),
        (&50.into(), &0.into()),
        "{a}"
    );
    // Ribbons are the default.
    let out = motu_ok(&["import", s(&scene), "-o", s(&ribbons)]);
    assert!(
        out.contains("50 curve shapes tessellated as ribbons (400 triangles)"),
        "{out}"
    );
    let b = motu_json(&["info", s(&ribbons), "--json"]);
    // 50 ribbons of 4 quads, gathered into one mesh, plus the ground.
    assert_eq!(b["unique_triangles"], 2 + 50 * 8, "{b}");
    assert_eq!(b["meshes"], 2, "{b}");
    assert_eq!(
        (
            &b["curves"],
            &b["curve_ribbons"],
            &b["curve_ribbon_triangles"]
        ),
        (&50.into(), &50.into(), &400.into()),
        "{b}"
    );
    let aov = dir.path().join("g.aov");
    motu_ok(&[
        "render",
        s(&ribbons),
        "-o",
        s(&dir.path().join("g.png")),
        "--backend",
        "cpu",
        "--width",
        "64",
        "--aov",
        s(&aov),
    ]);
}
