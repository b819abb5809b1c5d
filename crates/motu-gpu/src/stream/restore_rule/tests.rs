//! The restore rule with injected rates: no GPU.

use super::super::store_policy::{HostStorePolicy, MIN_BATCHES};
use super::*;

const MB: u64 = 1 << 20;

fn rate(per_blas_ms: f64, gb_per_s: f64) -> Rate {
    Rate {
        batches: 10,
        per_blas_ms,
        gb_per_s,
    }
}

/// `batches` batches of 10 structures of 1 MB each at `gb_per_s`.
fn feed(fit: &mut CostFit, batches: u32, gb_per_s: f64) {
    let c = Cost {
        per_blas_ms: 0.0,
        gb_per_s,
    };
    for _ in 0..batches {
        fit.add(10, 10 * MB, 10.0 * c.ms(MB));
    }
}

/// The H100's session-50 rates (island 0.63 at 24 GiB): build ~10.7 GB/s, upload and
/// deserialise ~12 GB/s, disk reads ~13 GB/s.
fn h100() -> DeviceRates {
    DeviceRates {
        build: Some(rate(0.0, 10.7)),
        restore: Some(rate(0.0, 12.0)),
        disk_read: Some(rate(0.0, 13.0)),
        store: Some(rate(0.0, 2.4)),
    }
}

#[test]
fn restores_slower_than_builds_are_declined_and_not_written() {
    let rule = RestoreRule::from_file(Ok(h100()));
    let est = StoreEstimator::new(10, rule.prior());
    for bytes in [64 << 10, MB, 256 * MB] {
        // From the directory: 1/13 + 1/12 s per GB against 1/10.7.
        assert!(!rule.restore_pays(&est, bytes, Tier::Disk), "{bytes}");
        assert!(!rule.write_pays(&est, bytes), "{bytes}");
        // From host memory: the upload and deserialise alone beat the build.
        assert!(rule.restore_pays(&est, bytes, Tier::Host), "{bytes}");
    }
}

#[test]
fn restores_faster_than_builds_are_restored_and_written() {
    // lavapipe: CPU builds far slower than copies.
    let rates = DeviceRates {
        build: Some(rate(0.5, 0.05)),
        restore: Some(rate(0.1, 2.0)),
        disk_read: Some(rate(0.05, 1.0)),
        store: Some(rate(0.1, 1.0)),
    };
    let rule = RestoreRule::from_file(Ok(rates));
    let est = StoreEstimator::new(10, rule.prior());
    for bytes in [4 << 10, MB, 64 * MB] {
        assert!(rule.restore_pays(&est, bytes, Tier::Disk), "{bytes}");
        assert!(rule.restore_pays(&est, bytes, Tier::Host), "{bytes}");
        assert!(rule.write_pays(&est, bytes), "{bytes}");
    }
}

#[test]
fn fixed_costs_decide_small_structures() {
    // Equal rates, but each disk read costs 2 ms: restores of small structures do not pay,
    // large ones do (builds 2 GB/s, restores and reads 8 GB/s each).
    let rates = DeviceRates {
        build: Some(rate(0.0, 2.0)),
        restore: Some(rate(0.0, 8.0)),
        disk_read: Some(rate(2.0, 8.0)),
        store: None,
    };
    let rule = RestoreRule::from_file(Ok(rates));
    let est = StoreEstimator::new(10, rule.prior());
    assert!(!rule.restore_pays(&est, MB, Tier::Disk));
    assert!(rule.restore_pays(&est, MB, Tier::Host));
    assert!(rule.restore_pays(&est, 64 * MB, Tier::Disk));
}

#[test]
fn unknown_rates_restore_and_write_so_they_get_measured() {
    // No file (or a bad one), nothing measured: as before the rule.
    for loaded in [
        Err(RatesError::Missing),
        Err(RatesError::Corrupt("test")),
        Err(RatesError::Foreign("another device".into())),
    ] {
        let rule = RestoreRule::from_file(loaded);
        let est = StoreEstimator::new(10, rule.prior());
        assert!(rule.restore_pays(&est, MB, Tier::Disk));
        assert!(rule.restore_pays(&est, MB, Tier::Host));
        assert!(rule.write_pays(&est, MB));
        // And the host tier's priors are the built-in ones.
        assert_eq!(rule.prior(), PRIOR);
    }
    // Build known from the file, restores not yet: still restored.
    let only_build = DeviceRates {
        build: Some(rate(0.0, 100.0)),
        ..DeviceRates::default()
    };
    let rule = RestoreRule::from_file(Ok(only_build));
    let est = StoreEstimator::new(10, rule.prior());
    assert!(rule.restore_pays(&est, MB, Tier::Disk));
}

