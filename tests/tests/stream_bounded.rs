//! Streaming over frames (issue 14 items 5 and 6), defaults only (no generator or import
//! flags): a per-frame build budget with the opt-in coarse fallback shows, counts and then
//! refines what is not resident yet until a still camera's path equals the full build; the
//! budget without the fallback is an error, never a silent wrong image; `motu bench` reports a
//! streaming flight per frame; and a camera path on the default island at a quarter of the
//! report's full-build peak needs at most 1.3 passes per frame after the first, for primary
//! visibility and for the shaded default (shadow and AO rays) alike, exact.

use motu_tests::{
    check_probe_rounds, gpu_island, json_u64 as u, motu, motu_ok, report_peak_and_floor, s,
    shot_cam_pose,
};
use std::path::{Path, PathBuf};

const W: &str = "64";
const H: &str = "36";

/// A camera path holding one pose: the generated island's `shotCam` (its pbrt `LookAt` and
/// fov), so every frame of the path sees the same image.
fn still_path(dir: &Path) -> PathBuf {
    let pose = shot_cam_pose(dir, 0.0);
    let file = serde_json::json!({
        "format": "motu-camera-path", "version": 1,
        "width": W.parse::<u32>().unwrap(), "height": H.parse::<u32>().unwrap(),
        "frames": [pose],
    });
    let p = dir.join("still.json");
    std::fs::write(&p, serde_json::to_string_pretty(&file).unwrap()).unwrap();
    p
}

fn read_json(p: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(p).expect("stats file")).expect("stats JSON")
}

