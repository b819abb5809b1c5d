//! Issue 14 acceptance on lavapipe (validation on via MOTU_VALIDATION=1), defaults only (no
//! generator or import flags): carried hits make every budget at or above the report's
//! streaming floor complete with the full build's AOV (0 mismatches, peak ≤ budget, exit 0);
//! a budget below the floor is refused naming it; a frame that runs out of passes is an error.

use motu_tests::{
    gen_island, gpu_available, json_u64 as u, motu, motu_json, motu_ok, peak_and_floor,
    report_json, s,
};
use std::path::Path;
use std::time::Instant;

const W: &str = "96";
const H: &str = "64";

/// (full-build peak, streaming floor) as `motu report` prints them for a W×H image.
fn report(pkg: &Path) -> (u64, u64) {
    let r = report_json(pkg, W, H);
    let (peak, floor) = peak_and_floor(&r);
    assert_eq!(
        floor,
        u(&r["streaming"]["floor"]["min_resident_bytes"]),
        "{}",
        r["streaming"]
    );
    // On a device the report sizes persistent TLASes (`--stream-tlas update`) by its
    // queries; these scenes' roots (tens of thousands of instances) stay rebuilt under auto.
    // Roots of tens of thousands of instances: none over the streaming split's cap.
    assert!(
        r["streaming"]
            .get("stream_split")
            .is_some_and(|v| v.is_null()),
        "{}",
        r["streaming"]
    );
    let p = &r["streaming"]["persistent_tlas"];
    assert!(u(&p["tlases"]) >= 1 && u(&p["bytes"]) > 0, "{p}");
    assert!(p["auto_min_budget_bytes"].is_null(), "{p}");
    let text = motu_ok(&["report", s(pkg), "--width", W, "--height", H]);
    assert!(
        text.contains("persistent TLASes (--stream-tlas update)")
            && text.contains("auto rebuilds them"),
        "{text}"
    );
    eprintln!("report: full-build peak {peak} bytes, streaming floor {floor} bytes");
    (peak, floor)
}

fn render_args<'a>(pkg: &'a Path, png: &'a Path, aov: &'a Path, backend: &'a str) -> Vec<&'a str> {
    vec![
        "render",
        s(pkg),
        "-o",
        s(png),
        "--backend",
        backend,
        "--width",
        W,
        "--height",
        H,
        "--aov",
        s(aov),
    ]
}

/// Streams at `budget` and checks the result equals `full_aov` exactly, under the budget.
/// Returns the frame's passes.
fn stream_matches(pkg: &Path, dir: &Path, full_aov: &Path, budget: u64, backend: &str) -> u64 {
    u(
        &stream_matches_with(pkg, dir, full_aov, budget, backend, &[])["stream"]["frames"][0]
            ["passes"],
    )
}

/// [`stream_matches`] with more render flags; returns the stats.
fn stream_matches_with(
    pkg: &Path,
    dir: &Path,
    full_aov: &Path,
    budget: u64,
    backend: &str,
    extra: &[&str],
) -> serde_json::Value {
    let t0 = Instant::now();
    let tag = format!("{backend}-{budget}-{}", extra.join(""));
    let png = dir.join(format!("{tag}.png"));
    let aov = dir.join(format!("{tag}.aov"));
    let stats = dir.join(format!("{tag}.json"));
    let b = budget.to_string();
    let mut args = render_args(pkg, &png, &aov, backend);
    args.extend(["--stream", "--vram-budget", &b, "--stats", s(&stats)]);
    // Frames of many passes evict and rebuild or restore: the passes compared between budgets
    // must not follow this machine's timing through the restore rule.
    args.extend(motu_tests::PINNED_RATES);
    args.extend(extra);
    motu_ok(&args);
    let st: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
    let frame = &st["stream"]["frames"][0];
    assert_eq!(frame["complete"], true, "{frame}");
    // Below the full build's bound: streamed, not handed to the full build.
    assert_eq!(
        st["stream_fit"]["full_build"], false,
        "{}",
        st["stream_fit"]
    );
    assert!(u(&st["vram_peak_bytes"]) <= budget, "{st}");
    let out = motu_ok(&["compare", s(full_aov), s(&aov), "--max-mismatch", "0"]);
    assert!(out.contains("(0 of "), "{out}");
    eprintln!(
        "{backend} at {budget} bytes: {} passes, {} BLAS built, {} evicted, peak {}; {:.1} s",
        frame["passes"],
        frame["blas_built"],
        frame["evicted"],
        frame["vram_peak_bytes"],
        t0.elapsed().as_secs_f64()
    );
    st
}

