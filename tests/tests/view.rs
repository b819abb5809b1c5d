//! `motu view` (issue 17) through a real window and swapchain: Xvfb on lavapipe in CI. Frames
//! read back from the swapchain must equal `motu render` per pixel; recorded camera paths must
//! replay identically in both; without a display the viewer must point at `motu render`.

use motu_tests::{
    gen_forest, gen_island, gen_lod_grid, gpu_available, has_ray_query, motu, motu_ok,
    motu_on_display, motu_on_wayland, report_peak_and_floor, s, weston, xvfb,
};
use std::path::{Path, PathBuf};

fn forest(dir: &Path) -> PathBuf {
    let scene = gen_forest(dir, &["--levels", "2", "--grid", "3x2", "--leaves", "60"]);
    let pkg = dir.join("forest.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    pkg
}

/// `motu view` on `display`, asserting success; returns stderr.
fn view_ok(display: &str, args: &[&str]) -> String {
    let mut all = vec!["view"];
    all.extend_from_slice(args);
    let out = motu_on_display(display, &all);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        out.status.success(),
        "motu {} failed:\n{err}",
        all.join(" ")
    );
    err
}

/// LOD in the viewer runs like `motu render`'s: instance-level by default (one trace, the
/// same levels as the render), the traversal shader with `--lod-mode traversal`; each equals
/// the render of the same mode per pixel and `--stats` names the mode that ran.
#[test]
fn view_lod_modes_equal_render_per_pixel() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("view_lod_modes_equal_render_per_pixel") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let (_, pkg) = gen_lod_grid(d, "grid", "6x12", "lod.motu", "4");
    for (mode, traces_max) in [("instance", 1.05), ("traversal", f64::INFINITY)] {
        let (vaov, vstats, raov) = (
            d.join(format!("view-{mode}.aov")),
            d.join(format!("view-{mode}.json")),
            d.join(format!("render-{mode}.aov")),
        );
        let mut args = vec![
            s(&pkg),
            "--width",
            "96",
            "--backend",
            "pipeline",
            "--view",
            "lod",
            "--frames",
            "2",
            "--aov",
            s(&vaov),
            "--stats",
            s(&vstats),
        ];
        if mode == "traversal" {
            args.extend(["--lod-mode", "traversal"]);
        }
        view_ok(&x.display, &args);
        let png = d.join(format!("render-{mode}.png"));
        render_full(
            &pkg,
            &png,
            &raov,
            &["--width", "96", "--view", "lod", "--lod-mode", mode],
        );
        compare_exact(&vaov, &raov);
        let st = read_json(&vstats);
        assert_eq!(st["lod_mode"], mode, "{st}");
        let traces = st["traces_per_ray"].as_f64().unwrap();
        assert!(traces <= traces_max, "{mode}: {traces} traces/ray: {st}");
        if mode == "traversal" {
            assert!(traces > 1.2, "traversal LOD takes hops: {st}");
        }
    }
}

/// `motu view` on a Wayland compositor (no X display): a native Wayland window and swapchain
/// whose frames equal `motu render`'s per pixel, like the X11 path.
#[test]
fn view_on_wayland_equals_render_per_pixel() {
    if !gpu_available() {
        return;
    }
    let Some(w) = weston("view_on_wayland_equals_render_per_pixel") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = forest(d);
    let (vpng, vaov, vstats) = (d.join("view.png"), d.join("view.aov"), d.join("view.json"));
    let out = motu_on_wayland(
        &w,
        &[
            "view",
            s(&pkg),
            "--width",
            "96",
            "--backend",
            "pipeline",
            "--frames",
            "3",
            "--screenshot",
            s(&vpng),
            "--aov",
            s(&vaov),
            "--stats",
            s(&vstats),
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "motu view on Wayland failed:\n{err}");
    assert!(!err.contains("ERROR"), "{err}");
    let (rpng, raov) = (d.join("render.png"), d.join("render.aov"));
    render_full(&pkg, &rpng, &raov, &["--width", "96"]);
    compare_exact(&vaov, &raov);
    assert!(
        decode_png(&vpng) == decode_png(&rpng),
        "the Wayland swapchain image differs from motu render's PNG"
    );
    let st = read_json(&vstats);
    assert_eq!(st["frames"], 3, "{st}");
    assert_eq!(st["window"]["presented_via"], "swapchain", "{st}");
}

/// `motu render PKG -o PNG --aov AOV --backend pipeline EXTRA...`: the full build the
/// viewer's image is compared with.
fn render_full(pkg: &Path, png: &Path, aov: &Path, extra: &[&str]) {
    let mut args = vec![
        "render",
        s(pkg),
        "-o",
        s(png),
        "--aov",
        s(aov),
        "--backend",
        "pipeline",
    ];
    args.extend_from_slice(extra);
    motu_ok(&args);
}

fn compare_exact(a: &Path, b: &Path) {
    let out = motu_ok(&["compare", s(a), s(b), "--max-mismatch", "0"]);
    assert!(out.contains("(0 of "), "{out}");
}

fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(p).expect("stats file")).expect("stats JSON")
}

