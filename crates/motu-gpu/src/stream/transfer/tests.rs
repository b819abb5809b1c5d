use super::*;

#[test]
fn kept_buffers_take_a_few_sizes_within_the_cap() {
    assert_eq!(kept_size_bytes(1), TRANSFER_MIN_BYTES);
    assert_eq!(
        kept_size_bytes(TRANSFER_MIN_BYTES + 1),
        2 * TRANSFER_MIN_BYTES
    );
    assert_eq!(kept_size_bytes(100 * MIB), 128 * MIB);
    assert_eq!(kept_size_bytes(TRANSFER_CAP_BYTES), TRANSFER_CAP_BYTES);
}

#[test]
fn staged_runs_fill_the_staging_buffer_and_send_larger_blobs_direct() {
    // Blobs at 0 (100), 256 (50), 512 (300: larger than the cap), 1024 (10), 1280 (20).
    let offsets = [0, 256, 512, 1024, 1280];
    let sizes = [100, 50, 300, 10, 20];
    let runs = staged_runs(&offsets, &sizes, 306);
    let got: Vec<_> = runs
        .iter()
        .map(|r| (r.blobs.clone(), r.start_bytes, r.len_bytes, r.staged))
        .collect();
    assert_eq!(
        got,
        vec![
            (0..2, 0, 306, true),
            (2..3, 512, 300, true),
            (3..5, 1024, 276, true),
        ]
    );
    let runs = staged_runs(&offsets, &sizes, 299);
    assert_eq!(runs[1].blobs, 1..2);
    assert_eq!((runs[2].blobs.clone(), runs[2].staged), (2..3, false));
    assert_eq!(runs.iter().map(|r| r.blobs.len()).sum::<usize>(), 5);
    assert!(staged_runs(&[], &[], 10).is_empty());
}

#[test]
fn the_staging_buffer_is_a_128th_of_the_budget_and_a_32nd_of_the_room() {
    let gib = 1024 * MIB;
    assert_eq!(staging_bytes(8 * gib, 6 * gib), Some(STAGING_MAX_BYTES));
    assert_eq!(staging_bytes(64 * gib, 60 * gib), Some(STAGING_MAX_BYTES));
    assert_eq!(staging_bytes(512 * MIB, 400 * MIB), Some(4 * MIB));
    assert_eq!(staging_bytes(512 * MIB, 64 * MIB), Some(2 * MIB));
    // At the floor (little room) and under small budgets: direct.
    assert_eq!(staging_bytes(8 * gib, 16 * MIB), None);
    assert_eq!(staging_bytes(64 * MIB, 60 * MIB), None);
}