#[test]
fn default_island_streams_at_fractions_of_its_full_build_and_at_the_floor() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pkg = gen_island(dir.path(), None);
    let (peak, floor) = report(&pkg);
    let full_aov = dir.path().join("full.aov");
    let full_png = dir.path().join("full.png");
    motu_ok(&render_args(&pkg, &full_png, &full_aov, "query"));
    // 1.05× the floor and the fractions of the full build on the query backend; the pipeline
    // backend (same GLSL core, several times slower per pass on lavapipe: ~60 passes at the
    // floor took 6 minutes) at a quarter.
    let at_floor = floor + floor / 20;
    let mut passes = vec![(
        "1.05× floor",
        stream_matches(&pkg, dir.path(), &full_aov, at_floor, "query"),
    )];
    stream_matches(&pkg, dir.path(), &full_aov, peak / 4, "pipeline");
    // The floor no longer grows with the instance count (proxy boxes are clustered, streamed
    // TLASes hold only resident instances) and the default partition bound keeps the largest
    // structure a small share of the build: a tenth of the full build is above the floor.
    for (name, budget) in [("50%", peak / 2), ("25%", peak / 4), ("10%", peak / 10)] {
        assert!(
            budget >= floor,
            "{name} of the full build ({budget} bytes) is below the floor ({floor} bytes)"
        );
        passes.push((
            name,
            stream_matches(&pkg, dir.path(), &full_aov, budget, "query"),
        ));
    }
    // Passes grow as the budget shrinks (reported per frame in --stats).
    eprintln!("passes: {passes:?}");
    assert!(passes[0].1 > 1, "{passes:?}");
    assert!(passes[passes.len() - 1].1 >= passes[1].1, "{passes:?}");
    // Persistent TLASes forced at the floor, which is sized for rebuilt ones: they do not
    // leave room for the frame (at this floor the root's takes about half the budget), so they
    // give way, the TLASes are rebuilt and the frame is still exact.
    let st = stream_matches_with(
        &pkg,
        dir.path(),
        &full_aov,
        at_floor,
        "query",
        // Meshes in VRAM on any device (host meshes leave the persistent TLASes room).
        &["--stream-tlas", "update", "--stream-mesh-memory", "device"],
    );
    let totals = &st["stream"]["totals"];
    if totals["host_memory_counted"] == true {
        assert_eq!(totals["persistent_dropped"], true, "{totals}");
        assert_eq!(totals["tlas_mode"], "rebuild", "{totals}");
    } else {
        // A discrete GPU keeps the persistent TLASes' records in host memory outside the
        // budget, and then they may fit at this floor: the drop is not forced (still exact).
        eprintln!(
            "persistent TLASes at the floor with host memory apart: dropped {}",
            totals["persistent_dropped"]
        );
    }
    // By default (`auto`) this scene's TLAS (22k instances) is rebuilt at any budget.
    let st = stream_matches_with(&pkg, dir.path(), &full_aov, peak / 2, "query", &[]);
    assert_eq!(
        st["stream"]["totals"]["tlas_mode"], "rebuild",
        "{}",
        st["stream"]["totals"]
    );
}

fn below_floor_is_refused(pkg: &Path, dir: &Path, budget: u64, floor: u64) -> String {
    let png = dir.join("refused.png");
    let aov = dir.join("refused.aov");
    let b = budget.to_string();
    let mut args = render_args(pkg, &png, &aov, "query");
    args.extend(["--stream", "--vram-budget", &b]);
    let out = motu(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("below the streaming floor") && err.contains(&floor.to_string()),
        "the refusal names the floor ({floor}): {err}"
    );
    assert!(!png.exists() && !aov.exists(), "nothing written");
    err.into_owned()
}