#[test]
fn a_frame_build_budget_shows_the_counted_fallback_and_converges_to_the_full_build() {
    let Some((dir, pkg)) = gpu_island(None) else {
        return;
    };
    let d = dir.path();
    let path = still_path(d);
    let full = d.join("full.aov");
    motu_ok(&[
        "render",
        s(&pkg),
        "-o",
        s(&d.join("full.png")),
        "--backend",
        "pipeline",
        "--camera-path",
        s(&path),
        "--aov",
        s(&full),
    ]);
    let budget = ["--stream-build-budget", "2MiB"];
    let base = |out: &Path, aov: &Path, stats: &Path| -> Vec<String> {
        let mut v: Vec<String> = [
            "render",
            s(&pkg),
            "-o",
            s(out),
            "--backend",
            "pipeline",
            "--stream",
            // No --vram-budget: the device's holds the scene; the streamer is under test.
            "--stream-always",
            "--camera-path",
            s(&path),
            "--frames",
            "16",
            "--aov",
            s(aov),
            "--stats",
            s(stats),
        ]
        .iter()
        .map(|a| a.to_string())
        .collect();
        v.extend(budget.iter().map(|a| a.to_string()));
        v
    };
    // Without the fallback, the first frame stops with unfinished pixels: an error naming the
    // build budget, nothing written.
    let (png, aov, stats) = (d.join("a.png"), d.join("a.aov"), d.join("a.json"));
    let args = base(&png, &aov, &stats);
    let out = motu(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "an unfinished frame exited 0: {err}");
    assert!(
        err.contains("unfinished") && err.contains("build budget"),
        "{err}"
    );
    assert!(
        !png.exists() && !aov.exists(),
        "an unfinished frame was written"
    );

    // With it: loud and counted on the first frames, exact at the end of the path.
    let (png, aov, stats) = (d.join("b.png"), d.join("b.aov"), d.join("b.json"));
    let mut args = base(&png, &aov, &stats);
    args.extend(["--stream-fallback".to_string(), "coarse".to_string()]);
    let out = motu(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("FALLBACK"), "the fallback is loud: {err}");
    let st = read_json(&stats);
    let frames = st["stream"]["frames"].as_array().expect("frames");
    let fallback: Vec<u64> = frames.iter().map(|f| u(&f["fallback_pixels"])).collect();
    let built: Vec<u64> = frames.iter().map(|f| u(&f["built_bytes"])).collect();
    eprintln!("fallback pixels per frame {fallback:?}, bytes built {built:?}");
    assert!(fallback[0] > 0, "{fallback:?}");
    assert_eq!(frames[0]["complete"], false);
    assert_eq!(frames[0]["build_budget_spent"], true);
    assert!(
        fallback.windows(2).all(|w| w[1] <= w[0]),
        "refines frame by frame: {fallback:?}"
    );
    let last = frames.last().expect("a frame");
    assert_eq!(last["complete"], true, "{last}");
    assert_eq!(u(&st["fallback_pixels"]), 0, "{st}");
    assert!(
        u(&st["stream"]["totals"]["fallback_pixels"]) >= fallback[0],
        "{}",
        st["stream"]["totals"]
    );
    let cmp = motu_ok(&["compare", s(&full), s(&aov), "--max-mismatch", "0"]);
    assert!(cmp.contains("(0 of "), "{cmp}");

    // The same flight as a benchmark: per-frame rows and means.
    let bench = motu_ok(&[
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
        "6",
        // No warm-up renderer: on lavapipe each new trace pipeline is a fresh LLVM compile.
        "--warmup",
        "0",
        "--backend",
        "pipeline",
        "--json",
    ]);
    let b: serde_json::Value = serde_json::from_str(&bench).expect("bench JSON");
    let rows = b["per_frame"].as_array().expect("per_frame");
    assert_eq!(rows.len(), 6, "{b}");
    assert_eq!(rows[0]["passes"], frames[0]["passes"], "a cold start: {b}");
    assert_eq!(u(&rows[0]["fallback_pixels"]), fallback[0], "{b}");
    for k in [
        "built_bytes",
        "build_ms",
        "trace_ms",
        "probe_rays",
        "probe_ms",
        "wall_ms",
        "gpu_ms",
        "working_set_bytes",
        "room_bytes",
        "evicted",
        "evicted_bytes",
        "evicted_for_tlas",
        "evicted_on_refusal",
        "tlas_ms",
        "tlas_builds",
        "tlas_updates",
        "first_pass_missed_evicted",
        "first_pass_missed_unprobed",
        "first_pass_missed_probed",
        "prefetched",
        "prefetch_skipped",
        "probe_pass_rows",
        "probe_pass_marks",
    ] {
        assert!(rows.iter().all(|r| r[k].is_number()), "{k}: {b}");
    }
    // A TLAS's time is part of the build's; updates are TLAS builds of persistent TLASes
    // (this island's 22k-instance root is rebuilt under `auto`).
    assert!(
        rows.iter()
            .all(|r| r["tlas_ms"].as_f64() <= r["build_ms"].as_f64()
                && u(&r["tlas_updates"]) <= u(&r["tlas_builds"])),
        "{b}"
    );
    assert_eq!(b["tlas_mode"], "rebuild", "{b}");
    // The causes of a frame's evictions are parts of them.
    assert!(
        rows.iter()
            .all(|r| u(&r["evicted_for_tlas"]) + u(&r["evicted_on_refusal"]) <= u(&r["evicted"])),
        "{b}"
    );
    assert!(b["mean_passes"].as_f64().expect("mean") >= 1.0, "{b}");
    assert!(b["mean_built_bytes"].as_f64().expect("mean") > 0.0, "{b}");
    assert!(b["mean_build_ms"].is_number() && b["mean_wall_ms"].is_number());
    assert!(b["mean_probe_ms"].is_number(), "{b}");
}

/// The default island (`gen island --scale 0.002`, the scene of `stream_floor.rs`; default
/// import) and a quarter of its report's full-build peak at the test size (see
/// [`quarter_budget`]).
fn quarter_budget_island() -> Option<QuarterBudget> {
    quarter_budget(Some("0.002"))
}

/// A streaming test's island and its budgets: the directory (kept alive while the package is
/// used), the package, the report's full-build peak at the test size and a quarter of it.
struct QuarterBudget {
    dir: tempfile::TempDir,
    pkg: PathBuf,
    peak: u64,
    budget: u64,
}

