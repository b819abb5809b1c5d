//! Issue 45.6: a viewer's camera at rest reaches the exact image and stays there. One pass a
//! frame (`render_progressive`, the viewer's flying mode) can churn at rest: each frame's build
//! step evicts what the next frame's single pass needs, and the image flickers between the
//! fallback and the exact one without ever completing (the default island at a quarter of its
//! peak, 64×36, 8 MiB of building a frame). After `StreamOptions::settle_after_still_frames` (2)
//! incomplete frames at one camera, the next ones there take passes until complete, without the
//! frame build budget; the frames before stay at one pass, and once complete every later still
//! frame is.

use motu_tests::{json_u64 as u, QuarterFlight};

#[test]
fn a_still_camera_settles_to_the_exact_image_where_one_pass_a_frame_churns() {
    let Some(flight) = QuarterFlight::new() else {
        return;
    };
    let still = 8usize;
    let b = flight.bench(&[
        "--stream-build-budget",
        "8MiB",
        "--frames",
        "4",
        "--still-frames",
        "8",
    ]);
    let rows = b["per_frame"].as_array().expect("per_frame");
    assert_eq!(rows.len(), 4 + still, "{b}");
    let summary: Vec<(u64, bool, u64)> = rows
        .iter()
        .map(|r| {
            (
                u(&r["passes"]),
                r["complete"] == true,
                u(&r["fallback_pixels"]),
            )
        })
        .collect();
    eprintln!("(passes, complete, fallback pixels) per frame: {summary:?}");
    // Moving: one pass a frame.
    assert!(summary[..3].iter().all(|f| f.0 == 1), "{summary:?}");
    // At rest (from the path's last frame, at the pose the still frames repeat): one pass a
    // frame until two were incomplete, then complete within a few frames and from then on,
    // without fallback pixels.
    let rest = &summary[3..];
    let mut incomplete = 0;
    for f in rest {
        if incomplete < 2 {
            assert_eq!(f.0, 1, "{summary:?}");
        }
        incomplete += u64::from(!f.1);
    }
    let first = rest
        .iter()
        .position(|f| f.1)
        .expect("a still frame completes");
    assert!(first <= 4, "{summary:?}");
    assert!(rest[first..].iter().all(|f| f.1 && f.2 == 0), "{summary:?}");
    assert!(
        rest.iter().any(|f| f.0 > 1),
        "settled frames take passes: {summary:?}"
    );
    let k = u(&b["still_frames_to_complete"]);
    assert!((1..=4).contains(&k), "{b}");
}
