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
