use super::*;

#[test]
fn the_frame_table_shows_each_frames_working_set_beside_its_room() {
    let mib = 1u64 << 20;
    let rows = vec![serde_json::json!({
        "frame": 3, "passes": 3, "working_set_bytes": 24 * mib, "room_bytes": 13 * mib,
        "built_bytes": 20 * mib, "build_ms": 1.5, "tlas_ms": 0.75, "trace_ms": 2.0,
        "wall_ms": 9.0,
        "fallback_pixels": 0,
    })];
    let t = frame_table(&rows);
    let mut lines = t.lines();
    let head = lines.next().expect("header");
    assert!(head.contains("working set  room"), "{t}");
    let row = lines.next().expect("a row");
    let cells: Vec<&str> = row
        .split("  ")
        .map(str::trim)
        .filter(|c| !c.is_empty())
        .collect();
    assert_eq!(
        &cells[..8],
        &["3", "3", "24.0 MiB", "13.0 MiB", "20.0 MiB", "1.50", "0.75", "2.00"],
        "{t}"
    );
    assert!(head.contains("build ms  TLAS ms  trace ms"), "{t}");
}

fn flight_options(stream_passes: Option<u32>, bounds: StreamBounds) -> FlightOptions {
    FlightOptions {
        package: PathBuf::from("p.motu"),
        camera_path: PathBuf::from("path.json"),
        width: None,
        height: None,
        frames: None,
        warmup: None,
        backend: None,
        stream: true,
        vram_budget: None,
        stream_bounds: bounds,
        shading: Default::default(),
        stream_passes,
        next_camera: NextCamera::Path,
        still_frames: 0,
    }
}

#[test]
fn stream_passes_one_takes_the_viewers_build_budget_unless_one_is_given() {
    let d = motu_gpu::StreamOptions::default();
    // The default: render_frame's pass cap and no build bound, as before.
    let o = opts_with_passes(&flight_options(None, StreamBounds::default()));
    assert_eq!((o.max_passes, o.frame_build_ms), (d.max_passes, 0.0));
    // The viewer's flying mode: one pass and, with no bound given, the viewer's 30 ms.
    let o = opts_with_passes(&flight_options(Some(1), StreamBounds::default()));
    assert_eq!(
        (o.max_passes, o.frame_build_ms),
        (1, motu_render::INTERACTIVE_BUILD_MS)
    );
    // A bound given is kept (bytes alone too: no millisecond bound is added).
    let ms = StreamBounds {
        frame_build_ms: Some(12.5),
        ..Default::default()
    };
    assert_eq!(
        opts_with_passes(&flight_options(Some(1), ms)).frame_build_ms,
        12.5
    );
    let bytes = StreamBounds {
        frame_build_bytes: Some(1 << 20),
        ..Default::default()
    };
    let o = opts_with_passes(&flight_options(Some(1), bytes));
    assert_eq!((o.frame_build_ms, o.frame_build_bytes), (0.0, 1 << 20));
    // A frame clock given: it bounds the frame, no build budget is added.
    let clock = StreamBounds {
        frame_ms: Some(50.0),
        ..Default::default()
    };
    let o = opts_with_passes(&flight_options(Some(1), clock));
    assert_eq!((o.frame_build_ms, o.frame_ms), (0.0, 50.0));
    // More passes than one: render_frame under that cap, no budget added.
    let o = opts_with_passes(&flight_options(Some(3), StreamBounds::default()));
    assert_eq!((o.max_passes, o.frame_build_ms), (3, 0.0));
}
