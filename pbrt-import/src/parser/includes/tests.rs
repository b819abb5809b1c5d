use super::*;

/// The counts over a text of several release windows, with an `Include` across a window's
/// end and another far past it; every byte's pages are released, each window once, in order.
#[test]
fn includes_are_counted_across_windows_and_every_window_is_released() {
    let w = RELEASE_TEXT_BYTES;
    let filler = |n: usize| "# ".repeat(n / 2);
    let mut text = filler(w - 4);
    text.push_str("\nInclude \"a.pbrt\"\n");
    text.push_str(&filler(w + 100));
    text.push_str("\nImport \"a.pbrt\" Include \"b.pbrt\"\n");
    let mut released: Vec<(usize, usize)> = Vec::new();
    let counts = count_includes(text.as_bytes(), |a, b| released.push((a, b)));
    assert_eq!(counts.get(&b"a.pbrt"[..]), Some(&2));
    assert_eq!(counts.get(&b"b.pbrt"[..]), Some(&1));
    assert_eq!(released.first().map(|r| r.0), Some(0));
    assert_eq!(released.last().map(|r| r.1), Some(text.len()));
    assert!(released.windows(2).all(|p| p[0].1 == p[1].0));
}

/// A text that names no include is scanned window by window and released as it goes.
#[test]
fn a_text_without_includes_is_released_window_by_window() {
    let text = "Shape \"sphere\"\n".repeat(3 * RELEASE_TEXT_BYTES / 15 + 7);
    let mut released: Vec<(usize, usize)> = Vec::new();
    assert!(count_includes(text.as_bytes(), |a, b| released.push((a, b))).is_empty());
    assert_eq!(released.len(), text.len().div_ceil(RELEASE_TEXT_BYTES));
    assert_eq!(released.last().map(|r| r.1), Some(text.len()));
}

/// The window grows with the pool's threads between its floor and its cap, in pieces, and
/// stops growing at 8 threads: 64 to 128 MiB at the default 4 MiB pieces.
#[test]
fn the_window_follows_the_threads_up_to_a_cap() {
    let piece = 4 << 20;
    assert_eq!(window_bytes_for(0, piece), 64 << 20);
    assert_eq!(window_bytes_for(2, piece), 64 << 20);
    assert_eq!(window_bytes_for(6, piece), 96 << 20);
    assert_eq!(window_bytes_for(8, piece), 128 << 20);
    for threads in [16, 64, 1 << 20, usize::MAX] {
        assert_eq!(window_bytes_for(threads, piece), 128 << 20, "{threads}");
    }
    assert_eq!(window_bytes_for(64, 100), MAX_WINDOW_PIECES * 100);
    assert_eq!(window_bytes_for(64, 0), MAX_WINDOW_PIECES);
}