/// A small scene whose streaming floor is above its full build's peak (buddha-fractal: one
/// 3 MB BLAS, 25k instances): a budget between the two is refused for `--stream`, with the
/// hint that the full build fits, and the full build renders under it.
#[test]
fn a_floor_over_the_full_build_says_render_without_stream() {
    let Some(scene) = motu_tests::shared_scene("buddha-fractal/buddha-fractal.pbrt") else {
        return;
    };
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("buddha.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    let (peak, floor) = report(&pkg);
    assert!(
        peak < floor,
        "precondition: peak {peak} below floor {floor}"
    );
    let err = below_floor_is_refused(&pkg, dir.path(), peak, floor);
    assert!(err.contains("render without --stream"), "{err}");
    let png = dir.path().join("full.png");
    let aov = dir.path().join("full.aov");
    let b = peak.to_string();
    let mut args = render_args(&pkg, &png, &aov, "query");
    args.extend(["--vram-budget", &b]);
    motu_ok(&args);
}

#[test]
fn below_the_floor_is_refused_and_an_unfinished_frame_is_an_error() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pkg = gen_island(dir.path(), None);
    let (peak, floor) = report(&pkg);
    let err = below_floor_is_refused(&pkg, dir.path(), floor - floor / 50, floor);
    assert!(
        !err.contains("without --stream"),
        "the island's full build does not fit under its floor: {err}"
    );

    // Pass cap 1 (a hidden testing option): pass 1 meets empty instances, so pixels are left.
    let budget = peak.max(floor + floor / 20).to_string();
    let png = dir.path().join("capped.png");
    let aov = dir.path().join("capped.aov");
    let mut args = render_args(&pkg, &png, &aov, "query");
    args.extend([
        "--stream",
        // The budget may hold the whole scene: the streamer's pass cap is under test.
        "--stream-always",
        "--vram-budget",
        &budget,
        "--stream-max-passes",
        "1",
    ]);
    let out = motu(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success(),
        "an unfinished frame exits non-zero: {err}"
    );
    assert!(
        err.contains("pixels unfinished after 1 passes"),
        "names the count: {err}"
    );
    assert!(!png.exists() && !aov.exists(), "nothing written");
    // Opted in: written, with a loud counted warning.
    args.push("--allow-incomplete");
    let out = motu(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("UNFINISHED"), "{err}");
    assert!(png.exists() && aov.exists());
}

/// Renders `pkg` in full and streamed at a quarter of the report's full-build peak: the same
/// AOV, under the budget.
fn quarter_of_the_full_build_matches(pkg: &Path, dir: &Path) {
    let (peak, floor) = report(pkg);
    let budget = peak / 4;
    assert!(
        budget >= floor,
        "25% ({budget} bytes) is below the floor ({floor})"
    );
    let full_aov = dir.join("full.aov");
    motu_ok(&render_args(pkg, &dir.join("full.png"), &full_aov, "query"));
    let passes = stream_matches(pkg, dir, &full_aov, budget, "query");
    assert!(passes > 1, "a quarter of the build streams in passes");
}

/// One mesh of 2M triangles (a default `gen lod-grid` mesh of that size, one copy, default
/// import: the partitioner cuts it into bounded BLASes) at a quarter of its full build.
#[test]
fn one_two_million_triangle_mesh_streams_at_a_quarter_of_its_full_build() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let gen = dir.path().join("mesh");
    motu_ok(&[
        "gen",
        "lod-grid",
        "--triangles",
        "2000000",
        "--grid",
        "1x1",
        "-o",
        s(&gen),
    ]);
    let pkg = dir.path().join("mesh.motu");
    motu_ok(&["import", s(&gen.join("scene.pbrt")), "-o", s(&pkg)]);
    let info = motu_json(&["info", s(&pkg), "--json"]);
    assert!(
        u(&info["unique_triangles"]) >= 1_900_000,
        "one mesh of about 2M triangles: {info}"
    );
    quarter_of_the_full_build_matches(&pkg, dir.path());
}

