use super::{reusable, with_headroom};
use crate::stream::{DEFAULT_TLAS_HEADROOM, MAX_TLAS_HEADROOM};

/// The old structure takes the new one when it fits with at most an eighth of the capacity to
/// spare: never a larger one, never one that would leave more than that slack held.
#[test]
fn storage_is_reused_within_an_eighth_of_its_capacity() {
    let cap = 800u64;
    assert!(reusable(cap, cap), "the same size");
    assert!(reusable(cap, cap - cap / 8), "an eighth to spare");
    assert!(
        !reusable(cap, cap - cap / 8 - 1),
        "more than an eighth to spare"
    );
    assert!(!reusable(cap, cap + 1), "larger than the capacity");
    assert!(!reusable(cap, 0), "nothing to build");
    assert!(reusable(0, 0));
}

/// A fresh structure with headroom takes its own need again and a need grown by less than the
/// headroom; it stays in 256-byte steps; headroom is capped so that the need it was made for
/// is still [`reusable`].
#[test]
fn headroom_lets_a_grown_piece_reuse_its_storage() {
    let need = 110_000_128u64; // a multiple of 256
    let cap = with_headroom(need, DEFAULT_TLAS_HEADROOM);
    assert_eq!(cap % 256, 0);
    assert!(cap >= need + need / 16, "{cap}");
    assert!(reusable(cap, need), "its own need");
    assert!(reusable(cap, need + need / 20), "grown by 5%");
    assert!(!reusable(cap, need + need / 10), "grown by 10%");
    assert!(!reusable(with_headroom(need, 0.0), need + 1), "no headroom");
    assert_eq!(with_headroom(need, 0.0), need.div_ceil(256) * 256);
    // The cap: a huge headroom is clamped, and the need is still reusable.
    let most = with_headroom(need, 10.0);
    assert_eq!(most, with_headroom(need, MAX_TLAS_HEADROOM));
    assert!(reusable(most, need), "{most}");
    assert_eq!(with_headroom(u64::MAX, DEFAULT_TLAS_HEADROOM) % 256, 0);
}
