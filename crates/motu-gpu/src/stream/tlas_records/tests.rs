use super::*;
use crate::stream::tlas_encode::kept_record;
use motu_abi::{BlasRecord, TlasRecord, BLAS_TRIANGLES};
use motu_abi::{BLAS_AABBS, FLAG_NEEDS_ANY_HIT};

/// The straightforward encoding the in-place one replaces: every resident instance in
/// order, its index in the TLAS as custom index, triangle instances masked.
fn naive(view: &HierarchyView<'_>, addrs: &[u64], t: u32) -> Vec<u8> {
    let mut out = Vec::new();
    for (j, inst) in instances_of(view, t).iter().enumerate() {
        let addr = addrs[inst.blas as usize];
        if addr == 0 {
            continue;
        }
        out.extend_from_slice(&instance_record(view, inst, j as u32, addr));
    }
    out
}

/// BLASes 0 and 2 of triangles, 1 of boxes.
fn three_blases() -> [BlasRecord; 3] {
    [BLAS_TRIANGLES, BLAS_AABBS, BLAS_TRIANGLES].map(|kind| BlasRecord {
        kind,
        ..Default::default()
    })
}

#[test]
fn chunks_encoded_in_place_equal_the_records_in_order_and_empty_tlases_get_one_inactive() {
    // Two TLASes: the second's 50 instances (over three BLASes, one of boxes, one not
    // resident) span several chunks of 3; the first has only non-resident instances.
    let blases = three_blases();
    let addrs = [0x1000u64, 0x2000, 0];
    let mut instances = vec![
        InstanceRecord {
            blas: 2,
            ..Default::default()
        };
        4
    ];
    for j in 0..50u32 {
        let mut m = [0f32; 12];
        m[3] = j as f32;
        instances.push(InstanceRecord {
            tlas_from_blas: m,
            blas: [0, 1, 2, 0, 2][j as usize % 5],
            flags: if j % 7 == 0 { FLAG_NEEDS_ANY_HIT } else { 0 },
            ..Default::default()
        });
    }
    let tlases = [
        TlasRecord {
            instance_base: 0,
            instance_count: 4,
            ..Default::default()
        },
        TlasRecord {
            instance_base: 4,
            instance_count: 50,
            ..Default::default()
        },
    ];
    let view = HierarchyView {
        tlases: &tlases,
        instances: &instances,
        blases: &blases,
        ..Default::default()
    };
    let tail = [7u8; RECORD_BYTES];
    let records = TlasRecords::count(view, &addrs, &[0, 1], &[], 3 * RECORD_BYTES as u64, |t| {
        if t == 1 {
            vec![tail]
        } else {
            Vec::new()
        }
    });
    assert_eq!(records.chunk_instances, 3);
    let expected = naive(&view, &addrs, 1);
    assert_eq!(
        expected.len(),
        30 * RECORD_BYTES,
        "3 of every 5 instances resident"
    );
    assert_eq!(records.record_counts(), vec![1, 31]);
    // The inactive record of the empty TLAS.
    assert_eq!(
        records.tlases[0].tail,
        vec![encode_instance(&super::super::IDENTITY, false, false, 0, 0)]
    );
    // Each chunk encoded into its counted slice, concatenated: the naive encoding.
    let TlasRecordCounts {
        per_chunk: counts,
        tail: t1_tail,
        ..
    } = &records.tlases[1];
    let range = instances_of(&view, 1);
    let mut got = Vec::new();
    for (k, &n) in counts.iter().enumerate() {
        let mut out = vec![0u8; n as usize * RECORD_BYTES];
        let start = k * 3;
        records.encode_chunk(&range[start..(start + 3).min(range.len())], start, &mut out);
        got.extend_from_slice(&out);
    }
    assert_eq!(got, expected);
    assert_eq!(t1_tail, &vec![tail]);
}

#[test]
fn the_gpu_compaction_of_kept_records_writes_the_host_paths_records() {
    // One TLAS over more than two compaction chunks, a third of its BLASes' instances not
    // resident: the shader's rule (motu_abi::tlas_compact::compact_order, kept records with
    // the address patched in) gives the host path's bytes, and the counts place the tail.
    let blases = three_blases();
    let addrs = [0x1000u64, 0, 0x3000];
    let n = 2 * TLAS_COMPACT_CHUNK + 300;
    let instances: Vec<InstanceRecord> = (0..n)
        .map(|j| {
            let mut m = [0f32; 12];
            m[7] = j as f32;
            InstanceRecord {
                tlas_from_blas: m,
                blas: [0, 2, 1, 0, 2, 1, 1][(j as usize * 7 / 5) % 7],
                flags: if j % 3 == 0 { FLAG_NEEDS_ANY_HIT } else { 0 },
                ..Default::default()
            }
        })
        .collect();
    let tlases = [TlasRecord {
        instance_base: 0,
        instance_count: n,
        ..Default::default()
    }];
    let view = HierarchyView {
        tlases: &tlases,
        instances: &instances,
        blases: &blases,
        ..Default::default()
    };
    let kept: Vec<[u8; RECORD_BYTES]> = instances
        .iter()
        .enumerate()
        .map(|(j, inst)| kept_record(&view, inst, j as u32))
        .collect();
    let resident: Vec<bool> = instances
        .iter()
        .map(|i| addrs[i.blas as usize] != 0)
        .collect();
    let mut got = Vec::new();
    for i in motu_abi::tlas_compact::compact_order(&resident) {
        let mut rec = kept[i as usize];
        let blas = u64::from_le_bytes(rec[56..64].try_into().unwrap());
        rec[56..64].copy_from_slice(&addrs[blas as usize].to_le_bytes());
        got.extend_from_slice(&rec);
    }
    let want = naive(&view, &addrs, 0);
    assert!(want.len() > RECORD_BYTES * 1000 && want.len() < n as usize * RECORD_BYTES);
    assert_eq!(got, want);
    // Counted in compaction chunks; the host writes only the tail.
    let tail = [9u8; RECORD_BYTES];
    let records = TlasRecords::count(view, &addrs, &[0], &[true], 1 << 20, |_| vec![tail]);
    assert_eq!(records.tlases[0].per_chunk.len(), 3);
    assert_eq!(records.compacted(), (want.len() / RECORD_BYTES) as u64);
    assert_eq!(records.host_written(), 1);
    let jobs = records.gpu_jobs(&[128]);
    assert_eq!((jobs.len(), jobs[0].first_record), (1, 2));
}