/// bmw-m6 (written by others, default import) at a quarter of its full build.
#[test]
fn bmw_m6_streams_at_a_quarter_of_its_full_build() {
    if !gpu_available() {
        return;
    }
    let Some(scene) = motu_tests::shared_scene("bmw-m6/bmw-m6.pbrt") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("bmw.motu");
    motu_ok(&["import", s(&scene), "-o", s(&pkg)]);
    quarter_of_the_full_build_matches(&pkg, dir.path());
}

/// A streamed render traces a sample's secondary rays in windows of 8 (`shade.glsl`,
/// `trace_stream.*`): a window's rays wait on their builds in the same pass and its clear rays
/// add their terms in ray order once all are done. With 12 AO rays (two windows) at a quarter
/// of the full build, on both backends, the streamed colour image is the full build's byte for
/// byte, and the frame needs several passes (so windows do span passes).
#[test]
fn streamed_secondary_windows_give_the_full_builds_colours() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pkg = gen_island(dir.path(), None);
    let (peak, _) = report(&pkg);
    let budget = (peak / 4).to_string();
    let mut backends = vec!["pipeline"];
    if motu_tests::has_ray_query() {
        backends.push("query");
    }
    for b in backends {
        let full_png = dir.path().join(format!("full-{b}.png"));
        let full_aov = dir.path().join(format!("full-{b}.aov"));
        let mut args = render_args(&pkg, &full_png, &full_aov, b);
        args.extend(["--ao-samples", "12", "--camera", "beachCam"]);
        motu_ok(&args);
        let png = dir.path().join(format!("stream-{b}.png"));
        let aov = dir.path().join(format!("stream-{b}.aov"));
        let stats = dir.path().join(format!("stream-{b}.json"));
        let mut args = render_args(&pkg, &png, &aov, b);
        args.extend([
            "--ao-samples",
            "12",
            "--camera",
            "beachCam",
            "--stream",
            "--vram-budget",
            &budget,
            "--stats",
            s(&stats),
        ]);
        motu_ok(&args);
        let st: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&stats).expect("stats")).expect("json");
        let frame = &st["stream"]["frames"][0];
        assert_eq!(frame["complete"], true, "{frame}");
        assert!(u(&frame["passes"]) > 1, "{frame}");
        let out = motu_ok(&["compare", s(&full_aov), s(&aov), "--max-mismatch", "0"]);
        assert!(out.contains("(0 of "), "{out}");
        let full = std::fs::read(&full_png).expect("full png");
        let streamed = std::fs::read(&png).expect("streamed png");
        assert!(
            full == streamed,
            "{b}: the streamed image equals the full build's"
        );
    }
}

/// The floor holds for a hierarchy split at load time (`--stream-split-instances`): a budget
/// below it is refused naming the split hierarchy's floor, and 1.05× that floor renders the
/// default island's frame exactly, its root split into pieces of at most 4000 instances.
#[test]
fn a_split_hierarchys_floor_is_honest() {
    if !gpu_available() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let pkg = gen_island(dir.path(), None);
    let full_aov = dir.path().join("full.aov");
    let full_png = dir.path().join("full.png");
    motu_ok(&render_args(&pkg, &full_png, &full_aov, "query"));
    let split = ["--stream-split-instances", "4000"];
    let (png, aov) = (dir.path().join("r.png"), dir.path().join("r.aov"));
    let mut args = render_args(&pkg, &png, &aov, "query");
    args.extend(["--stream", "--vram-budget", "1MiB"]);
    args.extend(split);
    let out = motu(&args);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("below the streaming floor"),
        "{err}"
    );
    // "... below the streaming floor of 12.3 MiB (12345678 bytes) for ..."
    let floor: u64 = err
        .split("below the streaming floor of ")
        .nth(1)
        .and_then(|r| r.split(" bytes)").next())
        .and_then(|r| r.rsplit('(').next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("the refusal names the floor in bytes: {err}"));
    let st = stream_matches_with(
        &pkg,
        dir.path(),
        &full_aov,
        floor + floor / 20,
        "query",
        &split,
    );
    let f = &st["stream"]["frames"][0];
    assert!(u(&f["tlas_rebuild_groups"]) >= 1, "{f}");
}
