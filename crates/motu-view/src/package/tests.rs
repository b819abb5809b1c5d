use super::*;

fn stream(max_passes: Option<u32>, frames: Option<u32>) -> ViewStreamSettings {
    ViewStreamSettings {
        max_passes,
        frames,
        ..Default::default()
    }
}

#[test]
fn progressive_when_flying_or_one_pass() {
    assert!(stream(None, None).progressive());
    assert!(stream(Some(1), None).progressive());
    assert!(stream(Some(1), Some(5)).progressive());
    assert!(!stream(None, Some(5)).progressive());
    assert!(!stream(Some(4), None).progressive());
}

#[test]
fn flying_without_a_build_bound_builds_an_interactive_frame_time() {
    let o = stream(None, None).options(1 << 30, Some(64));
    assert_eq!(o.budget_bytes, 1 << 30);
    assert_eq!(o.max_allocations, 64);
    assert_eq!(o.frame_build_ms, INTERACTIVE_BUILD_MS);
    assert_eq!(o.max_passes, motu_gpu::StreamOptions::default().max_passes);
    // A given bound wins, and scripted multi-pass frames are not bounded in time.
    let mut given = stream(None, None);
    given.bounds.frame_build_bytes = Some(1 << 20);
    let o = given.options(u64::MAX, None);
    assert_eq!(o.frame_build_ms, 0.0);
    assert_eq!(o.frame_build_bytes, 1 << 20);
    assert_eq!(
        o.max_allocations,
        motu_gpu::StreamOptions::default().max_allocations
    );
    // A frame clock given: it bounds the flying frame, no build budget is added.
    let mut clocked = stream(None, None);
    clocked.bounds.frame_ms = Some(50.0);
    let o = clocked.options(1 << 30, None);
    assert_eq!((o.frame_build_ms, o.frame_ms), (0.0, 50.0));
    assert_eq!(
        stream(Some(3), Some(2)).options(1, None).frame_build_ms,
        0.0
    );
    assert_eq!(stream(Some(3), Some(2)).options(1, None).max_passes, 3);
}
