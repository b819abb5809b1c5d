//! Issue 45 item 1: a pass's build step builds the structures open behind its pixels' nearest
//! ones only once few pixels are open (at most a 16th of the image): a cold frame's first pass
//! builds only what its rays wait for first, the passes that finish the frame build both. The
//! image is the streamer's with room for everything, on both backends.

use motu_tests::{
    gpu_island, json_u64 as u, motu_ok, report_peak_and_floor, s, streamed_path, PathShape,
};

const SHAPE: PathShape = PathShape {
    width: "64",
    height: "36",
    frames: "1",
};

#[test]
fn a_cold_frame_builds_what_lies_behind_the_nearest_only_once_few_pixels_are_open() {
    let Some((dir, pkg)) = gpu_island(None) else {
        return;
    };
    let d = dir.path();
    let (peak, _floor) = report_peak_and_floor(&pkg, SHAPE.width, SHAPE.height);
    let pixels = 64 * 36;
    for backend in ["pipeline", "query"] {
        let run = |name: &str, budget: u64| {
            streamed_path(
                &pkg,
                d,
                &format!("{name}-{backend}"),
                budget,
                backend,
                SHAPE,
                &[],
                &[],
            )
        };
        let (_, full) = run("everything", peak * 2);
        let (st, aov) = run("half", peak / 2);
        motu_ok(&["compare", s(&full), s(&aov), "--max-mismatch", "0"]);
        let frame = &st["stream"]["frames"][0];
        assert_eq!(frame["complete"], true, "{frame}");
        let log = frame["pass_log"].as_array().expect("pass_log");
        // Pass 1 of a cold frame leaves most pixels open: it builds only what they wait for
        // first, though it saw structures open behind those.
        let first = &log[0];
        assert!(u(&first["open_pixels"]) * 16 > pixels, "{first}");
        assert!(
            u(&first["later"]) > 0,
            "open structures behind the nearest: {first}"
        );
        assert_eq!(first["later_deferred"], true, "{first}");
        assert!(
            u(&first["blas_built"]) <= u(&first["needed"]),
            "only the needed structures: {first}"
        );
        // A pass that leaves few pixels open builds the open ones too.
        for p in log {
            let few = u(&p["open_pixels"]) * 16 <= pixels;
            assert_eq!(p["later_deferred"], !few, "{p}");
        }
        eprintln!(
            "{backend}: passes {}, {}",
            log.len(),
            log.iter()
                .map(|p| format!(
                    "{}/{}/{}{}",
                    u(&p["open_pixels"]),
                    u(&p["needed"]),
                    u(&p["later"]),
                    if p["later_deferred"] == true { "d" } else { "" }
                ))
                .collect::<Vec<_>>()
                .join(" ")
        );
    }
}