/// `gen island` at `scale` (None: the generator's default), default import, and a quarter of
/// its report's full-build peak at the test size (checked to be above the floor); `None`
/// without a ray-tracing device ([`gpu_island`]).
fn quarter_budget(scale: Option<&str>) -> Option<QuarterBudget> {
    let (dir, pkg) = gpu_island(scale)?;
    let (peak, floor) = report_peak_and_floor(&pkg, W, H);
    let budget = peak / 4;
    assert!(budget >= floor, "a quarter is above the floor ({floor})");
    Some(QuarterBudget {
        dir,
        pkg,
        peak,
        budget,
    })
}

/// Streams the default 30-frame camera path from `palmsCam` (`--frames 30`: a yaw sweep with a
/// dolly) at `budget`; checks what holds for every frame (complete, peak ≤ budget, per-frame
/// passes, bytes and ms reported) and returns the stats.
fn stream_path(pkg: &Path, d: &Path, name: &str, budget: u64, extra: &[&str]) -> serde_json::Value {
    let mut args = vec!["--camera", "palmsCam"];
    args.extend_from_slice(extra);
    stream_path_from(pkg, d, name, budget, &args)
}

/// [`stream_path`] from the scene's own camera unless `extra` names one.
fn stream_path_from(
    pkg: &Path,
    d: &Path,
    name: &str,
    budget: u64,
    extra: &[&str],
) -> serde_json::Value {
    stream_frames(pkg, d, name, budget, 30, extra)
}

/// [`stream_path_from`] over the first `frame_count` frames of the default path.
fn stream_frames(
    pkg: &Path,
    d: &Path,
    name: &str,
    budget: u64,
    frame_count: u32,
    extra: &[&str],
) -> serde_json::Value {
    let stats = d.join(format!("{name}.json"));
    let frames_arg = frame_count.to_string();
    let budget_arg = budget.to_string();
    let png = d.join(format!("{name}.png"));
    let mut args = vec![
        "render",
        s(pkg),
        "-o",
        s(&png),
        "--backend",
        "pipeline",
        "--width",
        W,
        "--height",
        H,
        "--stream",
        // The streamer itself, also "with room" (a budget that holds the whole scene).
        "--stream-always",
        "--vram-budget",
        &budget_arg,
        "--frames",
        &frames_arg,
        "--stats",
        s(&stats),
    ];
    // Paths that evict and return: the passes compared below must not follow this machine's
    // timing through the restore rule.
    args.extend(motu_tests::PINNED_RATES);
    args.extend_from_slice(extra);
    motu_ok(&args);
    let st = read_json(&stats);
    let frames = st["stream"]["frames"].as_array().expect("frames");
    assert_eq!(frames.len(), frame_count as usize);
    for f in frames {
        assert_eq!(f["complete"], true, "{f}");
        assert!(u(&f["vram_peak_bytes"]) <= budget, "{f}");
        for k in ["built_bytes", "bytes_streamed", "build_ms", "trace_ms"] {
            assert!(f[k].is_number(), "{k}: {f}");
        }
        // What the heap holds after the frame: live bytes inside blocks inside the budget.
        let (blocks, in_use) = (u(&f["heap_block_bytes"]), u(&f["heap_in_use_bytes"]));
        assert!(in_use > 0 && in_use <= blocks && blocks <= budget, "{f}");
        // The room for structures: the budget less the skeleton, tables and frame buffers.
        let room = u(&f["room_bytes"]);
        assert!(room > 0 && room < budget && budget - room <= in_use, "{f}");
    }
    let passes: Vec<u64> = frames.iter().map(|f| u(&f["passes"])).collect();
    eprintln!(
        "{name}: budget {budget}: passes {passes:?}, mean after the first {:.3}, most resident \
         {} B, working set / room {:.2} at most, totals {}",
        mean_after_first(&st),
        max_resident(&st),
        frames
            .iter()
            .map(|f| u(&f["working_set_bytes"]) as f64 / u(&f["room_bytes"]) as f64)
            .fold(0.0, f64::max),
        st["stream"]["totals"]
    );
    assert!(
        u(&st["stream"]["totals"]["built_bytes"]) > 0,
        "{}",
        st["stream"]["totals"]
    );
    st
}

