//! The VRAM-budget report end to end (issue 9).

use motu_tests::{
    artifacts_dir, chromium, chromium_available, motu_json, motu_ok, s, shared_scene,
};

#[test]
fn buddha_fractal_html_report_renders_in_chromium() {
    let Some(scene) = shared_scene("buddha-fractal/buddha-fractal.pbrt") else {
        return;
    };
    if !chromium_available("buddha_fractal_html_report_renders_in_chromium") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("buddha.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    let page = dir.path().join("report.html");
    motu_ok(&["report", s(&pkg), "--budget", "8MiB", "--html", s(&page)]);
    let html = std::fs::read_to_string(&page).unwrap();
    assert!(
        !html.contains("http://") && !html.contains("https://"),
        "the page must load no network assets"
    );
    let (dom, log) = chromium(&page, "--dump-dom");
    let errors: Vec<&str> = log
        .lines()
        .filter(|l| {
            l.contains(":CONSOLE")
                && ["Uncaught", "Error", "Failed"]
                    .iter()
                    .any(|w| l.contains(w))
        })
        .collect();
    assert!(errors.is_empty(), "console errors: {errors:#?}");
    for id in ["chart-elements", "chart-variants", "chart-budget"] {
        assert!(dom.contains(&format!(r#"id="{id}""#)), "chart {id} missing");
    }
    assert!(dom.contains("geometry"), "the element is in the page");
    let shot = artifacts_dir().join("buddha-fractal-report.png");
    chromium(&page, &format!("--screenshot={}", shot.display()));
    assert!(
        std::fs::metadata(&shot).unwrap().len() > 10_000,
        "screenshot at {}",
        shot.display()
    );
}

#[test]
fn report_json_compares_single_and_multi_level_and_suggests_a_subset() {
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("forest");
    motu_ok(&[
        "gen",
        "forest",
        "-o",
        s(&gen),
        "--levels",
        "2",
        "--grid",
        "3x2",
        "--leaves",
        "200",
    ]);
    let pkg = dir.path().join("f.motu");
    motu_ok(&["import", s(&gen.join("scene.pbrt")), "-o", s(&pkg)]);
    let r = motu_json(&["report", s(&pkg), "--json", "--budget", "1GiB"]);
    let text = r.to_string();
    assert!(
        text.contains("as_compiled") && text.contains("\"sl\""),
        "{text}"
    );
    let isl = dir.path().join("island");
    motu_ok(&["gen", "island", "-o", s(&isl)]);
    let ipkg = dir.path().join("i.motu");
    motu_ok(&["import", s(&isl.join("scene.pbrt")), "-o", s(&ipkg)]);
    let out = motu_ok(&["report", s(&ipkg), "--budget", "24MiB"]);
    assert!(out.contains("--subset "), "a ready --subset list: {out}");
}

#[test]
fn measure_builds_and_compacts_on_the_device() {
    if !motu_tests::gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("flake");
    motu_ok(&["gen", "sphereflake", "-o", s(&gen), "--depth", "2"]);
    let pkg = dir.path().join("f.motu");
    motu_ok(&["import", s(&gen.join("scene.pbrt")), "-o", s(&pkg)]);
    let r = motu_json(&["report", s(&pkg), "--json", "--measure"]);
    assert!(r.to_string().contains("measured on this device"), "{r}");
}

/// A split root (issue 15): the pieces' instances keep their elements' tags, so the per-element
/// rows of a split package count what the unsplit package's rows count; only the split's own
/// skeleton (piece TLASes and the PI BLAS into them) is "(untagged)", with no triangles.
#[test]
fn split_root_keeps_per_element_rows() {
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("island");
    motu_ok(&["gen", "island", "-o", s(&gen)]);
    let scene = gen.join("scene.pbrt");
    let whole = dir.path().join("whole.motu");
    let split = dir.path().join("split.motu");
    motu_ok(&["import", s(&scene), "-o", s(&whole)]);
    motu_ok(&[
        "import",
        s(&scene),
        "-o",
        s(&split),
        "--max-instances",
        "300",
    ]);
    let info = motu_json(&["info", s(&split), "--json"]);
    assert!(info["split_tlases"].as_u64().unwrap() > 0, "{info}");
    let rows = |pkg: &std::path::Path| {
        let r = motu_json(&["report", s(pkg), "--json"]);
        r["elements"].as_array().unwrap().clone()
    };
    let (w, sp) = (rows(&whole), rows(&split));
    let elements: Vec<&serde_json::Value> = w.iter().filter(|e| e["kind"] == "element").collect();
    assert!(elements.len() > 3, "{w:?}");
    for e in elements {
        let other = sp
            .iter()
            .find(|x| x["name"] == e["name"])
            .unwrap_or_else(|| panic!("{} missing from the split report", e["name"]));
        for key in [
            "root_instances",
            "flattened_instances",
            "instanced_triangles",
            "unique_triangles",
        ] {
            assert_eq!(other[key], e[key], "{} {key}", e["name"]);
        }
    }
    if let Some(u) = sp.iter().find(|x| x["kind"] == "untagged") {
        assert_eq!(u["instanced_triangles"], 0, "{u}");
        assert_eq!(u["root_instances"], 0, "{u}");
    }
}
