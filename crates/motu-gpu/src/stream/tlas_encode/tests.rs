use super::super::{MARKS_MASK, PI_MASK, PROXY_MASK, TRIANGLE_MASK};
use super::*;

/// The instance masks are written twice (Rust in `stream.rs`, `CULL_MASK_*` in common.glsl):
/// a first walk (bit 0) meets triangles and PIs, never proxies; a proxy walk only proxies; a
/// mark walk PIs and proxies, never triangles; and only probe passes the marks.
#[test]
fn instance_masks_match_the_cull_masks_of_common_glsl() {
    let glsl = include_str!("../../../../../shaders/common.glsl");
    let mask = |name: &str| -> u8 {
        let line = glsl
            .lines()
            .find_map(|l| l.strip_prefix(&format!("#define CULL_MASK_{name} ")))
            .unwrap_or_else(|| panic!("common.glsl has no CULL_MASK_{name}"));
        let hex = line
            .split_whitespace()
            .next()
            .unwrap()
            .trim_end_matches('u');
        u8::from_str_radix(hex.trim_start_matches("0x"), 16).expect("a hex mask")
    };
    let (walk, marks, mark_walk, proxies, probe) = (
        mask("WALK"),
        mask("MARKS"),
        mask("MARK_WALK"),
        mask("PROXIES"),
        mask("PROBE"),
    );
    assert_eq!(TRIANGLE_MASK, walk);
    assert_eq!(MARKS_MASK, marks);
    assert_eq!(PROXY_MASK, mark_walk | proxies);
    assert_eq!(PROXY_MASK & walk, 0, "a first walk would meet the proxies");
    assert_eq!(PI_MASK & proxies, 0, "a proxy walk would meet the PIs");
    assert_ne!(PI_MASK & walk, 0, "a first walk must meet the PIs");
    assert_ne!(PI_MASK & mark_walk, 0, "a mark walk must meet the PIs");
    assert_eq!(TRIANGLE_MASK & (mark_walk | proxies), 0);
    assert_eq!(MARKS_MASK & (walk | mark_walk | proxies), 0);
    assert_eq!(probe, 0xFF);
    // The records carry them: a proxy tail, a marks tail, an absent tail inactive.
    assert_eq!(tail_record(7, false, 1)[51], PROXY_MASK);
    assert_eq!(tail_record(7, true, 1)[51], MARKS_MASK);
    assert_eq!(tail_record(7, false, 0)[51], 0);
}
