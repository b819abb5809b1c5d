//! Issue 45.5: a rebuilt TLAS piece is built into the storage of the structure it replaces
//! when the new one fits it with at most an eighth to spare (`tlas_build/storage.rs`), instead
//! of a fresh allocation for the new one and a free of the old (a dedicated block each at a
//! quarter of island 0.3 on an H100). Along the default island's camera path, its root split
//! into pieces and rebuilt, under a budget that rebuilds pieces every frame: some rebuilds
//! reuse their storage, fewer TLAS structures are allocated than rebuilt, the budget holds and
//! the AOV is the full build's. With the default headroom on fresh storage, fewer old
//! structures are released for having been outgrown than without it (`--stream-tlas-headroom
//! 0`), and the AOV is the same.

use motu_tests::{
    gpu_island, json_u64 as u, motu_ok, pieces_path, report_peak_and_floor, s,
    stream_total as total, PIECES_SHAPE as SHAPE,
};
use std::path::{Path, PathBuf};

/// The default camera's path streamed under `budget` bytes (pieces of 3000 instances,
/// rebuilt, the host's records): the statistics and the AOV.
fn path(pkg: &Path, dir: &Path, name: &str, budget: u64) -> (serde_json::Value, PathBuf) {
    path_with(pkg, dir, name, budget, &[])
}

fn path_with(
    pkg: &Path,
    dir: &Path,
    name: &str,
    budget: u64,
    extra: &[&str],
) -> (serde_json::Value, PathBuf) {
    let mut args = vec!["--stream-tlas-records", "host"];
    args.extend_from_slice(extra);
    pieces_path(pkg, dir, name, budget, &args)
}

#[test]
fn rebuilt_tlas_pieces_reuse_their_storage_and_give_the_full_builds_aov() {
    let Some((dir, pkg)) = gpu_island(None) else {
        return;
    };
    let d = dir.path();
    let (peak, floor) = report_peak_and_floor(&pkg, SHAPE.width, SHAPE.height);
    // The reference frames: the same path with room for everything.
    let (_, full) = path(&pkg, d, "everything", peak * 2);
    let quarter = floor + (peak - floor) / 4;
    let (st, aov) = path(&pkg, d, "quarter", quarter);
    motu_ok(&["compare", s(&full), s(&aov), "--max-mismatch", "0"]);
    let totals = &st["stream"]["totals"];
    let (reused, allocated) = (
        u(&totals["tlas_storage_reused"]),
        u(&totals["tlas_storage_allocated"]),
    );
    let rebuilt = total(&st, "tlas_builds");
    eprintln!(
        "{quarter} bytes (floor {floor}, peak {peak}): {rebuilt} TLAS builds, storage reused \
         {reused}, allocated {allocated}; one submission {}, groups {}",
        total(&st, "tlas_one_submission"),
        total(&st, "tlas_rebuild_groups"),
    );
    assert_eq!(totals["incomplete_frames"], 0, "{totals}");
    assert!(reused > 0, "no rebuild reused its storage: {totals}");
    // The totals are the frames' sums; a rebuild reuses or allocates once it builds (a
    // refused attempt, counted in `tlas_builds`, does neither).
    assert_eq!(reused, total(&st, "tlas_storage_reused"));
    assert_eq!(allocated, total(&st, "tlas_storage_allocated"));
    assert!(reused + allocated <= rebuilt, "{totals}");
    assert!(
        allocated < rebuilt,
        "{allocated} allocated for {rebuilt} rebuilds"
    );
    let vram_peak = u(&st["vram_peak_bytes"]);
    assert!(
        vram_peak <= quarter,
        "peak {vram_peak} over the budget {quarter}"
    );
}

#[test]
fn headroom_lets_grown_pieces_keep_their_storage() {
    let Some((dir, pkg)) = gpu_island(None) else {
        return;
    };
    let d = dir.path();
    let (peak, floor) = report_peak_and_floor(&pkg, SHAPE.width, SHAPE.height);
    let (_, full) = path(&pkg, d, "everything", peak * 2);
    let quarter = floor + (peak - floor) / 4;
    let (exact, exact_aov) = path_with(&pkg, d, "exact", quarter, &["--stream-tlas-headroom", "0"]);
    let (roomy, roomy_aov) = path(&pkg, d, "roomy", quarter);
    for aov in [&exact_aov, &roomy_aov] {
        motu_ok(&["compare", s(&full), s(aov), "--max-mismatch", "0"]);
    }
    let counts = |st: &serde_json::Value| {
        let t = &st["stream"]["totals"];
        assert_eq!(t["incomplete_frames"], 0, "{t}");
        assert!(u(&st["vram_peak_bytes"]) <= quarter, "{t}");
        (
            u(&t["tlas_storage_grew"]),
            u(&t["tlas_storage_allocated"]),
            u(&t["tlas_storage_reused"]),
        )
    };
    let (grew0, allocated0, reused0) = counts(&exact);
    let (grew, allocated, reused) = counts(&roomy);
    eprintln!(
        "headroom 0: grew {grew0}, allocated {allocated0}, reused {reused0}; default: grew \
         {grew}, allocated {allocated}, reused {reused}"
    );
    assert_eq!(grew0, total(&exact, "tlas_storage_grew"));
    assert!(
        grew0 > 0,
        "without headroom some piece outgrows its storage"
    );
    assert!(grew < grew0, "headroom: {grew} outgrown, without {grew0}");
}
