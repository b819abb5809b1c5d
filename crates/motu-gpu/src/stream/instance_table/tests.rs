use super::*;

fn inst(i: usize) -> InstanceRecord {
    InstanceRecord {
        blas: i as u32,
        element: 7,
        ..Default::default()
    }
}

/// The table as the skeleton used to copy it: per TLAS its view range, then the proxy and
/// marks instances.
fn expected(
    view: &[InstanceRecord],
    pieces: &[(usize, usize, Option<u32>)],
) -> Vec<InstanceRecord> {
    let mut out = Vec::new();
    for &(first, count, proxy) in pieces {
        out.extend_from_slice(&view[first..first + count]);
        if let Some(b) = proxy {
            for id in [b, b + 1] {
                out.push(InstanceRecord {
                    tlas_from_blas: IDENTITY,
                    blas: id,
                    flags: 0,
                    element: motu_abi::NONE_U32,
                    _pad: 0,
                });
            }
        }
    }
    out
}

/// Any range written, from any start and of any length, equals the same range of the table
/// copied whole; pieces without instances, without clusters and with only clusters included.
#[test]
fn any_range_written_equals_the_table_copied_whole() {
    let view: Vec<InstanceRecord> = (0..40).map(inst).collect();
    let pieces = [
        (0, 5, Some(100)),
        (5, 0, None),
        (5, 0, Some(102)),
        (5, 3, None),
        (8, 12, Some(104)),
        (20, 0, None),
        (20, 20, None),
        (40, 0, Some(106)),
    ];
    let mut table = InstanceTable::default();
    let mut bases = Vec::new();
    for &(first, count, proxy) in &pieces {
        bases.push(table.push(first, count, proxy));
    }
    let whole = expected(&view, &pieces);
    assert_eq!(table.len(), whole.len());
    assert_eq!(bases, vec![0, 7, 7, 9, 12, 26, 26, 46]);
    for first in 0..whole.len() {
        for len in 0..=whole.len() - first {
            let mut out = vec![InstanceRecord::default(); len];
            table.write(&view, first, &mut out);
            assert_eq!(
                out,
                whole[first..first + len],
                "records {first}..{}",
                first + len
            );
        }
    }
}

/// The parallel writer, over more records than one task fills, equals the sequential one.
#[test]
fn the_parallel_writer_equals_the_sequential_one() {
    let n = 3 * RECORDS_PER_TASK + 17;
    let view: Vec<InstanceRecord> = (0..n).map(inst).collect();
    let mut pieces = Vec::new();
    let mut at = 0;
    let mut k = 0u32;
    while at < n {
        let count = (1000 + 7919 * k as usize % 5000).min(n - at);
        pieces.push((at, count, (k % 3 != 0).then_some(2 * k)));
        at += count;
        k += 1;
    }
    let mut table = InstanceTable::default();
    for &(first, count, proxy) in &pieces {
        table.push(first, count, proxy);
    }
    let whole = expected(&view, &pieces);
    for first in [0, 1, RECORDS_PER_TASK - 1, 5000] {
        let mut out = vec![InstanceRecord::default(); whole.len() - first];
        table.write_parallel(&view, first, &mut out);
        assert!(out == whole[first..], "from record {first}");
    }
}
