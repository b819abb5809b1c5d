use super::*;

#[test]
fn block_size_fills_budget_within_count_cap() {
    // issue 6 acceptance setting: 64 MiB budget, 8 allocations.
    assert_eq!(standard_block_size_bytes(64 * MIB, 8, 2 * GIB), 8 * MIB);
    // a real card: 8 GiB, 4096 allocations -> the 256 MiB ceiling.
    assert_eq!(standard_block_size_bytes(8 * GIB, 4096, 4 * GIB), 256 * MIB);
    // a huge budget with a tiny cap forces bigger blocks, capped by the allocation size.
    assert_eq!(standard_block_size_bytes(64 * GIB, 4, 2 * GIB), 2 * GIB);
    // a small budget: the 1 MiB floor, but never beyond the budget.
    assert_eq!(standard_block_size_bytes(4 * MIB, 4096, GIB), MIB);
    assert_eq!(standard_block_size_bytes(100_000, 4096, GIB), 100_000);
    for (budget, count) in [
        (64 * MIB, 8u32),
        (100 * MIB, 7),
        (3 * GIB, 16),
        (10 * GIB, 4096),
    ] {
        let block = standard_block_size_bytes(budget, count, 2 * GIB);
        assert!(block <= budget);
        // count blocks of that size cover the budget unless the allocation size caps it
        assert!(u64::from(count) * block >= budget || block == 2 * GIB);
    }
}

#[test]
fn effective_budget_takes_smaller_bound() {
    let margin = SafetyMargin::default();
    assert_eq!(effective_budget_bytes(None, None, margin), None);
    assert_eq!(effective_budget_bytes(Some(GIB), None, margin), Some(GIB));
    // 8 GiB available: 5 % margin (409.6 MiB) beats the 64 MiB minimum.
    let device = effective_budget_bytes(None, Some(8 * GIB), margin);
    assert_eq!(device, Some(8 * GIB - 8 * GIB / 20));
    assert_eq!(
        effective_budget_bytes(Some(GIB), Some(8 * GIB), margin),
        Some(GIB)
    );
    assert_eq!(
        effective_budget_bytes(Some(16 * GIB), Some(8 * GIB), margin),
        device
    );
    // small heaps keep at least the minimum margin, and never go negative.
    assert_eq!(
        effective_budget_bytes(None, Some(512 * MIB), margin),
        Some(448 * MIB)
    );
    assert_eq!(effective_budget_bytes(None, Some(MIB), margin), Some(0));
}

#[test]
fn lowered_limits_never_raise() {
    let device = AllocLimits::with_budget(8 * GIB);
    let test = AllocLimits {
        max_allocation_count: 8,
        max_allocation_size_bytes: u64::MAX,
        budget_bytes: 64 * MIB,
        host_visible_budget_bytes: u64::MAX,
    };
    let lowered = device.lowered_to(test);
    assert_eq!(lowered.max_allocation_count, 8);
    assert_eq!(
        lowered.max_allocation_size_bytes,
        device.max_allocation_size_bytes
    );
    assert_eq!(lowered.budget_bytes, 64 * MIB);
    assert_eq!(
        lowered.host_visible_budget_bytes,
        device.host_visible_budget_bytes
    );
}