fn decode_png(p: &Path) -> (u32, u32, Vec<u8>) {
    let dec = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(p).expect("png"),
    ));
    let mut r = dec.read_info().expect("png header");
    let mut buf = vec![0; r.output_buffer_size().expect("png size")];
    let info = r.next_frame(&mut buf).expect("png frame");
    buf.truncate(info.buffer_size());
    (info.width, info.height, buf)
}

#[test]
fn view_without_a_display_names_the_headless_path() {
    let out = std::process::Command::new(motu_tests::motu_bin())
        .args(["view", "scene.motu", "--frames", "1"])
        .env_remove("DISPLAY")
        .env_remove("WAYLAND_DISPLAY")
        .output()
        .expect("spawning motu");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "must fail without a display: {err}");
    assert!(err.contains("no display"), "{err}");
    assert!(
        err.contains("DISPLAY") && err.contains("WAYLAND_DISPLAY"),
        "{err}"
    );
    assert!(err.contains("motu render"), "{err}");
}

#[test]
fn view_frames_through_the_swapchain_equal_render_per_pixel() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("view_frames_through_the_swapchain_equal_render_per_pixel") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = forest(d);
    let mut cases = vec![("pipeline", "shaded"), ("pipeline", "heatmap")];
    if has_ray_query() {
        cases.push(("query", "ids"));
    }
    for (backend, view) in cases {
        let tag = format!("{backend}-{view}");
        let (vpng, vaov, vstats) = (
            d.join(format!("view-{tag}.png")),
            d.join(format!("view-{tag}.aov")),
            d.join(format!("view-{tag}.json")),
        );
        view_ok(
            &x.display,
            &[
                s(&pkg),
                "--width",
                "96",
                "--backend",
                backend,
                "--view",
                view,
                "--frames",
                "5",
                "--screenshot",
                s(&vpng),
                "--aov",
                s(&vaov),
                "--stats",
                s(&vstats),
            ],
        );
        let (rpng, raov) = (
            d.join(format!("render-{tag}.png")),
            d.join(format!("render-{tag}.aov")),
        );
        motu_ok(&[
            "render",
            s(&pkg),
            "-o",
            s(&rpng),
            "--aov",
            s(&raov),
            "--width",
            "96",
            "--backend",
            backend,
            "--view",
            view,
        ]);
        compare_exact(&vaov, &raov);
        // The screenshot is the swapchain image read back: the window got the same pixels.
        let (vw, vh, vpx) = decode_png(&vpng);
        let (rw, rh, rpx) = decode_png(&rpng);
        assert_eq!((vw, vh), (rw, rh), "{tag}");
        assert!(
            vpx == rpx,
            "{tag}: the swapchain image differs from motu render's PNG"
        );
        let st = read_json(&vstats);
        assert_eq!(st["frames"], 5, "{st}");
        assert_eq!(st["backend"], backend, "{st}");
        assert_eq!(st["window"]["presented_via"], "swapchain", "{st}");
        assert_eq!(st["streaming"], false, "{st}");
        assert!(st["traces_per_ray"].as_f64().unwrap() >= 1.0, "{st}");
        assert!(
            st["resident_structures"].as_u64().unwrap() > 0
                && st["resident_structures"] == st["total_structures"],
            "{st}"
        );
    }
    // The panel, when shown in a scripted run, is drawn on the window after the read-back:
    // the screenshot and the AOV are the frame without it (equal to the render's), and every
    // frame presented had the panel drawn over it.
    let (ppng, paov, pstats) = (
        d.join("panel.png"),
        d.join("panel.aov"),
        d.join("panel.json"),
    );
    view_ok(
        &x.display,
        &[
            s(&pkg),
            "--width",
            "96",
            "--backend",
            "pipeline",
            "--frames",
            "2",
            "--overlay",
            "--screenshot",
            s(&ppng),
            "--aov",
            s(&paov),
            "--stats",
            s(&pstats),
        ],
    );
    let st = read_json(&pstats);
    assert_eq!(st["window"]["panel_frames"], 2, "{st}");
    // It did reach the window: the image read again after drawing it differs.
    let (pw, ph) = (96u64, u64::from(decode_png(&ppng).1));
    let changed = st["window"]["panel_pixels"].as_u64().unwrap();
    assert!(changed > 0 && changed <= pw * ph, "{st}");
    compare_exact(&paov, &d.join("render-pipeline-shaded.aov"));
    assert!(
        decode_png(&ppng) == decode_png(&d.join("render-pipeline-shaded.png")),
        "the panel reached the screenshot"
    );
    let st = read_json(&d.join("view-pipeline-shaded.json"));
    assert_eq!(
        st["window"]["panel_frames"], 0,
        "a scripted run without --overlay shows no panel: {st}"
    );
}

