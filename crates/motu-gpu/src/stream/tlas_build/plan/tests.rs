use super::{cluster_order, residency_key};
use crate::stream::topology::ProxyCluster;

fn cluster(blas: u32) -> ProxyCluster {
    ProxyCluster {
        blas,
        bounds: [0.0; 6],
        members: Vec::new(),
        member_first: 0,
    }
}

/// The pool's key and the order read from its words are the serial definitions': bit i set
/// where cluster i's BLAS is resident, the non-resident clusters then the resident ones, each
/// ascending; across task boundaries and a partial last word.
#[test]
fn key_and_order_match_the_serial_definition() {
    // 3 BLASes, every 3rd or 7th resident; lengths around word and task edges.
    for len in [0usize, 1, 63, 64, 65, 4095, 4096, 4097, 10_001] {
        let clusters: Vec<ProxyCluster> = (0..len)
            .map(|i| cluster((i % 3 + i % 7 / 6 * 3) as u32))
            .collect();
        let addrs = [0u64, 0x1000, 0, 0x2000, 0, 0x3000];
        let resident = |i: usize| addrs[clusters[i].blas as usize] != 0;
        let (key, non_resident) = residency_key(&clusters, &addrs);
        assert_eq!(key.len(), len.div_ceil(64));
        for i in 0..len {
            assert_eq!(
                key[i / 64] >> (i % 64) & 1 != 0,
                resident(i),
                "len {len} bit {i}"
            );
        }
        let ones: u32 = key.iter().map(|w| w.count_ones()).sum();
        assert_eq!(
            ones as usize,
            len - non_resident as usize,
            "no bit past the clusters"
        );
        let want_nr: Vec<u32> = (0..len)
            .filter(|&i| !resident(i))
            .map(|i| i as u32)
            .collect();
        let want_r: Vec<u32> = (0..len)
            .filter(|&i| resident(i))
            .map(|i| i as u32)
            .collect();
        assert_eq!(non_resident as usize, want_nr.len());
        assert_eq!(cluster_order(&key, len, non_resident, false), want_nr);
        let both: Vec<u32> = want_nr.iter().chain(&want_r).copied().collect();
        assert_eq!(cluster_order(&key, len, non_resident, true), both);
    }
}
