use super::*;

#[test]
fn auto_makes_large_tlases_persistent_only_when_they_take_a_small_share_of_the_budget() {
    let gb = 1_000_000_000u64;
    // Island 0.3 on the H200: 9M instances, 1.8 GB persistent.
    let (n, bytes) = (9_000_000, 1_800_000_000);
    assert!(
        auto_persistent(n, bytes, 19_749_285_836),
        "half the full build: 9%"
    );
    assert!(!auto_persistent(n, bytes, 9_874_642_918), "a quarter: 18%");
    // The edge: exactly an eighth.
    assert!(auto_persistent(n, gb, 8 * gb));
    assert!(!auto_persistent(n, gb + 1, 8 * gb));
    // Small scenes stay rebuilt whatever the budget.
    assert!(!auto_persistent(22_000, 1_000, 100 * gb));
    assert!(auto_persistent(AUTO_MIN_INSTANCES, 1_000, 100 * gb));
}

#[test]
fn names_are_the_flag_values() {
    for (m, name) in [
        (TlasUpdate::Auto, "auto"),
        (TlasUpdate::Update, "update"),
        (TlasUpdate::Rebuild, "rebuild"),
    ] {
        assert_eq!(m.name(), name);
    }
}