/// A camera path with four distinct poses around the start camera (read from a recording).
fn scripted_path(d: &Path, display: &str, pkg: &Path) -> PathBuf {
    let start = d.join("start.json");
    view_ok(
        display,
        &[
            s(pkg),
            "--width",
            "80",
            "--backend",
            "pipeline",
            "--frames",
            "1",
            "--record",
            s(&start),
        ],
    );
    let rec = read_json(&start);
    assert_eq!(rec["format"], "motu-camera-path", "{rec}");
    assert_eq!(rec["frames"].as_array().unwrap().len(), 1, "{rec}");
    let p0 = rec["frames"][0].clone();
    let f = |v: &serde_json::Value, i: usize| v[i].as_f64().unwrap();
    let mut frames = Vec::new();
    for k in 0..4 {
        let mut p = p0.clone();
        let t = k as f64 / 3.0;
        // Walk forward along the view and turn a little: every frame sees something else.
        for i in 0..3 {
            p["eye"][i] = (f(&p0["eye"], i) + f(&p0["forward"], i) * t * 20.0).into();
        }
        p["forward"][0] = (f(&p0["forward"], 0) + 0.3 * t).into();
        p["fov_deg"] = (40.0 + 5.0 * t).into();
        frames.push(p);
    }
    let path = d.join("path.json");
    let file = serde_json::json!({
        "format": "motu-camera-path", "version": 1, "width": 80, "height": 45, "frames": frames,
    });
    std::fs::write(&path, serde_json::to_string_pretty(&file).unwrap()).unwrap();
    path
}

