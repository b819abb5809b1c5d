//! Issue 45 item 1 in the viewer: `motu view --stream` (and `--vram-budget`) hands a budget that
//! holds the whole scene to the full build, as `motu render --stream` does (tests/stream_fit.rs):
//! `stream_fit` in `--stats` says so (`streaming` false), the frame is the render's per pixel,
//! a budget equal to the bound holds it, a byte less streams, and `--stream-always` streams
//! regardless. On a textured scene, so the full build's frames also show that the viewer draws
//! textures as `motu render` does (Xvfb, lavapipe, 64×36).

use motu_tests::{checker_scene, gpu_available, json_u64 as u, motu_ok, motu_on_display, s, xvfb};
use std::path::{Path, PathBuf};

const SIZE: [&str; 6] = ["--width", "64", "--height", "36", "--backend", "pipeline"];

fn decode_png(p: &Path) -> Vec<u8> {
    let dec = png::Decoder::new(std::io::BufReader::new(
        std::fs::File::open(p).expect("png"),
    ));
    let mut r = dec.read_info().expect("png header");
    let mut buf = vec![0; r.output_buffer_size().expect("png size")];
    let info = r.next_frame(&mut buf).expect("png frame");
    buf.truncate(info.buffer_size());
    buf
}

fn same_aov(a: &Path, b: &Path, what: &str) {
    let out = motu_ok(&["compare", s(a), s(b), "--max-mismatch", "0"]);
    assert!(out.contains("(0 of "), "{what}: {out}");
}

/// A scripted `motu view` of two frames: its stats, AOV and screenshot.
fn view(
    display: &str,
    pkg: &Path,
    d: &Path,
    tag: &str,
    extra: &[&str],
) -> (serde_json::Value, PathBuf, Vec<u8>) {
    let (png, aov, stats) = (
        d.join(format!("{tag}.png")),
        d.join(format!("{tag}.aov")),
        d.join(format!("{tag}.json")),
    );
    let mut args = vec!["view", s(pkg)];
    args.extend(SIZE);
    args.extend([
        "--frames",
        "2",
        "--screenshot",
        s(&png),
        "--aov",
        s(&aov),
        "--stats",
        s(&stats),
    ]);
    args.extend_from_slice(extra);
    let out = motu_on_display(display, &args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "motu {}:\n{err}", args.join(" "));
    let st = serde_json::from_slice(&std::fs::read(&stats).expect("stats")).expect("json");
    (st, aov, decode_png(&png))
}

#[test]
fn view_hands_a_budget_that_holds_the_scene_to_the_full_build() {
    if !gpu_available() {
        return;
    }
    let Some(x) = xvfb("view_hands_a_budget_that_holds_the_scene_to_the_full_build") else {
        return;
    };
    let t0 = std::time::Instant::now();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let scene = checker_scene(d);
    let pkg = d.join("checker.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    let (rpng, raov) = (d.join("render.png"), d.join("render.aov"));
    let mut args = vec!["render", s(&pkg), "-o", s(&rpng), "--aov", s(&raov)];
    args.extend(SIZE);
    motu_ok(&args);
    let rendered = decode_png(&rpng);

    // The device's budget holds the scene: the full build draws it, textured as the render.
    let (st, aov, png) = view(&x.display, &pkg, d, "stream", &["--stream"]);
    let fit = &st["stream_fit"];
    assert_eq!(fit["full_build"], true, "{st}");
    assert_eq!(st["streaming"], false, "{st}");
    let bound = u(&fit["full_build_upper_bytes"]);
    assert!(bound > 0 && bound <= u(&fit["budget_bytes"]), "{fit}");
    same_aov(&aov, &raov, "the hand-over's AOV vs render");
    assert!(
        png == rendered,
        "the hand-over's frame differs from motu render's PNG"
    );

    // The bound holds the full build: a budget equal to it draws it, within it.
    let b = bound.to_string();
    let (st, aov, _) = view(&x.display, &pkg, d, "at-bound", &["--vram-budget", &b]);
    assert_eq!(st["stream_fit"]["full_build"], true, "{st}");
    assert_eq!(u(&st["stream_fit"]["budget_bytes"]), bound, "{st}");
    assert!(u(&st["vram_used_bytes"]) <= bound, "{st}");
    same_aov(&aov, &raov, "the full build at the bound vs render");

    // A byte less: not the full build; this scene's streaming floor lies below its full build,
    // so the streamer draws it, with the full build's image.
    let less = (bound - 1).to_string();
    let (st, aov, _) = view(&x.display, &pkg, d, "under", &["--vram-budget", &less]);
    assert_eq!(st["stream_fit"]["full_build"], false, "{st}");
    assert_eq!(st["streaming"], true, "{st}");
    assert_eq!(st["detail"]["complete"], true, "{st}");
    assert!(u(&st["vram_used_bytes"]) < bound, "{st}");
    same_aov(&aov, &raov, "the streamer a byte under the bound vs render");

    // `--stream-always`: the streamer even where the budget holds the scene.
    let (st, aov, _) = view(
        &x.display,
        &pkg,
        d,
        "always",
        &["--vram-budget", &b, "--stream-always"],
    );
    assert!(st["stream_fit"].is_null(), "{st}");
    assert_eq!(st["streaming"], true, "{st}");
    assert_eq!(st["detail"]["complete"], true, "{st}");
    same_aov(&aov, &raov, "the streamer vs render");

    // `--stream-always` without streaming is a mistake, said.
    let out = motu_on_display(
        &x.display,
        &["view", s(&pkg), "--frames", "1", "--stream-always"],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--stream-always"),
        "{err}"
    );
    eprintln!(
        "view_hands_a_budget_that_holds_the_scene_to_the_full_build: {:.1} s",
        t0.elapsed().as_secs_f64()
    );
}
