//! `motu bench` end to end on the tiniest settings (issue 10): every step runs in a child
//! process, the JSON report has the contract's keys, the measurements are sane and the ratios
//! are taken against the `sl` configuration of the same run. Runs on lavapipe in CI (or on the
//! CPU backend, said out loud, where no Vulkan device exists).

use motu_tests::{motu, motu_json, s};

#[test]
fn bench_quick_json_reports_every_configuration_with_sane_values() {
    let dir = tempfile::tempdir().unwrap();
    let work = dir.path().join("work");
    let md = dir.path().join("bench.md");
    let r = motu_json(&[
        "bench",
        "quick",
        "--json",
        "--work-dir",
        s(&work),
        "--only",
        "forest,sphereflake",
        "--width",
        "48",
        "--height",
        "27",
        "--frames",
        "2",
        "--warmup",
        "1",
        "--markdown",
        s(&md),
    ]);
    for key in [
        "suite", "command", "commit", "machine", "settings", "scenes", "total_s", "failures",
    ] {
        assert!(r.get(key).is_some(), "missing key {key}: {r}");
    }
    assert_eq!(r["suite"], "quick");
    assert_eq!(r["failures"], 0, "{r:#}");
    assert_eq!(r["complete"], true);
    assert_eq!(r["settings"]["width"], 48);
    let scenes = r["scenes"].as_array().unwrap();
    let names: Vec<&str> = scenes.iter().map(|s| s["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["forest", "sphereflake"]);
    for sc in scenes {
        let labels: Vec<&str> = sc["configs"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c["label"].as_str().unwrap())
            .collect();
        assert_eq!(labels, ["sl", "ml", "levels2", "auto"], "{sc}");
        let flattened = sc["gen"]["flattened_instances"].as_u64().unwrap();
        for c in sc["configs"].as_array().unwrap() {
            let ctx = format!("{}/{}: {c:#}", sc["name"], c["label"]);
            assert_eq!(c["status"], "ok", "{ctx}");
            let i = &c["import"];
            assert!(i["wall_s"].as_f64().unwrap() > 0.0, "{ctx}");
            assert!(i["peak_rss_bytes"].as_u64().unwrap() > 1 << 20, "{ctx}");
            assert!(i["file_bytes"].as_u64().unwrap() > 0, "{ctx}");
            // Every configuration of one scene renders the same flattened instances.
            assert_eq!(i["flattened_instances"].as_u64(), Some(flattened), "{ctx}");
            let m = &c["render"];
            assert_eq!(m["width"], 48, "{ctx}");
            assert_eq!(m["frames"], 2, "{ctx}");
            assert!(m["ms_per_frame"].as_f64().unwrap() > 0.0, "{ctx}");
            // Primary rays for every pixel plus some shadow rays.
            assert!(m["rays"].as_u64().unwrap() > 48 * 27, "{ctx}");
            assert!(m["rays_per_second"].as_f64().unwrap() > 0.0, "{ctx}");
            assert!(m["traces_per_ray"].as_f64().unwrap() >= 1.0, "{ctx}");
            assert_eq!(m["stack_overflows"], 0, "{ctx}");
            if m["backend"] != "cpu" {
                assert!(m["as_bytes"].as_u64().unwrap() > 0, "{ctx}");
                assert!(
                    m["blas_compacted_bytes"].as_u64() <= m["blas_bytes"].as_u64(),
                    "{ctx}"
                );
            }
            let rays_vs_sl = c["ratios"]["rays_per_second_vs_sl"].as_f64().unwrap();
            assert!(rays_vs_sl > 0.0, "{ctx}");
            if c["label"] == "sl" {
                assert_eq!(rays_vs_sl, 1.0, "{ctx}");
            }
            if m["backend"] != "cpu" {
                assert!(
                    c["ratios"]["as_bytes_sl_over_this"].as_f64().unwrap() > 0.0,
                    "{ctx}"
                );
            }
        }
    }
    // Multi-level instancing keeps the forest's shared trees: fewer AS bytes than flattening.
    let forest = &scenes[0]["configs"];
    if forest[0]["render"]["backend"] != "cpu" {
        assert!(
            forest[1]["ratios"]["as_bytes_sl_over_this"]
                .as_f64()
                .unwrap()
                > 1.0
        );
    }
    let table = std::fs::read_to_string(&md).unwrap();
    assert!(table.contains("| forest | ml |"), "{table}");
    assert!(work.join("bench.json").exists());
    // Packages are removed after rendering unless --keep.
    assert_eq!(std::fs::read_dir(work.join("packages")).unwrap().count(), 0);
}

#[test]
fn bench_rejects_unknown_suites_and_scenes_with_a_clear_error() {
    let out = motu(&["bench", "nosuch", "--dry-run"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("gpu, quick and cpu"), "{err}");
    let out = motu(&["bench", "quick", "--only", "teapot", "--dry-run"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("unknown scene"));
}

#[test]
fn bench_gpu_plan_is_the_thesis_suite() {
    let plan = motu_json(&["bench", "gpu", "--dry-run"]);
    assert_eq!(plan["settings"]["width"], 1920);
    assert_eq!(plan["settings"]["height"], 1080);
    assert!(plan["settings"]["frames"].as_u64().unwrap() >= 20);
    assert!(plan["settings"]["warmup_frames"].as_u64().unwrap() >= 1);
    let scenes = plan["scenes"].as_array().unwrap();
    let forest = &scenes[0];
    assert_eq!(
        forest["source"]["args"],
        serde_json::json!(["forest", "--levels", "3", "--grid", "4x3", "--leaves", "8732"])
    );
    let island = scenes.iter().find(|s| s["name"] == "island").unwrap();
    // The island is last, and large enough to overflow one TLAS when flattened.
    assert_eq!(scenes.last().unwrap()["name"], "island");
    assert_eq!(island["must_exceed_instances"], (1u64 << 24) - 1);
    let scale: f64 = island["source"]["args"][2]
        .as_str()
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        scale * 28.0e6 > 16.9e6,
        "island scale {scale} is too small to overflow 2^24"
    );
}
