//! Issue 45.6 (notes/flight.md D2, D3): the viewer's flying mode on a whole-frame clock
//! (`--stream-frame-ms`). A clock of a microsecond is out of time in every frame, so each frame
//! builds only the one BLAS it must (and rebuilds only the stale TLAS piece it must): counts,
//! not times, on any device. Its open pixels stay on the counted fallback, no frame with open
//! pixels is complete, and a camera at rest still settles to the exact image.

use motu_tests::{json_u64 as u, QuarterFlight};

#[test]
fn a_frame_clock_out_of_time_builds_one_blas_a_frame_and_the_camera_settles_at_rest() {
    let Some(flight) = QuarterFlight::new() else {
        return;
    };
    let (frames, still) = (6usize, 8usize);
    let b = flight.bench(&[
        "--stream-frame-ms",
        "0.001",
        "--frames",
        &frames.to_string(),
        "--still-frames",
        &still.to_string(),
    ]);
    // The clock replaces the viewer's 30 ms build budget, which is not added.
    assert_eq!(b["frame_ms"], 0.001, "{b}");
    assert_eq!(b["frame_build_ms"], 0.0, "{b}");
    let rows = b["per_frame"].as_array().expect("per_frame");
    assert_eq!(rows.len(), frames + still, "{b}");
    // (passes, complete, blas_built, fallback pixels, incomplete pixels) a frame.
    let summary: Vec<(u64, bool, u64, u64, u64)> = rows
        .iter()
        .map(|r| {
            (
                u(&r["passes"]),
                r["complete"] == true,
                u(&r["blas_built"]),
                u(&r["fallback_pixels"]),
                u(&r["incomplete_pixels"]),
            )
        })
        .collect();
    eprintln!("(passes, complete, blas_built, fallback, incomplete) per frame: {summary:?}");
    // Moving, and at rest until the camera settles (two incomplete frames at the pose the
    // still frames repeat, the path's last one included): one pass, at most one BLAS, every
    // open pixel on the fallback and none complete with one open.
    let settles_at = frames - 1
        + summary[frames - 1..]
            .iter()
            .scan(0, |incomplete, f| {
                let clocked = *incomplete < 2;
                *incomplete += u32::from(!f.1);
                Some(clocked)
            })
            .take_while(|&c| c)
            .count();
    for f in &summary[..settles_at] {
        assert_eq!(f.0, 1, "{summary:?}");
        assert!(f.2 <= 1, "more than one BLAS on the clock: {summary:?}");
        assert_eq!(f.3, f.4, "{summary:?}");
        assert!(!f.1 || f.4 == 0, "{summary:?}");
    }
    // The cold first frames cannot finish with one BLAS each.
    assert!(!summary[0].1 && summary[0].3 > 0, "{summary:?}");
    // At rest the camera settles: complete within a few still frames, and stays so.
    let rest = &summary[frames - 1..];
    let first = rest
        .iter()
        .position(|f| f.1)
        .expect("a still frame completes");
    assert!(rest[first..].iter().all(|f| f.1 && f.3 == 0), "{summary:?}");
    let k = u(&b["still_frames_to_complete"]);
    assert!((1..=still as u64).contains(&k), "{b}");
}
