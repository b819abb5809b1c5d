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
