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

/// A camera path over the generated island: `shotCam`, then its eye a fifth of the way toward
/// its target (a dolly), at 64×36.
fn dolly_path(dir: &std::path::Path) -> std::path::PathBuf {
    motu_tests::shot_cam_dolly_path(dir, 0.2)
}

/// The per-frame keys of a streaming flight that say where a frame's time went (issue 45.6).
const PHASE_KEYS: [&str; 12] = [
    "frame_ms",
    "host_ms",
    "tables_ms",
    "mesh_ms",
    "blas_ms",
    "tlas_rebuilt",
    "tlas_submits",
    "tlas_fence_waits",
    "submits",
    "fence_waits",
    "mark_walks",
    "first_pass_trace_ms",
];

/// `motu bench --camera-path … --stream` on the default island along a dolly, with a
/// per-frame build budget and the coarse fallback: `--stream-passes 1` flies as the viewer
/// does (one pass a frame, the extrapolated next camera), a still tail converges and says
/// when; without it frames take their passes as before. Every row has the phase columns.
#[test]
fn bench_stream_passes_one_measures_the_viewers_flying_mode() {
    let Some((dir, pkg)) = motu_tests::gpu_island(None) else {
        return;
    };
    let d = dir.path();
    let path = dolly_path(d);
    let flight = |extra: &[&str]| -> serde_json::Value {
        let mut args = vec![
            "bench",
            "--camera-path",
            s(&path),
            "--package",
            s(&pkg),
            "--stream",
            "--stream-fallback",
            "coarse",
            "--stream-build-budget",
            "2MiB",
            "--frames",
            "4",
            // No warm-up renderer: on lavapipe each new trace pipeline is a fresh LLVM compile.
            "--warmup",
            "0",
            "--backend",
            "pipeline",
            "--json",
        ];
        args.extend(extra);
        motu_json(&args)
    };
    let u = motu_tests::json_u64;
    let still = 16;
    let b = flight(&[
        "--stream-passes",
        "1",
        "--next-camera",
        "extrapolated",
        "--still-frames",
        "16",
    ]);
    assert_eq!(b["progressive"], true, "{b}");
    assert_eq!(b["stream_passes"], 1, "{b}");
    assert_eq!(b["next_camera"], "extrapolated", "{b}");
    let rows = b["per_frame"].as_array().expect("per_frame");
    assert_eq!(rows.len(), 4 + still, "{b}");
    // One pass a frame while moving, and at rest (from the path's last frame, its pose) until
    // two frames there were incomplete (then a still camera settles: `render_progressive`,
    // tests/tests/stream_settle.rs).
    let mut still_incomplete = 0;
    for (f, r) in rows.iter().enumerate() {
        if f < 3 || still_incomplete < 2 {
            assert_eq!(r["passes"], 1, "one pass a frame: {r}");
        }
        if f >= 3 && r["complete"] != true {
            still_incomplete += 1;
        }
        for k in PHASE_KEYS {
            assert!(r[k].is_number(), "{k}: {r}");
        }
        // The trace alone is a submission waited for; the TLAS rebuilds' are the frame's.
        assert!(u(&r["fence_waits"]) >= 1, "{r}");
        assert!(u(&r["tlas_fence_waits"]) <= u(&r["fence_waits"]), "{r}");
        assert!(u(&r["tlas_submits"]) <= u(&r["submits"]), "{r}");
        assert!(r["frame_ms"].as_f64() >= r["trace_ms"].as_f64(), "{r}");
    }
    // Nothing is resident at the start: the first frame is all fallback, counted.
    assert!(u(&rows[0]["fallback_pixels"]) > 0, "{}", rows[0]);
    assert_eq!(rows[0]["complete"], false, "{}", rows[0]);
    // The viewer's next camera: none before a previous frame; one while moving, and the
    // camera itself while still (a frame that left all it saw resident skips its probe).
    let named: Vec<bool> = rows.iter().map(|r| r["next_camera"] == true).collect();
    assert_eq!(named[..4], [false, true, true, true], "{named:?}");
    assert!(named[4..].iter().all(|&n| n), "{named:?}");
    assert!(b["median_fallback_pixels"].is_number(), "{b}");
    // At rest the frames refine to complete, and the report says after how many.
    let k = u(&b["still_frames_to_complete"]) as usize;
    assert!((1..=still).contains(&k), "{b}");
    assert_eq!(rows[3 + k]["complete"], true, "{b}");
    assert!(rows[4..3 + k].iter().all(|r| r["complete"] == false), "{b}");
    assert_eq!(rows.last().unwrap()["complete"], true, "{b}");

    // Without --stream-passes: `render_frame` as before, the path's next pose named.
    let b = flight(&[]);
    assert_eq!(b["progressive"], false, "{b}");
    assert!(b["stream_passes"].is_null(), "{b}");
    assert!(b["still_frames_to_complete"].is_null(), "{b}");
    let rows = b["per_frame"].as_array().expect("per_frame");
    assert_eq!(rows.len(), 4, "{b}");
    // The cold start's pass left pixels open, the step built, a last pass traced them again.
    assert!(u(&rows[0]["passes"]) >= 2, "{}", rows[0]);
    let named: Vec<bool> = rows.iter().map(|r| r["next_camera"] == true).collect();
    assert_eq!(named, [true, true, true, false], "{b}");
    for r in rows {
        for k in PHASE_KEYS {
            assert!(r[k].is_number(), "{k}: {r}");
        }
    }

    // The viewer's options need streaming; no pass is no frame.
    let out = motu(&[
        "bench",
        "--camera-path",
        s(&path),
        "--package",
        s(&pkg),
        "--stream-passes",
        "1",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("need --stream"),
        "{err}"
    );
    let out = motu(&[
        "bench",
        "--camera-path",
        s(&path),
        "--package",
        s(&pkg),
        "--stream",
        "--stream-passes",
        "0",
    ]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("at least 1"), "{err}");
}
