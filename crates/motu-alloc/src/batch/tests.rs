use super::*;

fn sizes(scratch: &[u64]) -> Vec<BuildSize> {
    scratch
        .iter()
        .map(|&scratch_bytes| BuildSize {
            result_bytes: scratch_bytes.saturating_mul(2),
            scratch_bytes,
        })
        .collect()
}

fn limits(budget: u64, alignment: u64, max: u64) -> BatchLimits {
    BatchLimits {
        scratch_budget_bytes: budget,
        scratch_alignment_bytes: alignment,
        scratch_pool_max_bytes: max,
        max_batch_result_bytes: None,
    }
}

#[test]
fn groups_under_aligned_budget() {
    // aligned to 128: 128, 256, 128, 384, 128 with a 512 budget
    let plan =
        plan_build_batches(&sizes(&[100, 200, 128, 300, 1]), limits(512, 128, 4096)).unwrap();
    let ranges: Vec<_> = plan.batches.iter().map(|b| b.builds.clone()).collect();
    assert_eq!(ranges, vec![0..3, 3..5]);
    assert_eq!(plan.batches[0].scratch_bytes, 512);
    assert_eq!(plan.batches[1].scratch_bytes, 512);
    assert_eq!(plan.scratch_offsets_bytes, vec![0, 128, 384, 0, 384]);
    assert_eq!(plan.scratch_pool_bytes, 512);
    assert_eq!(plan.batches[0].result_bytes, 856);
    assert!(plan.oversized_builds.is_empty());
}

#[test]
fn oversized_build_runs_alone_or_fails() {
    let plan = plan_build_batches(&sizes(&[10, 10, 1000, 10]), limits(64, 8, 1024)).unwrap();
    let ranges: Vec<_> = plan.batches.iter().map(|b| b.builds.clone()).collect();
    assert_eq!(ranges, vec![0..2, 2..3, 3..4]);
    assert!(plan.batches[1].oversized);
    assert_eq!(plan.oversized_builds, vec![2]);
    assert_eq!(plan.scratch_pool_bytes, 1000);
    assert_eq!(plan.scratch_offsets_bytes, vec![0, 16, 0, 0]);

    let err = plan_build_batches(&sizes(&[10, 2000]), limits(64, 8, 1024)).unwrap_err();
    assert_eq!(
        err,
        BatchError::ScratchTooLarge {
            build_index: 1,
            scratch_bytes: 2000,
            scratch_pool_max_bytes: 1024
        }
    );
    let message = err.to_string();
    assert!(
        message.contains("build 1")
            && message.contains("2000 bytes")
            && message.contains("1024 bytes")
    );
}

#[test]
fn result_cap_closes_batches() {
    let mut batch_limits = limits(1 << 20, 8, 1 << 20);
    batch_limits.max_batch_result_bytes = Some(50);
    // result = 2 * scratch: 20, 20, 20, 60 (over the cap: alone but allowed)
    let plan = plan_build_batches(&sizes(&[10, 10, 10, 30]), batch_limits).unwrap();
    let ranges: Vec<_> = plan.batches.iter().map(|b| b.builds.clone()).collect();
    assert_eq!(ranges, vec![0..2, 2..3, 3..4]);
}

#[test]
fn empty_and_bad_inputs() {
    let plan = plan_build_batches(&[], limits(64, 8, 64)).unwrap();
    assert!(plan.batches.is_empty());
    assert_eq!(plan.scratch_pool_bytes, 0);
    assert_eq!(
        plan_build_batches(&sizes(&[1]), limits(64, 12, 64)),
        Err(BatchError::BadAlignment(12))
    );
    assert_eq!(
        plan_build_batches(&sizes(&[u64::MAX]), limits(64, 8, 64)),
        Err(BatchError::Overflow(0))
    );
}

#[test]
fn every_batch_respects_budget_and_alignment() {
    // a deterministic pseudo-random sweep (xorshift), checked against the contract
    let mut state = 0x9e37_79b9_7f4a_7c15u64;
    for _ in 0..200 {
        let count = (state % 40) as usize;
        let builds: Vec<BuildSize> = (0..count)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                BuildSize {
                    result_bytes: state % 5000,
                    scratch_bytes: state % 3000,
                }
            })
            .collect();
        let batch_limits = limits(2048, 256, 4096);
        let plan = plan_build_batches(&builds, batch_limits).unwrap();
        let mut next = 0;
        for batch in &plan.batches {
            assert_eq!(batch.builds.start, next);
            assert!(!batch.builds.is_empty());
            next = batch.builds.end;
            assert_eq!(
                batch.oversized,
                batch.scratch_bytes > batch_limits.scratch_budget_bytes
            );
            let mut end = 0;
            for index in batch.builds.clone() {
                let offset = plan.scratch_offsets_bytes[index];
                assert_eq!(offset % 256, 0);
                assert!(offset >= end);
                end = offset + builds[index].scratch_bytes;
            }
            assert!(end <= batch.scratch_bytes);
            assert!(batch.scratch_bytes <= plan.scratch_pool_bytes);
        }
        assert_eq!(next, builds.len());
    }
}
