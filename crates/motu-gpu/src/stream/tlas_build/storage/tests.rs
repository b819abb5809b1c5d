use super::reusable;

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