#[test]
fn a_recorded_camera_path_replays_identically_in_view_and_render() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("a_recorded_camera_path_replays_identically_in_view_and_render") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = forest(d);
    let path = scripted_path(d, &x.display, &pkg);
    // One frame per recorded pose (4), then the same path spread over 7 frames (interpolated).
    for frames in ["4", "7"] {
        let (vaov, raov) = (
            d.join(format!("view-{frames}.aov")),
            d.join(format!("render-{frames}.aov")),
        );
        let again = d.join(format!("again-{frames}.json"));
        let err = view_ok(
            &x.display,
            &[
                s(&pkg),
                "--backend",
                "pipeline",
                "--camera-path",
                s(&path),
                "--frames",
                frames,
                "--aov",
                s(&vaov),
                "--record",
                s(&again),
            ],
        );
        assert!(err.contains(&format!("{frames} frames shown")), "{err}");
        let rstats = d.join(format!("render-{frames}.json"));
        render_full(
            &pkg,
            &d.join(format!("render-{frames}.png")),
            &raov,
            &[
                "--camera-path",
                s(&path),
                "--frames",
                frames,
                "--stats",
                s(&rstats),
            ],
        );
        compare_exact(&vaov, &raov);
        let st = read_json(&rstats);
        assert_eq!(st["frames"].as_u64(), frames.parse().ok(), "{st}");
        assert_eq!(st["width"], 80, "the path's recorded size: {st}");
        // What view flew is what the file said: re-recording the replay gives the same poses.
        let again = read_json(&again);
        let original = read_json(&path);
        assert_eq!(
            again["frames"].as_array().unwrap().len(),
            frames.parse::<usize>().unwrap()
        );
        if frames == "4" {
            // Poses are f32: the file's decimal values, rounded to f32, exactly.
            let flat = |v: &serde_json::Value| -> Vec<f32> {
                let mut out = Vec::new();
                for fr in v["frames"].as_array().unwrap() {
                    for k in ["eye", "forward", "up"] {
                        out.extend(
                            fr[k]
                                .as_array()
                                .unwrap()
                                .iter()
                                .map(|x| x.as_f64().unwrap() as f32),
                        );
                    }
                    out.push(fr["fov_deg"].as_f64().unwrap() as f32);
                }
                out
            };
            assert_eq!(flat(&again), flat(&original));
        }
    }
    // The same flight as a benchmark: one timed frame per pose.
    let b = motu_tests::motu_json(&[
        "bench",
        "--camera-path",
        s(&path),
        "--package",
        s(&pkg),
        "--backend",
        "pipeline",
        "--warmup",
        "1",
        "--json",
    ]);
    assert_eq!(b["kind"], "flight", "{b}");
    assert_eq!(b["frames"], 4, "{b}");
    let ms = b["frame_ms"].as_array().unwrap();
    assert_eq!(ms.len(), 4, "{b}");
    assert!(ms.iter().all(|m| m.as_f64().unwrap() > 0.0), "{b}");
    assert!(b["traces_per_ray_mean"].as_f64().unwrap() >= 1.0, "{b}");
    // The path moves: its last frame is not its first pose.
    let first = d.join("first.aov");
    let one = d.join("one.json");
    let mut p = read_json(&path);
    p["frames"] = serde_json::json!([p["frames"][0].clone()]);
    std::fs::write(&one, p.to_string()).unwrap();
    render_full(
        &pkg,
        &d.join("first.png"),
        &first,
        &["--camera-path", s(&one)],
    );
    let out = motu(&[
        "compare",
        s(&first),
        s(&d.join("render-4.aov")),
        "--max-mismatch",
        "0",
    ]);
    assert!(
        !out.status.success(),
        "the path's frames are all the same image"
    );
}

#[test]
fn view_streams_under_a_vram_budget_with_the_full_builds_image() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("view_streams_under_a_vram_budget_with_the_full_builds_image") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = forest(d);
    let (vaov, vstats, raov) = (d.join("v.aov"), d.join("v.json"), d.join("r.aov"));
    view_ok(
        &x.display,
        &[
            s(&pkg),
            "--width",
            "64",
            "--backend",
            "pipeline",
            "--vram-budget",
            "256MiB",
            // The budget holds the forest: the full build would draw it (view_fit.rs).
            "--stream-always",
            "--frames",
            "3",
            "--aov",
            s(&vaov),
            "--stats",
            s(&vstats),
        ],
    );
    render_full(&pkg, &d.join("r.png"), &raov, &["--width", "64"]);
    compare_exact(&vaov, &raov);
    let st = read_json(&vstats);
    assert_eq!(st["streaming"], true, "{st}");
    assert_eq!(st["detail"]["complete"], true, "{st}");
    assert!(st["detail"]["frame"].as_u64() == Some(3), "{st}");
    assert!(st["vram_used_bytes"].as_u64().unwrap() <= 256 << 20, "{st}");
}