/// BLAS bytes the frames after the first built (their own passes and the prefetch for the
/// next frame), beside the full build's compacted BLAS bytes from `motu report`.
fn built_after_first(pkg: &Path, st: &serde_json::Value) -> (u64, u64) {
    let rep: serde_json::Value =
        serde_json::from_str(&motu_ok(&["report", s(pkg), "--json"])).expect("report JSON");
    let full = u(&rep["variants"][0]["cost"]["blas_compacted_bytes"]);
    let built = st["stream"]["frames"]
        .as_array()
        .expect("frames")
        .iter()
        .skip(1)
        .map(|f| u(&f["built_bytes"]))
        .sum();
    (built, full)
}

fn mean_after_first(st: &serde_json::Value) -> f64 {
    st["stream"]["mean_passes_after_first"]
        .as_f64()
        .expect("mean passes")
}

fn max_resident(st: &serde_json::Value) -> u64 {
    st["stream"]["frames"]
        .as_array()
        .expect("frames")
        .iter()
        .map(|f| u(&f["resident_bytes"]))
        .max()
        .unwrap_or(0)
}

/// Issue 14 item 6 for primary visibility (`--view ids`) on the default island: the 30-frame
/// camera path from `palmsCam` at a quarter of the report's full-build peak needs at most 1.3
/// passes per frame after the first (the probe of the next camera and the guard band prefetch,
/// structures kept across frames, exact demand inside proxy clusters), every frame complete
/// and under the budget.
#[test]
fn default_island_camera_path_at_a_quarter_budget_needs_at_most_1_3_passes_per_frame_for_primary_visibility(
) {
    let Some(QuarterBudget {
        dir, pkg, budget, ..
    }) = quarter_budget_island()
    else {
        return;
    };
    let d = dir.path();
    let st = stream_path(&pkg, d, "ids", budget, &["--view", "ids"]);
    let mean = mean_after_first(&st);
    assert!(mean <= 1.3, "mean passes after the first frame: {mean}");
}

/// Issue 14 item 6, shaded, on `gen island` with no flags at all (scale 0.0005): the 30-frame
/// path at a quarter of the report's peak needs at most 1.3 passes per frame after the first
/// (lavapipe: 1.621 before the probe's marks of what rays pass through, 1.07 with them, 1.00
/// with the mark walk).
#[test]
fn unscaled_island_shaded_camera_path_at_a_quarter_needs_at_most_1_3_passes_per_frame() {
    let Some(QuarterBudget {
        dir, pkg, budget, ..
    }) = quarter_budget(None)
    else {
        return;
    };
    let d = dir.path();
    let st = stream_path(&pkg, d, "unscaled-shaded", budget, &[]);
    let mean = mean_after_first(&st);
    assert!(mean <= 1.3, "mean passes after the first frame: {mean}");
    // Structures built ahead are the ones rays meet in front of their hits: marked against
    // the closest hit *so far* (before the mark walk), the 29 frames built 1.11 full builds'
    // worth (lavapipe); with the mark walk 0.05.
    let (built, full) = built_after_first(&pkg, &st);
    assert!(
        built * 2 < full,
        "built {built} B after the first frame; full build {full} B"
    );
}

