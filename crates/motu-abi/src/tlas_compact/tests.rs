use super::*;

#[test]
fn chunk_firsts_are_exclusive_prefix_sums() {
    assert_eq!(chunk_firsts(&[3, 0, 5, 1]), (vec![0, 3, 3, 8], 9));
    assert_eq!(chunk_firsts(&[]), (vec![], 0));
}

#[test]
fn compaction_keeps_instance_order() {
    // Several chunks, a partial last one, runs of residency crossing invocation and chunk
    // boundaries: the output is the resident instances in instance order (the host path's).
    let n = 3 * TLAS_COMPACT_CHUNK as usize + 77;
    let mut state = 0x2545_f491_u32;
    let resident: Vec<bool> = (0..n)
        .map(|i| {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            // Dense, sparse and empty stretches.
            match (i / 700) % 3 {
                0 => state % 4 != 0,
                1 => state % 9 == 0,
                _ => false,
            }
        })
        .collect();
    let want: Vec<u32> = (0..n as u32).filter(|&i| resident[i as usize]).collect();
    assert!(want.len() > 100 && want.len() < n);
    assert_eq!(compact_order(&resident), want);
    assert_eq!(
        compact_order(&vec![true; n]),
        (0..n as u32).collect::<Vec<_>>()
    );
    assert!(compact_order(&vec![false; n]).is_empty());
}

#[test]
fn push_constants_are_48_bytes() {
    // The shader's push block: 4 addresses and 4 words.
    assert_eq!(std::mem::size_of::<TlasCompactPush>(), 48);
}