#[test]
fn streaming_refines_over_frames_and_never_writes_an_unfinished_frame() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("streaming_refines_over_frames_and_never_writes_an_unfinished_frame") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = forest(d);
    // A budget far below the full build (as in the render streaming tests): the first frame
    // needs several build-trace passes.
    let common = [
        s(&pkg),
        "--width",
        "64",
        "--backend",
        "pipeline",
        "--vram-budget",
        "3MiB",
        "--stream-always",
        // What the frames evict and need again is restored or built by fixed rates, not by
        // this machine's timing (the passes decide whether the frame completes).
        motu_tests::PINNED_RATES[0],
        motu_tests::PINNED_RATES[1],
    ];
    let (vaov, vstats, raov) = (d.join("v.aov"), d.join("v.json"), d.join("r.aov"));
    // With carried hits this small forest completes within two passes at this budget, so the
    // refinement over several frames is not exercised here (a scene whose working set exceeds
    // the budget is needed: noted on issue 17).
    let mut args = common.to_vec();
    args.extend_from_slice(&[
        "--stream-passes",
        "2",
        "--frames",
        "8",
        "--aov",
        s(&vaov),
        "--stats",
        s(&vstats),
    ]);
    view_ok(&x.display, &args);
    let st = read_json(&vstats);
    assert_eq!(st["detail"]["complete"], true, "{st}");
    assert!(st["vram_used_bytes"].as_u64().unwrap() <= 3 << 20, "{st}");
    render_full(&pkg, &d.join("r.png"), &raov, &["--width", "64"]);
    compare_exact(&vaov, &raov);
}

/// A scripted run whose last frame is unfinished fails and writes nothing: the default island
/// just above its streaming floor needs far more than two passes for its first frame.
#[test]
fn view_never_writes_an_unfinished_frame() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("view_never_writes_an_unfinished_frame") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = gen_island(d, None);
    let (_, floor) = report_peak_and_floor(&pkg, "64", "36");
    let budget = (floor as f64 * 1.05) as u64;
    let bad = d.join("bad.aov");
    let budget_arg = budget.to_string();
    let out = motu_on_display(
        &x.display,
        &[
            "view",
            s(&pkg),
            "--width",
            "64",
            "--height",
            "36",
            "--backend",
            "pipeline",
            "--vram-budget",
            &budget_arg,
            "--stream-always",
            "--stream-passes",
            "2",
            "--frames",
            "1",
            "--aov",
            s(&bad),
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "two passes cannot finish the first frame: {err}"
    );
    assert!(err.contains("incomplete"), "{err}");
    assert!(!bad.exists(), "an unfinished frame was written");
}

#[test]
fn view_subsets_equal_render_subsets() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("view_subsets_equal_render_subsets") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = gen_island(d, None);
    let raov = d.join("r.aov");
    render_full(
        &pkg,
        &d.join("r.png"),
        &raov,
        &["--width", "64", "--subset", "isBeach,isMountainA"],
    );
    // The full build, the hand-over of a budget that holds the subset, and the streamer.
    for extra in [
        &[][..],
        &["--stream"][..],
        &["--stream", "--stream-always"][..],
    ] {
        let vaov = d.join(format!("v{}.aov", extra.len()));
        let mut args = vec![
            s(&pkg),
            "--width",
            "64",
            "--backend",
            "pipeline",
            "--subset",
            "isBeach,isMountainA",
            "--frames",
            "2",
            "--aov",
            s(&vaov),
        ];
        args.extend_from_slice(extra);
        view_ok(&x.display, &args);
        compare_exact(&vaov, &raov);
    }
    // An unknown element is a clear error.
    let out = motu_on_display(
        &x.display,
        &["view", s(&pkg), "--subset", "nope", "--frames", "1"],
    );
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("nope"));
}

