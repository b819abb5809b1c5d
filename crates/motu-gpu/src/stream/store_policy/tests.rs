//! The host tier's store rule with injected rates: no GPU.

use super::*;

const MB: u64 = 1 << 20;

/// `batches` batches of `n` structures of `bytes` each at `per_blas_ms` + `gb_per_s`.
fn feed(fit: &mut CostFit, batches: u32, n: u64, bytes: u64, per_blas_ms: f64, gb_per_s: f64) {
    let c = Cost {
        per_blas_ms,
        gb_per_s,
    };
    for _ in 0..batches {
        fit.add(n, n * bytes, n as f64 * c.ms(bytes));
    }
}

/// An estimator that saw 100 BLASes built, 60 returns of 40 of them.
fn with_returns() -> StoreEstimator {
    let mut e = StoreEstimator::new(100, PRIOR);
    for b in 0..100 {
        e.note_made(b);
    }
    for b in 0..40 {
        assert!(e.note_made(b));
    }
    for b in 0..20 {
        assert!(e.note_made(b));
    }
    e
}

#[test]
fn returns_are_counted_per_blas_built_and_per_blas_returned() {
    let e = with_returns();
    assert_eq!(
        (e.built_blases, e.returns, e.returned_blases),
        (100, 60, 40)
    );
    assert!((e.expected_returns(false) - 0.6).abs() < 1e-12);
    assert!((e.expected_returns(true) - 0.5).abs() < 1e-12);
    assert!(e.returned_before(3) && !e.returned_before(50));
}

#[test]
fn restores_slower_than_rebuilds_store_nothing() {
    let mut e = with_returns();
    feed(&mut e.build, 4, 10, MB, 0.0, 3.0);
    feed(&mut e.restore, 4, 10, MB, 0.0, 2.0);
    feed(&mut e.store, 4, 10, MB, 0.0, 50.0);
    for bytes in [4 << 10, MB, 64 * MB, 1 << 30] {
        assert!(!e.should_store(bytes, false), "{bytes} stored");
        assert!(!e.should_store(bytes, true), "{bytes} stored");
    }
}

#[test]
fn restores_much_faster_than_rebuilds_store() {
    let mut e = with_returns();
    feed(&mut e.build, 4, 10, MB, 0.0, 0.05);
    feed(&mut e.restore, 4, 10, MB, 0.0, 1.0);
    feed(&mut e.store, 4, 10, MB, 0.0, 1.0);
    let (build, restore, store) = e.costs();
    assert!((build.gb_per_s - 0.05).abs() < 1e-9, "{build:?}");
    assert!((restore.gb_per_s - 1.0).abs() < 1e-9, "{restore:?}");
    assert!((store.gb_per_s - 1.0).abs() < 1e-9, "{store:?}");
    // 0.6 × (20 − 1) ms per MB against 1 ms per MB.
    for bytes in [4 << 10, MB, 64 * MB] {
        assert!(e.should_store(bytes, false), "{bytes} not stored");
    }
}

#[test]
fn too_few_samples_decide_by_the_prior() {
    let mut e = StoreEstimator::new(100, PRIOR);
    // Two batches each: fewer than MIN_BATCHES, however one-sided.
    feed(&mut e.build, MIN_BATCHES - 1, 10, MB, 0.0, 0.001);
    feed(&mut e.restore, MIN_BATCHES - 1, 10, MB, 0.0, 100.0);
    feed(&mut e.store, MIN_BATCHES - 1, 10, MB, 0.0, 100.0);
    assert_eq!(e.costs(), (PRIOR.build, PRIOR.restore, PRIOR.store));
    assert_eq!(e.expected_returns(false), PRIOR.returns_fresh);
    assert_eq!(e.expected_returns(true), PRIOR.returns_again);
    // The prior (the H100's: restores no faster than builds) stores nothing.
    assert!(!e.should_store(MB, false));
    // One batch more and the measured rates decide.
    feed(&mut e.build, 1, 10, MB, 0.0, 0.001);
    feed(&mut e.restore, 1, 10, MB, 0.0, 100.0);
    feed(&mut e.store, 1, 10, MB, 0.0, 100.0);
    assert!(e.should_store(MB, false));
}

#[test]
fn the_fit_separates_fixed_costs_from_rates() {
    let mut fit = CostFit::default();
    // Batches of different shapes: the fit recovers 0.5 ms a BLAS and 2 GB/s.
    feed(&mut fit, 2, 100, 16 << 10, 0.5, 2.0);
    feed(&mut fit, 2, 4, 64 * MB, 0.5, 2.0);
    let c = fit.cost(PRIOR.build);
    assert!((c.per_blas_ms - 0.5).abs() < 1e-6, "{c:?}");
    assert!((c.gb_per_s - 2.0).abs() < 1e-6, "{c:?}");
    // Batches of one shape fit a rate alone.
    let mut one = CostFit::default();
    feed(&mut one, 3, 10, MB, 0.0, 4.0);
    let c = one.cost(PRIOR.build);
    assert_eq!(c.per_blas_ms, 0.0);
    assert!((c.gb_per_s - 4.0).abs() < 1e-9, "{c:?}");
}

#[test]
fn small_structures_whose_rebuild_is_cheap_are_not_stored() {
    let mut e = with_returns();
    // Builds: no fixed cost, 0.2 GB/s; restores and stores: 1 ms fixed each, 5 GB/s.
    feed(&mut e.build, 2, 100, 16 << 10, 0.0, 0.2);
    feed(&mut e.build, 2, 4, 64 * MB, 0.0, 0.2);
    for fit in [&mut e.restore, &mut e.store] {
        feed(fit, 2, 100, 16 << 10, 1.0, 5.0);
        feed(fit, 2, 4, 64 * MB, 1.0, 5.0);
    }
    assert!(!e.should_store(16 << 10, false));
    assert!(e.should_store(16 * MB, false));
}

#[test]
fn stats_report_the_estimates() {
    let mut e = with_returns();
    feed(&mut e.restore, 3, 10, MB, 0.0, 2.0);
    let s = e.stats(HostStorePolicy::Measured);
    assert_eq!(s.policy, "measured");
    assert_eq!((s.build_batches, s.restore_batches), (0, 3));
    assert_eq!(s.build_gb_per_s, PRIOR.build.gb_per_s);
    assert!((s.restore_gb_per_s - 2.0).abs() < 1e-9);
    assert!((s.restore_mean_gb_per_s - 2.0).abs() < 1e-9);
    assert_eq!(
        (s.built_blases, s.returns, s.returned_blases),
        (100, 60, 40)
    );
}
