use super::*;
use motu_abi::{InstanceRecord, TlasRecord, NONE_U32};

fn inst(blas: u32, element: u32) -> InstanceRecord {
    InstanceRecord {
        blas,
        element,
        ..Default::default()
    }
}

#[test]
fn counts_pairs_per_tlas_and_round_trips() {
    // TLAS 0: a large one (counted in pieces), TLAS 1: root placements with elements.
    let mut instances: Vec<InstanceRecord> = (0..PIECE_INSTANCES as u32 * 3 + 7)
        .map(|i| inst(i % 5, NONE_U32))
        .collect();
    let big = instances.len() as u32;
    instances.extend([inst(2, 0), inst(2, 1), inst(2, 0), inst(0, 1)]);
    let tlases = [
        TlasRecord {
            instance_base: 0,
            instance_count: big,
            ..Default::default()
        },
        TlasRecord {
            instance_base: big,
            instance_count: 4,
            ..Default::default()
        },
    ];
    let blases = vec![motu_abi::BlasRecord::default(); 5];
    let view = HierarchyView {
        tlases: &tlases,
        instances: &instances,
        blases: &blases,
        ..Default::default()
    };
    let c = BlasCounts::of(&view);
    let naive = |t: usize| {
        let mut m = std::collections::BTreeMap::<(u32, u32), u64>::new();
        for i in &instances[tlases[t].instance_range()] {
            *m.entry((i.blas, i.element)).or_default() += 1;
        }
        m.into_iter()
            .map(|((blas, element), count)| BlasCount {
                blas,
                element,
                count,
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(c.tlas(0), &naive(0)[..]);
    assert_eq!(c.tlas(1), &naive(1)[..]);
    assert_eq!(c.tlas(1).len(), 3);
    assert!(c.fits(&view));
    let bytes = encode_section(&view, &c);
    assert_eq!(decode_section(&bytes, &view), Some(c.clone()));
    // Damaged or foreign tables are not used.
    assert_eq!(decode_section(&bytes[..bytes.len() - 1], &view), None);
    let mut wrong = c.clone();
    wrong.entries[0].count += 1;
    assert!(!wrong.fits(&view));
    assert_eq!(decode_section(&encode_section(&view, &wrong), &view), None);
    let fewer = HierarchyView {
        tlases: &tlases[..1],
        ..view
    };
    assert_eq!(decode_section(&bytes, &fewer), None);
}

/// Counted a batch at a time (small TLASes together, a large one in groups of pieces), the
/// table is the one counted at once, and every batch is announced.
#[test]
fn counted_in_batches_is_the_same_table() {
    let big = PIECE_INSTANCES as u32 * 2 + 3;
    let mut instances: Vec<InstanceRecord> = (0..big).map(|i| inst(i % 7, NONE_U32)).collect();
    let mut tlases = vec![TlasRecord {
        instance_base: 0,
        instance_count: big,
        ..Default::default()
    }];
    for t in 0..10u32 {
        tlases.push(TlasRecord {
            instance_base: instances.len() as u32,
            instance_count: t + 1,
            ..Default::default()
        });
        instances.extend((0..=t).map(|i| inst(i % 3, t % 2)));
    }
    let blases = vec![motu_abi::BlasRecord::default(); 7];
    let view = HierarchyView {
        tlases: &tlases,
        instances: &instances,
        blases: &blases,
        ..Default::default()
    };
    let mut batches = 0;
    let c = BlasCounts::of_then(&view, &mut || batches += 1);
    assert!(batches >= 2, "{batches} batches");
    assert_eq!(c, BlasCounts::of(&view));
    assert!(c.fits(&view));
    assert_eq!(c.tlas(0).len(), 7);
}