#[test]
fn bad_camera_paths_fail_with_the_reason() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = forest(d);
    let bad = d.join("bad.json");
    // Renders the camera path `text`: it fails, writes no image, and its message is returned.
    let refused = |text: &str| -> String {
        std::fs::write(&bad, text).unwrap();
        let out = motu(&[
            "render",
            s(&pkg),
            "-o",
            s(&d.join("x.png")),
            "--backend",
            "cpu",
            "--camera-path",
            s(&bad),
        ]);
        assert!(!out.status.success());
        assert!(!d.join("x.png").exists(), "no output on bad input");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let err = refused("{\"format\": \"motu-camera-path\",\n \"version\": 1, \"frames\": [}");
    assert!(
        err.contains("camera path") && err.contains("line 2"),
        "{err}"
    );
    let err = refused(
        r#"{"format":"motu-camera-path","version":1,"frames":[{"eye":[0,0,0],"forward":[0,0,0],"up":[0,1,0],"fov_deg":40}]}"#,
    );
    assert!(err.contains("frame 0") && err.contains("forward"), "{err}");
}

/// Issue 17 item 3: `motu view --stream` with a per-frame build budget traces each frame with
/// what is resident (`--stream-passes 1`: trace, then build toward the next frame), shows the
/// counted fallback for the rest, and refines until a frame equals `motu render` of the same
/// camera per pixel. The default island's first view needs far more than the 2 MiB budget.
#[test]
fn view_streams_progressively_within_a_frame_build_budget() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("view_streams_progressively_within_a_frame_build_budget") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = gen_island(d, None);
    // One pose, the start camera (recorded through the window).
    let start = d.join("start.json");
    view_ok(
        &x.display,
        &[
            s(&pkg),
            "--width",
            "64",
            "--height",
            "36",
            "--backend",
            "pipeline",
            "--frames",
            "1",
            "--record",
            s(&start),
        ],
    );
    let raov = d.join("r.aov");
    motu_ok(&[
        "render",
        s(&pkg),
        "-o",
        s(&d.join("r.png")),
        "--backend",
        "pipeline",
        "--camera-path",
        s(&start),
        "--aov",
        s(&raov),
    ]);
    let vaov = d.join("v.aov");
    let vstats = d.join("v.json");
    let err = view_ok(
        &x.display,
        &[
            s(&pkg),
            "--backend",
            "pipeline",
            "--camera-path",
            s(&start),
            "--frames",
            "24",
            "--stream",
            "--stream-always",
            "--stream-passes",
            "1",
            "--stream-build-budget",
            "2MiB",
            "--stream-fallback",
            "coarse",
            "--aov",
            s(&vaov),
            "--stats",
            s(&vstats),
        ],
    );
    let st = read_json(&vstats);
    let per_frame: Vec<u64> = st["incomplete_pixels_per_frame"]
        .as_array()
        .expect("per-frame counts")
        .iter()
        .map(|v| v.as_u64().unwrap())
        .collect();
    eprintln!("pixels refining per frame: {per_frame:?}");
    assert_eq!(per_frame.len(), 24, "{st}");
    assert!(
        per_frame[0] > 0,
        "frame 1 shows the fallback: {per_frame:?}"
    );
    assert_eq!(*per_frame.last().unwrap(), 0, "{per_frame:?}; {err}");
    assert_eq!(st["detail"]["passes"], 1, "one trace per frame: {st}");
    assert_eq!(st["detail"]["complete"], true, "{st}");
    compare_exact(&vaov, &raov);
}

