//! Issue 45 items 4/5: `--stream-probe-paths stop` (opt-in; `through` is the default) ends a
//! probe ray's pixel path where a structure that is not resident lies in front of its
//! resident hit (primary and bounce rays), so a round prefetches only what paths right so far
//! meet. The probe decides what to prefetch, never the image: along the default island's
//! camera path with the default bounce, under an eighth of the full build, the streamed AOV
//! equals the path streamed with room for everything, and the probe still runs its rounds.

use motu_tests::{
    check_probe_rounds, gpu_island, json_u64 as u, motu_ok, report_peak_and_floor, s,
    streamed_path, PathShape,
};

const SHAPE: PathShape = PathShape {
    width: "32",
    height: "18",
    frames: "4",
};

#[test]
fn stopped_probe_paths_give_the_full_builds_aov() {
    let Some((dir, pkg)) = gpu_island(None) else {
        return;
    };
    let d = dir.path();
    let (peak, floor) = report_peak_and_floor(&pkg, SHAPE.width, SHAPE.height);
    let budget = peak / 8;
    assert!(
        budget > floor,
        "an eighth of {peak} is above the floor {floor}"
    );
    let run = |name: &str, budget: u64, extra: &[&str]| {
        streamed_path(&pkg, d, name, budget, "pipeline", SHAPE, extra, &[])
    };
    let (_, full) = run("everything", peak * 2, &[]);
    let (st, aov) = run("stop", budget, &["--stream-probe-paths", "stop"]);
    motu_ok(&["compare", s(&full), s(&aov), "--max-mismatch", "0"]);
    let totals = &st["stream"]["totals"];
    assert_eq!(u(&totals["incomplete_frames"]), 0, "{totals}");
    // Every frame but the last probes the next camera, in at most two open-pixel rounds.
    check_probe_rounds(&st, 2);
    let frames = st["stream"]["frames"].as_array().expect("frames");
    let rays: u64 = frames.iter().map(|f| u(&f["probe_rays"])).sum();
    eprintln!(
        "an eighth ({budget} of {peak} bytes): passes after the first {}, probe rays {rays}",
        st["stream"]["mean_passes_after_first"]
    );
    assert!(rays > 0, "the probe ran");
}
