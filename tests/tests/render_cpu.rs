//! The CPU oracle end to end (issue 5): differently compiled packages of one scene render the
//! same hits, pixel by pixel.

use motu_tests::{
    gen_forest, gen_lod_grid, import, motu, motu_json, motu_ok, render, s, shared_scene,
};
use std::path::Path;

fn render_aov(pkg: &Path, aov: &Path, extra: &[&str]) -> serde_json::Value {
    render(pkg, "cpu", aov, extra)
}

#[test]
fn forest_ml_sl_levels_and_splits_agree() {
    let dir = tempfile::tempdir().unwrap();
    let scene = gen_forest(
        dir.path(),
        &["--levels", "2", "--grid", "3x2", "--leaves", "120"],
    );
    let configs: [(&str, &[&str]); 4] = [
        ("ml", &[]),
        ("sl", &["--levels", "sl"]),
        ("l2", &["--levels", "2"]),
        ("cap", &["--max-instances", "9"]),
    ];
    let mut aovs = Vec::new();
    for (name, extra) in configs {
        let pkg = dir.path().join(format!("{name}.motu"));
        import(&scene, &pkg, extra);
        let aov = dir.path().join(format!("{name}.aov"));
        let stats = render_aov(&pkg, &aov, &["--width", "96", "--view", "ids"]);
        // The contract's keys from their one source (CLI.md's list, checked there).
        for key in motu_render::stats::CONTRACT_KEYS {
            assert!(!stats[key].is_null(), "--stats lacks {key}");
        }
        if name == "ml" {
            assert!(
                stats["traces_per_ray"].as_f64().unwrap() > 1.0,
                "ml should trace several levels: {stats}"
            );
        }
        aovs.push(aov);
    }
    for other in &aovs[1..] {
        let out = motu_ok(&["compare", s(&aovs[0]), s(other), "--max-mismatch", "0.001"]);
        assert!(out.contains("mismatch"), "{out}");
    }
    // The comparison can fail: a different scene does not match.
    let flake = dir.path().join("flake");
    motu_ok(&["gen", "sphereflake", "-o", s(&flake), "--depth", "1"]);
    let fpkg = dir.path().join("flake.motu");
    import(&flake.join("scene.pbrt"), &fpkg, &[]);
    let faov = dir.path().join("flake.aov");
    render_aov(&fpkg, &faov, &["--width", "96", "--height", "54"]);
    let out = motu(&["compare", s(&aovs[0]), s(&faov)]);
    assert!(
        !out.status.success(),
        "different scenes must not compare equal"
    );
}

#[test]
fn buddha_fractal_renders_with_its_camera() {
    let Some(scene) = shared_scene("buddha-fractal/buddha-fractal.pbrt") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let ml = dir.path().join("ml.motu");
    let sl = dir.path().join("sl.motu");
    import(&scene, &ml, &[]);
    import(&scene, &sl, &["--levels", "sl", "--max-instances", "1000"]);
    let a = dir.path().join("ml.aov");
    let b = dir.path().join("sl.aov");
    let stats = render_aov(&ml, &a, &["--width", "128", "--camera", "buddha-fractal"]);
    assert_eq!(
        stats["height"], 205,
        "height follows the camera's 750×1200 aspect"
    );
    render_aov(&sl, &b, &["--width", "128"]);
    motu_ok(&["compare", s(&a), s(&b)]);
    let out = motu(&[
        "render",
        s(&ml),
        "-o",
        s(&dir.path().join("x.png")),
        "--camera",
        "nope",
    ]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("buddha-fractal"));
}

#[test]
fn subset_render_equals_subset_import() {
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("island");
    motu_ok(&["gen", "island", "-o", s(&gen)]);
    let scene = gen.join("scene.pbrt");
    let full = dir.path().join("full.motu");
    let coral = dir.path().join("coral.motu");
    import(&scene, &full, &[]);
    import(&scene, &coral, &["--subset", "isCoral"]);
    let a = dir.path().join("a.aov");
    let b = dir.path().join("b.aov");
    let c = dir.path().join("c.aov");
    render_aov(
        &full,
        &a,
        &["--width", "128", "--subset", "isCoral", "--view", "ids"],
    );
    render_aov(&coral, &b, &["--width", "128", "--view", "ids"]);
    render_aov(&full, &c, &["--width", "128", "--view", "ids"]);
    motu_ok(&["compare", s(&a), s(&b)]);
    // A split root mixes elements in its pieces (issue 15): the run-time subset still filters
    // every placement, pieces included.
    let split = dir.path().join("split.motu");
    import(&scene, &split, &["--max-instances", "300"]);
    let info = motu_json(&["info", s(&split), "--json"]);
    assert!(info["tlas_count"].as_u64().unwrap() > 3, "{info}");
    let d = dir.path().join("d.aov");
    render_aov(
        &split,
        &d,
        &["--width", "128", "--subset", "isCoral", "--view", "ids"],
    );
    motu_ok(&["compare", s(&d), s(&b)]);
    assert!(
        !motu(&["compare", s(&a), s(&c)]).status.success(),
        "the subset must differ from the whole"
    );
    let bad = motu(&[
        "render",
        s(&full),
        "-o",
        s(&dir.path().join("x.png")),
        "--subset",
        "isAtlantis",
    ]);
    assert!(String::from_utf8_lossy(&bad.stderr).contains("osOcean"));
    let info = motu_json(&["info", s(&coral), "--json"]);
    assert_eq!(info["elements"], serde_json::json!(["isCoral"]));
}

#[test]
fn lod_grid_gets_coarser_with_distance() {
    let dir = tempfile::tempdir().unwrap();
    let (_, pkg) = gen_lod_grid(dir.path(), "grid", "6x24", "lod.motu", "4");
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert!(info["lod_selectors"].as_u64().unwrap() >= 1, "{info}");
    let aov = dir.path().join("lod.aov");
    render_aov(&pkg, &aov, &["--width", "192", "--view", "lod"]);
    let bytes = std::fs::read(&aov).unwrap();
    // (t, lod) of every hit, then: the nearest quarter of hits uses finer levels than the farthest.
    let mut hits: Vec<(f32, u8)> = bytes[32..]
        .chunks_exact(16)
        .filter(|r| u32::from_le_bytes([r[0], r[1], r[2], r[3]]) != u32::MAX)
        .map(|r| (f32::from_le_bytes([r[8], r[9], r[10], r[11]]), r[12]))
        .collect();
    assert!(hits.len() > 100);
    hits.sort_by(|a, b| a.0.total_cmp(&b.0));
    let q = hits.len() / 4;
    let mean = |s: &[(f32, u8)]| s.iter().map(|h| h.1 as f64).sum::<f64>() / s.len() as f64;
    let (near, far) = (mean(&hits[..q]), mean(&hits[hits.len() - q..]));
    assert!(
        far > near + 0.4,
        "LOD should coarsen with distance: near {near:.2}, far {far:.2}"
    );
    // Forcing level 0 everywhere gives only level-0 hits.
    let forced = dir.path().join("forced.aov");
    render_aov(&pkg, &forced, &["--width", "96", "--lod", "0"]);
    let b = std::fs::read(&forced).unwrap();
    assert!(b[32..].chunks_exact(16).all(|r| r[12] == 0));
}