/// Issue 47 item 3: a window at rest accumulates samples (each frame the next ones of every
/// pixel's sequence), so its image converges toward a many-sample render while the AOV stays
/// the pixel centres' (equal to `motu render`'s); `--denoise` (the N key) filters what is shown.
#[test]
fn view_accumulates_samples_at_rest_toward_a_many_sample_render() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("view_accumulates_samples_at_rest_toward_a_many_sample_render") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = forest(d);
    let size = ["--width", "48", "--height", "32", "--backend", "pipeline"];
    let (vpng, vaov, vstats) = (d.join("v.png"), d.join("v.aov"), d.join("v.json"));
    let mut args = vec![s(&pkg), "--frames", "16", "--accumulate"];
    args.extend(size);
    args.extend([
        "--screenshot",
        s(&vpng),
        "--aov",
        s(&vaov),
        "--stats",
        s(&vstats),
    ]);
    view_ok(&x.display, &args);
    let st = read_json(&vstats);
    assert_eq!(st["accumulated_samples"], 16, "{st}");
    assert_eq!(st["denoised"], false, "{st}");
    let render_spp = |spp: &str| {
        let (png, aov) = (d.join(format!("r{spp}.png")), d.join(format!("r{spp}.aov")));
        let mut args = vec![
            "render",
            s(&pkg),
            "-o",
            s(&png),
            "--aov",
            s(&aov),
            "--spp",
            spp,
        ];
        args.extend(size);
        motu_ok(&args);
        (decode_png(&png).2, aov)
    };
    let (one, one_aov) = render_spp("1");
    let (many, _) = render_spp("256");
    compare_exact(&vaov, &one_aov);
    let (_, _, shown) = decode_png(&vpng);
    let mad = |a: &[u8], b: &[u8]| {
        a.iter()
            .zip(b)
            .map(|(p, q)| f64::from(p.abs_diff(*q)))
            .sum::<f64>()
            / a.len() as f64
    };
    let (e_one, e_view) = (mad(&one, &many), mad(&shown, &many));
    eprintln!(
        "mean absolute difference to 256 spp: 1 spp {e_one:.2}, 16 frames at rest {e_view:.2}"
    );
    assert!(
        e_view < 0.6 * e_one,
        "16 frames at rest are not nearer 256 spp than one frame: {e_view:.2} vs {e_one:.2}"
    );
    // Without --accumulate a scripted frame is the render's (the other tests rely on it); with
    // --denoise the shown image is filtered.
    let dpng = d.join("dn.png");
    let mut args = vec![s(&pkg), "--frames", "2", "--denoise"];
    args.extend(size);
    args.extend(["--screenshot", s(&dpng), "--stats", s(&vstats)]);
    view_ok(&x.display, &args);
    let st = read_json(&vstats);
    assert_eq!(st["denoised"], true, "{st}");
    assert_eq!(st["accumulated_samples"], 1, "{st}");
    assert_ne!(decode_png(&dpng).2, one, "the denoiser changed nothing");
}

/// Issue 45 item 6: the viewer streams with the structure cache as `motu render --stream`
/// does: a second viewer process over the same `--as-cache` directory restores every BLAS the
/// first built, from disk, and shows the same image.
#[test]
fn a_second_viewer_restores_structures_from_the_cache_directory() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("a_second_viewer_restores_structures_from_the_cache_directory") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = forest(d);
    let cache = d.join("as-cache");
    let run = |name: &str| {
        let (aov, stats) = (
            d.join(format!("{name}.aov")),
            d.join(format!("{name}.json")),
        );
        view_ok(
            &x.display,
            &[
                s(&pkg),
                "--width",
                "48",
                "--backend",
                "pipeline",
                "--stream",
                "--stream-always",
                "--frames",
                "1",
                "--as-cache",
                s(&cache),
                // Every cached BLAS restored, whatever this device's rates say.
                "--stream-host-cache-policy",
                "always",
                "--aov",
                s(&aov),
                "--stats",
                s(&stats),
            ],
        );
        let st = read_json(&stats);
        let detail: serde_json::Value = match &st["detail"] {
            serde_json::Value::String(t) => serde_json::from_str(t).unwrap(),
            v => v.clone(),
        };
        (aov, detail)
    };
    let (cold_aov, cold) = run("cold");
    let built = cold["blas_built"].as_u64().unwrap();
    assert!(built > 0, "{cold}");
    assert_eq!(cold["cache_stored"].as_u64(), Some(built), "{cold}");
    let (warm_aov, warm) = run("warm");
    assert_eq!(warm["blas_built"].as_u64(), Some(0), "{warm}");
    assert_eq!(warm["restored_from_disk"].as_u64(), Some(built), "{warm}");
    compare_exact(&cold_aov, &warm_aov);
}
