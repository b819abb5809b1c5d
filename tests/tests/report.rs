//! The VRAM-budget report end to end (issue 9).

use motu_tests::{
    artifacts_dir, chromium, chromium_available, gen_forest, motu_json, motu_ok, s, shared_scene,
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
    let scene = gen_forest(
        dir.path(),
        &["--levels", "2", "--grid", "3x2", "--leaves", "200"],
    );
    let pkg = dir.path().join("f.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
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
    // Elements alone need 27–40 MiB at the island camera's 1024×429 (frame buffers included).
    let out = motu_ok(&["report", s(&ipkg), "--budget", "32MiB"]);
    assert!(out.contains("--subset "), "a ready --subset list: {out}");
}

/// The report's peaks are budgets the renderer keeps: the default island's full build renders
/// under `variants[0].cost.peak_bytes` (frame buffers, staging ring and allocator slack
/// included) and fails under three quarters of it; every element renders alone (`--subset`)
/// under its `alone.peak_bytes`, though the package holds every other element's records; and
/// so does bmw-m6 (a scene written by others). Before, the report left out the staging ring,
/// the frame buffers and partly used blocks, and counted a subset's tables as if the renderer
/// uploaded only its own: 15–44% short on lavapipe (buddha-fractal needed 20.1 MB for a
/// printed 14.0 MB) and every element of island 0.002 failed at its printed peak.
#[test]
fn report_peaks_are_budgets_that_render() {
    if !motu_tests::gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("island");
    motu_ok(&["gen", "island", "-o", s(&gen)]);
    let island = dir.path().join("i.motu");
    motu_ok(&["import", s(&gen.join("scene.pbrt")), "-o", s(&island)]);
    let mut pkgs = vec![island.clone()];
    if let Some(bmw) = shared_scene("bmw-m6/bmw-m6.pbrt") {
        let p = dir.path().join("bmw.motu");
        motu_ok(&["import", s(&bmw), "-o", s(&p)]);
        pkgs.push(p);
    }
    let size = ["--width", "64", "--height", "36"];
    let render = |pkg: &std::path::Path, budget: u64, extra: &[&str]| {
        let png = dir.path().join("x.png");
        let b = budget.to_string();
        let mut args = vec!["render", s(pkg), "-o", s(&png), "--vram-budget", &b];
        args.extend_from_slice(&size);
        args.extend_from_slice(extra);
        motu_tests::motu(&args)
    };
    for pkg in &pkgs {
        let mut args = vec!["report", s(pkg), "--json"];
        args.extend_from_slice(&size);
        let r = motu_json(&args);
        let peak = r["variants"][0]["cost"]["peak_bytes"].as_u64().unwrap();
        let overhead = r["render_overhead"]["total_bytes"].as_u64().unwrap();
        assert!(overhead > 0, "{r}");
        let ok = render(pkg, peak, &[]);
        assert!(
            ok.status.success(),
            "{}: the full build under the report's peak {peak}: {}",
            pkg.display(),
            String::from_utf8_lossy(&ok.stderr)
        );
        let short = render(pkg, peak * 3 / 4, &[]);
        assert!(
            !short.status.success(),
            "{}: three quarters of the peak should not fit",
            pkg.display()
        );
        let err = String::from_utf8_lossy(&short.stderr);
        assert!(err.contains("budget") && !err.contains("panicked"), "{err}");
        if pkg != &island {
            continue;
        }
        let mut alone = 0;
        for e in r["elements"].as_array().unwrap() {
            let Some(p) = e["alone"]["peak_bytes"].as_u64() else {
                continue;
            };
            let name = e["name"].as_str().unwrap();
            let out = render(pkg, p, &["--subset", name]);
            assert!(
                out.status.success(),
                "{name} alone under its report peak {p}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            alone += 1;
        }
        assert!(alone >= 5, "{alone} elements rendered alone");
    }
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
        // `motu import` stored the BLAS counts the report walks (a split root too).
        assert_eq!(r["sources"]["blas_counts"], "package", "{}", r["sources"]);
        assert!(
            r["timings_ms"]["ownership"].as_f64().is_some(),
            "{}",
            r["timings_ms"]
        );
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