/// Issue 14 item 6 along a wide view: the default island's own camera (`shotCam`, the whole
/// island in view) at a quarter. Its frames' rays need most of the room (`room_bytes`, the
/// budget less the skeleton, tables and frame buffers; up to 0.87× it here since a pass builds
/// the structures open behind its pixels' nearest only once few pixels are open, up to 1.11×
/// before, 1.6–2× at 160×90), and a frame that needs more than the room is never one pass: the
/// cost is reported per frame. Secondary rays traced ahead of their primary hit (while the
/// primary ray waits on a structure in front of it) save passes: mean after the first frame
/// 2.414 before, 2.241 with them, 2.069 with the open structures built late (lavapipe,
/// pipeline backend). The path is timed with `--bounces 0`: bounce rays are not
/// traced ahead, and the default bounce's rays need more than the room in more frames (2.83
/// passes after the first). One frame on each backend, with the default bounce, equals the
/// full build, AOV and colours.
#[test]
fn default_island_wide_view_at_a_quarter_reports_its_room_and_traces_secondary_rays_ahead() {
    let Some(QuarterBudget {
        dir, pkg, budget, ..
    }) = quarter_budget_island()
    else {
        return;
    };
    let d = dir.path();
    let st = stream_path_from(&pkg, d, "wide", budget, &["--bounces", "0"]);
    let frames = st["stream"]["frames"].as_array().expect("frames");
    // Every frame reports its working set against its room, and most need more than half of
    // it; one that needs more than the room is never one pass.
    let ratio = |f: &serde_json::Value| {
        u(&f["working_set_bytes"]) as f64 / u(&f["room_bytes"]).max(1) as f64
    };
    let most = frames.iter().map(ratio).fold(0.0f64, f64::max);
    assert!(
        most > 0.5,
        "the wide view needs most of the room: {most:.2}"
    );
    for f in frames.iter().filter(|f| ratio(f) > 1.0) {
        assert!(u(&f["passes"]) >= 2, "more than the room in one pass: {f}");
    }
    let mean = mean_after_first(&st);
    assert!(mean <= 2.2, "mean passes after the first frame: {mean}");
    streamed_frame_equals_the_full_build(&pkg, d, "wide", budget, &[]);
}

/// Renders `pkg`'s own camera as a full build, then streamed at `budget` (with `extra`) on
/// both backends; each streamed frame must equal the full build: AOV (0 mismatches) and colours.
fn streamed_frame_equals_the_full_build(
    pkg: &Path,
    d: &Path,
    tag: &str,
    budget: u64,
    extra: &[&str],
) {
    let budget_arg = budget.to_string();
    let full_png = d.join(format!("{tag}-full.png"));
    let full_aov = d.join(format!("{tag}-full.aov"));
    motu_ok(&[
        "render",
        s(pkg),
        "-o",
        s(&full_png),
        "--width",
        W,
        "--height",
        H,
        "--aov",
        s(&full_aov),
    ]);
    for backend in ["pipeline", "query"] {
        let png = d.join(format!("{tag}-{backend}.png"));
        let aov = d.join(format!("{tag}-{backend}.aov"));
        let mut args = vec![
            "render",
            s(pkg),
            "-o",
            s(&png),
            "--backend",
            backend,
            "--width",
            W,
            "--height",
            H,
            "--stream",
            "--vram-budget",
            &budget_arg,
            "--aov",
            s(&aov),
        ];
        args.extend_from_slice(extra);
        motu_ok(&args);
        let cmp = motu_ok(&["compare", s(&full_aov), s(&aov), "--max-mismatch", "0"]);
        assert!(cmp.contains("(0 of "), "{backend}: {cmp}");
        assert!(
            std::fs::read(&png).unwrap() == std::fs::read(&full_png).unwrap(),
            "{backend}: the streamed frame's colours differ from the full build's"
        );
    }
}

/// The palmsCam pose of the generated island, turned by `yaw_deg` about its up vector, as a
/// camera-path pose.
fn palms_pose(d: &Path, yaw_deg: f64) -> serde_json::Value {
    let (_, n) = motu_tests::island_camera(d, "palmsCam");
    let f: Vec<f64> = (0..3).map(|i| n[3 + i] - n[i]).collect();
    let len = f.iter().map(|v| v * v).sum::<f64>().sqrt();
    let f: Vec<f64> = f.iter().map(|v| v / len).collect();
    // Rodrigues about the unit up vector.
    let ul = (n[6] * n[6] + n[7] * n[7] + n[8] * n[8]).sqrt();
    let k = [n[6] / ul, n[7] / ul, n[8] / ul];
    let (sn, cs) = yaw_deg.to_radians().sin_cos();
    let kxf = [
        k[1] * f[2] - k[2] * f[1],
        k[2] * f[0] - k[0] * f[2],
        k[0] * f[1] - k[1] * f[0],
    ];
    let kdf = k[0] * f[0] + k[1] * f[1] + k[2] * f[2];
    let fwd: Vec<f64> = (0..3)
        .map(|i| f[i] * cs + kxf[i] * sn + k[i] * kdf * (1.0 - cs))
        .collect();
    serde_json::json!({ "eye": &n[0..3], "forward": fwd, "up": &n[6..9], "fov_deg": 30.0 })
}

