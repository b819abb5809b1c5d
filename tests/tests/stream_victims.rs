//! Session 48: victims go least often used first. One-sample bounce rays meet a different part
//! of the scene's fringe each frame; evicting least recently seen first threw out a BLAS met
//! every second or third frame just before it returned (`rebuilt_blases`: built before,
//! evicted, built again), while the room could hold the often met part of the fringe. The
//! default now ranks victims by the frames of the last 16 that used them, least recently seen
//! first among equals; `--stream-victims-by-recency` keeps the old rule for comparison.

use motu_tests::PathShape;
use motu_tests::{gpu_island, json_u64 as u, motu_ok, report_peak_and_floor, s, streamed_path};
use std::path::{Path, PathBuf};

const SHAPE: PathShape = PathShape {
    width: "96",
    height: "54",
    frames: "8",
};

/// The default camera's path (96×54, 8 frames, the CLI's bounce, no structure cache) streamed
/// under `budget` bytes with `extra` flags: the statistics and the AOV.
fn path(
    pkg: &Path,
    dir: &Path,
    name: &str,
    budget: u64,
    extra: &[&str],
) -> (serde_json::Value, PathBuf) {
    let mut args = vec!["--no-as-cache", "--bounces", "1"];
    args.extend(extra);
    streamed_path(pkg, dir, name, budget, "pipeline", SHAPE, &args, &[])
}

/// Sum over the frames after the first of statistic `k`.
fn after_first(st: &serde_json::Value, k: &str) -> u64 {
    let frames = st["stream"]["frames"].as_array().expect("frames");
    frames.iter().skip(1).map(|f| u(&f[k])).sum()
}

/// Island 0.002 at a third of its full build, where the frames' working set about fits the room (like
/// the H100's quarter of island 0.3). Measured (lavapipe, the same path, frames after the
/// first): see BENCHMARKS.md session 48. The image is the full build's either way.
#[test]
fn victims_least_often_used_first_rebuild_fewer_blases() {
    let Some((dir, pkg)) = gpu_island(Some("0.002")) else {
        return;
    };
    let (peak, floor) = report_peak_and_floor(&pkg, SHAPE.width, SHAPE.height);
    let budget = peak / 3;
    assert!(budget >= floor, "a third of the peak is above the floor");
    let (_, reference) = path(&pkg, dir.path(), "everything", peak * 2, &[]);
    let (old, old_aov) = path(
        &pkg,
        dir.path(),
        "recency",
        budget,
        &["--stream-victims-by-recency"],
    );
    let (new, new_aov) = path(&pkg, dir.path(), "frequency", budget, &[]);
    for (name, st) in [("recency", &old), ("frequency", &new)] {
        eprintln!(
            "{name}: rebuilt {}, built {} bytes, evicted {}, passes after the first {}",
            after_first(st, "rebuilt_blases"),
            after_first(st, "built_bytes"),
            after_first(st, "evicted"),
            st["stream"]["mean_passes_after_first"],
        );
        assert_eq!(st["stream"]["totals"]["incomplete_frames"], 0, "{st}");
    }
    let (rebuilt_old, rebuilt_new) = (
        after_first(&old, "rebuilt_blases"),
        after_first(&new, "rebuilt_blases"),
    );
    assert!(
        rebuilt_new * 4 <= rebuilt_old * 3,
        "least often used first rebuilds at most 3/4 of what least recently seen first \
         does: {rebuilt_new} vs {rebuilt_old}"
    );
    motu_ok(&["compare", s(&reference), s(&old_aov), "--max-mismatch", "0"]);
    motu_ok(&["compare", s(&reference), s(&new_aov), "--max-mismatch", "0"]);
}
