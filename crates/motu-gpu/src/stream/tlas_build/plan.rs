//! The proxies' plan on the host, per TLAS of a rebuild: its clusters' residency key and the
//! order of their boxes ([`super::TlasBuild::plan_proxies`]). A root piece has tens of
//! thousands of clusters and every step rebuilds nearly every piece: the key is made by the
//! pool, the order read from its words.

use rayon::prelude::*;

use crate::stream::topology::ProxyCluster;

/// Key words one task makes (64 clusters a word).
const TASK_WORDS: usize = 64;

/// The residency key of `clusters` (bit `i % 64` of word `i / 64` set where cluster `i`'s BLAS
/// is resident: its address in `addrs` is not 0; bits past the last cluster clear) and how
/// many are not resident.
pub(super) fn residency_key(clusters: &[ProxyCluster], addrs: &[u64]) -> (Vec<u64>, u32) {
    let mut key = vec![0u64; clusters.len().div_ceil(64)];
    let resident: u32 = key
        .par_chunks_mut(TASK_WORDS)
        .zip(clusters.par_chunks(64 * TASK_WORDS))
        .map(|(words, cs)| {
            let mut n = 0;
            for (w, c64) in words.iter_mut().zip(cs.chunks(64)) {
                let mut bits = 0u64;
                for (i, c) in c64.iter().enumerate() {
                    bits |= u64::from(addrs[c.blas as usize] != 0) << i;
                }
                *w = bits;
                n += bits.count_ones();
            }
            n
        })
        .sum();
    (key, clusters.len() as u32 - resident)
}

/// The boxes' order of `len` clusters keyed `key` with `non_resident` clear bits: the
/// non-resident clusters, then (`with_marks`) the resident ones, each in cluster order.
pub(super) fn cluster_order(
    key: &[u64],
    len: usize,
    non_resident: u32,
    with_marks: bool,
) -> Vec<u32> {
    let marks = if with_marks {
        len - non_resident as usize
    } else {
        0
    };
    let mut order = Vec::with_capacity(non_resident as usize + marks);
    push_indices(&mut order, key, len, false);
    if with_marks {
        push_indices(&mut order, key, len, true);
    }
    order
}

/// Appends the indices below `len` whose bit in `key` is `set`, ascending.
fn push_indices(order: &mut Vec<u32>, key: &[u64], len: usize, set: bool) {
    for (w, &word) in key.iter().enumerate() {
        let mut bits = if set { word } else { !word };
        let valid = len - w * 64;
        if valid < 64 {
            // The last word's high bits are no clusters.
            bits &= (1u64 << valid) - 1;
        }
        while bits != 0 {
            order.push((w * 64) as u32 + bits.trailing_zeros());
            bits &= bits - 1;
        }
    }
}

#[cfg(test)]
mod tests;