fn write_path(p: &Path, poses: Vec<serde_json::Value>) {
    let file = serde_json::json!({
        "format": "motu-camera-path", "version": 1,
        "width": W.parse::<u32>().unwrap(), "height": H.parse::<u32>().unwrap(),
        "frames": poses,
    });
    std::fs::write(p, serde_json::to_string_pretty(&file).unwrap()).unwrap();
}

/// Issue 14 item 6 for the shaded default (scene lights' shadow rays and one AO ray reaching a
/// fifth of the scene diagonal): the probe of the next camera, and where the budget decides.
/// - With room for the path (the full build's peak as budget, nothing evicted) every frame
///   after the first completes in one pass only with the probe: the guard band sees primary
///   visibility, but shadow and AO rays reach structures the camera never sees, and each move
///   sends them elsewhere. Without the probe (`--stream-probe 0`) such frames take a second
///   pass.
/// - At half and at a quarter of the peak the probed path needs at most 1.3 passes per frame
///   after the first, and a panning path's last frame equals the full build's AOV. At a
///   quarter that takes the boxes inside BLASes (rays through a BLAS's empty space open
///   nothing), the probe's marks of what its rays pass through (kept by the prefetch), and
///   units a 256th of the build (a frame's working set is made of whole units): BENCHMARKS.md,
///   "What rays pass through, and units a 256th of the build".
#[test]
fn default_island_shaded_camera_path_needs_one_pass_per_frame_with_room_and_the_probe_and_is_exact_at_a_quarter(
) {
    let Some(QuarterBudget {
        dir,
        pkg,
        peak,
        budget,
        ..
    }) = quarter_budget_island()
    else {
        return;
    };
    let d = dir.path();
    let roomy = stream_path(&pkg, d, "shaded-roomy", peak, &[]);
    let unprobed = stream_path(
        &pkg,
        d,
        "shaded-roomy-unprobed",
        peak,
        &["--stream-probe", "0"],
    );
    let half = stream_path(&pkg, d, "shaded-half", peak / 2, &[]);
    let quarter = stream_path(&pkg, d, "shaded-quarter", budget, &[]);
    let means = [&roomy, &unprobed, &half, &quarter].map(mean_after_first);
    eprintln!(
        "shaded path, mean passes after the first frame: {:.3} with room ({peak} B), {:.3} \
         with room and no probe, {:.3} at half, {:.3} at a quarter ({budget} B)",
        means[0], means[1], means[2], means[3]
    );
    for (st, probed) in [(&roomy, true), (&unprobed, false)] {
        assert_eq!(
            u(&st["stream"]["totals"]["evicted"]),
            0,
            "with room nothing is evicted"
        );
        // Each frame but the last probes its successor's 64 × 36 pixels (and, in a second
        // round, those left open), or none does.
        if probed {
            check_probe_rounds(st, 2);
        } else {
            let rays: u64 = st["stream"]["frames"]
                .as_array()
                .unwrap()
                .iter()
                .map(|f| u(&f["probe_rays"]) + u(&f["probe_rounds"]))
                .sum();
            assert_eq!(rays, 0, "no probe");
        }
    }
    assert!(means[0] <= 1.05, "with room and the probe: {}", means[0]);
    assert!(means[1] > means[0], "the probe saves passes: {means:?}");
    assert!(means[2] <= 1.3, "at half the peak: {}", means[2]);
    // At a quarter: 2.45 passes before the boxes inside BLASes, 1.59 with them, 1.48 with the
    // probe's marks, 1.00 with units a 256th of the build (lavapipe, query backend).
    assert!(
        u(&quarter["stream"]["totals"]["proxy_boxes"]) > 0,
        "{}",
        quarter["stream"]["totals"]
    );
    assert!(means[3] <= 1.3, "at a quarter: {}", means[3]);
    let (built, full) = built_after_first(&pkg, &quarter);
    assert!(
        built * 2 < full,
        "built {built} B after the first frame; full build {full} B"
    );
    // A panning recorded path (palmsCam turned from +20° back to itself over 12 frames),
    // streamed at the quarter and at half: its last frame equals the full build of that pose.
    let path = d.join("pan.json");
    write_path(
        &path,
        (0..12)
            .map(|i| palms_pose(d, 20.0 * (1.0 - f64::from(i) / 11.0)))
            .collect(),
    );
    let last = d.join("last.json");
    write_path(&last, vec![palms_pose(d, 0.0)]);
    let full = d.join("full.aov");
    motu_ok(&[
        "render",
        s(&pkg),
        "-o",
        s(&d.join("full.png")),
        "--backend",
        "pipeline",
        "--camera-path",
        s(&last),
        "--aov",
        s(&full),
    ]);
    // At half the peak the probe's prefetch makes most frames one pass: those frames too must
    // end in the full build's image.
    for (name, b) in [("pan-quarter", budget), ("pan-half", peak / 2)] {
        let streamed = d.join(format!("{name}.aov"));
        let budget_arg = b.to_string();
        motu_ok(&[
            "render",
            s(&pkg),
            "-o",
            s(&d.join(format!("{name}.png"))),
            "--backend",
            "pipeline",
            "--camera-path",
            s(&path),
            "--stream",
            "--vram-budget",
            &budget_arg,
            "--aov",
            s(&streamed),
        ]);
        motu_ok(&["compare", s(&full), s(&streamed), "--max-mismatch", "0"]);
    }
}

