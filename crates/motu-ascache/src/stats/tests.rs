use super::*;

#[test]
fn counts_by_reason_and_names() {
    let mut w = WarningCounts::default();
    for (i, &r) in WarningReason::ALL.iter().enumerate() {
        for _ in 0..=i {
            w.count(r);
        }
    }
    for (i, &r) in WarningReason::ALL.iter().enumerate() {
        assert_eq!(w.get(r), i as u64 + 1, "{r}");
    }
    assert_eq!(w.total(), 28);
}