#[test]
fn this_process_s_fits_replace_the_file_s_rates() {
    // The file says restores pay; this process measures reads far slower than its builds.
    let lavapipe_like = DeviceRates {
        build: Some(rate(0.0, 0.05)),
        restore: Some(rate(0.0, 2.0)),
        disk_read: Some(rate(0.0, 1.0)),
        store: None,
    };
    let mut rule = RestoreRule::from_file(Ok(lavapipe_like));
    let mut est = StoreEstimator::new(10, rule.prior());
    assert!(rule.restore_pays(&est, MB, Tier::Disk));
    feed(&mut est.build, MIN_BATCHES, 10.0);
    feed(&mut est.restore, MIN_BATCHES, 12.0);
    // Two batches of reads: the file's read rate still decides; the third replaces it.
    feed(&mut rule.disk_read, MIN_BATCHES - 1, 0.5);
    assert!(
        !rule.restore_pays(&est, MB, Tier::Disk),
        "build/restore now measured"
    );
    assert!(rule.restore_pays(&est, MB, Tier::Host));
    feed(&mut rule.disk_read, 1, 0.5);
    assert!(!rule.restore_pays(&est, MB, Tier::Disk));
    // What is recorded for the next process: the fits, with their batches; the store rate
    // neither measured nor in the file stays unrecorded.
    let saved = rule.to_save(&est);
    let b = saved.build.unwrap();
    assert_eq!(b.batches, MIN_BATCHES);
    assert!((b.gb_per_s - 10.0).abs() < 1e-6, "{b:?}");
    assert!((saved.disk_read.unwrap().gb_per_s - 0.5).abs() < 1e-6);
    assert_eq!(saved.store, None);
    let mut st = StorePolicyStats::default();
    rule.note_saved();
    rule.add_stats(&mut st);
    assert_eq!((st.rates_file, st.rates_saved), ("loaded", true));
    assert_eq!(st.disk_read_batches, MIN_BATCHES);
    assert!((st.disk_read_gb_per_s - 0.5).abs() < 1e-6);
}

#[test]
fn unmeasured_operations_keep_the_file_s_rates() {
    let rule = RestoreRule::from_file(Ok(h100()));
    let est = StoreEstimator::new(10, rule.prior());
    assert_eq!(rule.to_save(&est), h100());
    // The host tier's store rule starts from them too.
    let p = rule.prior();
    assert_eq!((p.build.gb_per_s, p.restore.gb_per_s), (10.7, 12.0));
}

/// `est` as the fixed-rates renderer makes it (`cache.rs`, `Reuse::new`).
fn fixed_estimator(rule: &RestoreRule) -> StoreEstimator {
    let mut est = StoreEstimator::new(10, PRIOR);
    est.fix_prior(rule.prior());
    est
}

#[test]
fn fixed_rates_decide_whatever_this_process_measures() {
    // Fixed: restores pay (lavapipe-like). Measured: far slower restores and reads, which
    // would decline every restore and write with the rates measured (the test above).
    let fixed = DeviceRates {
        build: Some(rate(0.5, 0.05)),
        restore: Some(rate(0.1, 2.0)),
        disk_read: Some(rate(0.05, 1.0)),
        store: Some(rate(0.1, 1.0)),
    };
    let mut rule = RestoreRule::fixed(fixed);
    let mut est = fixed_estimator(&rule);
    let decide = |rule: &RestoreRule, est: &StoreEstimator| {
        [MB, 64 * MB].map(|bytes| {
            (
                rule.restore_pays(est, bytes, Tier::Disk),
                rule.restore_pays(est, bytes, Tier::Host),
                rule.write_pays(est, bytes),
                est.should_store(bytes, false),
            )
        })
    };
    let before = decide(&rule, &est);
    assert_eq!(before, [(true, true, true, true); 2]);
    feed(&mut est.build, 2 * MIN_BATCHES, 10.0);
    feed(&mut est.restore, 2 * MIN_BATCHES, 0.01);
    feed(&mut est.store, 2 * MIN_BATCHES, 0.01);
    feed(&mut rule.disk_read, 2 * MIN_BATCHES, 0.01);
    assert_eq!(
        decide(&rule, &est),
        before,
        "the fits do not move fixed rates"
    );
    // The same fits decide the other way when measured.
    let mut measured = RestoreRule::from_file(Ok(fixed));
    measured.disk_read = rule.disk_read;
    let mut m_est = StoreEstimator::new(10, measured.prior());
    (m_est.build, m_est.restore, m_est.store) = (est.build, est.restore, est.store);
    assert_eq!(decide(&measured, &m_est), [(false, false, false, false); 2]);
    // Reported as fixed, with the fixed rates; never saved for the next process.
    assert!(rule.is_fixed() && !measured.is_fixed());
    let mut st = est.stats(HostStorePolicy::Measured);
    rule.add_stats(&mut st);
    assert_eq!((st.rates_file, st.rates_saved), ("fixed", false));
    assert_eq!((st.build_gb_per_s, st.restore_gb_per_s), (0.05, 2.0));
    assert_eq!(st.disk_read_gb_per_s, 1.0);
    assert_eq!(
        st.build_batches,
        2 * MIN_BATCHES,
        "fits still made and reported"
    );
}

#[test]
fn fixed_unmeasured_rates_restore_write_and_keep_the_store_prior() {
    let mut rule = RestoreRule::fixed(DeviceRates::default());
    let mut est = fixed_estimator(&rule);
    // Builds measured far slower than the prior's restores: measured, the store rule would
    // store; fixed, its prior (the H100's: restores no faster than builds) stores nothing.
    feed(&mut est.build, 2 * MIN_BATCHES, 0.01);
    feed(&mut est.restore, 2 * MIN_BATCHES, 0.01);
    feed(&mut rule.disk_read, 2 * MIN_BATCHES, 0.01);
    assert!(rule.restore_pays(&est, MB, Tier::Disk));
    assert!(rule.restore_pays(&est, MB, Tier::Host));
    assert!(rule.write_pays(&est, MB));
    assert!(!est.should_store(MB, false));
    assert_eq!(rule.prior(), PRIOR);
}