/// Large TLASes split at load time and rebuilt a group at a time (issue 14): the streamer splits
/// every TLAS over `--stream-split-instances` (default a million; the default island's root of
/// 58k instances is under it, so the test asks for 8000) into spatial pieces, as `import
/// --max-instances` would, and rebuilds the pieces one after another, so a rebuild takes one
/// piece's room from resident BLASes, not the whole root's. Along the default island's own
/// camera path at a quarter of its peak: frames rebuild in several groups, the most room a
/// rebuild took is below the unsplit root's (`--stream-split-instances 0`) at the same
/// budget, every frame completes under the budget, and a streamed frame equals the full build
/// pixel for pixel on both backends.
#[test]
fn large_tlases_are_split_at_load_and_rebuilt_piece_by_piece_exactly() {
    let Some(QuarterBudget {
        dir, pkg, budget, ..
    }) = quarter_budget_island()
    else {
        return;
    };
    let d = dir.path();
    // Eight frames of the default path (every frame complete, under the budget: checked there).
    let stream = |split: &str, name: &str| {
        stream_frames(
            &pkg,
            d,
            name,
            budget,
            8,
            &["--stream-split-instances", split],
        )
    };
    let most_transient = |st: &serde_json::Value| -> u64 {
        let frames = st["stream"]["frames"].as_array().expect("frames");
        for f in frames {
            assert!(u(&f["tlas_rebuild_groups"]) <= u(&f["tlas_rebuilt"]), "{f}");
        }
        frames
            .iter()
            .map(|f| u(&f["tlas_rebuild_transient_bytes"]))
            .max()
            .unwrap_or(0)
    };
    let split_st = stream("8000", "split");
    let whole_st = stream("0", "whole");
    let frames = split_st["stream"]["frames"].as_array().expect("frames");
    assert!(
        frames.iter().any(|f| u(&f["tlas_rebuild_groups"]) >= 2),
        "no frame rebuilt the pieces in more than one group: {}",
        split_st["stream"]["totals"]
    );
    let (t_split, t_whole) = (most_transient(&split_st), most_transient(&whole_st));
    eprintln!("rebuild transient: split {t_split} B, whole {t_whole} B");
    assert!(
        t_split > 0 && t_split < t_whole,
        "a piece-by-piece rebuild took {t_split} B, the whole root's {t_whole} B"
    );
    // The path's first frame is the scene's camera: the full build's image.
    streamed_frame_equals_the_full_build(
        &pkg,
        d,
        "split",
        budget,
        &["--stream-split-instances", "8000"],
    );
}
