use super::*;

/// Root → element 0's PI → TLAS A (3 instances); element 1's PI → TLAS B (2 instances).
/// Keeping element 0 keeps A's records and the new root's, and empties B's and its PI's.
#[test]
fn root_subset_keeps_only_the_records_its_root_reaches() {
    let tri = BlasRecord {
        kind: BLAS_TRIANGLES,
        ..Default::default()
    };
    let pi_blas = |item_base| BlasRecord {
        kind: BLAS_AABBS,
        item_base,
        item_count: 1,
        ..Default::default()
    };
    let blases = [tri, pi_blas(0), pi_blas(1)];
    let inst = |blas, element| InstanceRecord {
        tlas_from_blas: IDENTITY_3X4,
        blas,
        element,
        ..Default::default()
    };
    let instances = [
        inst(1, 0),
        inst(2, 1),
        inst(0, NONE_U32),
        inst(0, NONE_U32),
        inst(0, NONE_U32),
        inst(0, NONE_U32),
        inst(0, NONE_U32),
    ];
    let tlas = |instance_base, instance_count| TlasRecord {
        instance_base,
        instance_count,
        ..Default::default()
    };
    let tlases = [tlas(0, 2), tlas(2, 3), tlas(5, 2)];
    let pi = |target| PiRecord {
        kind: PI_TLAS,
        target,
        ..Default::default()
    };
    let pis = [pi(1), pi(2)];
    let base = HierarchyView {
        root_tlas: 0,
        tlases: &tlases,
        instances: &instances,
        blases: &blases,
        pis: &pis,
        ..Default::default()
    };
    base.check_references().expect("valid base");
    let sub = RootSubset::new(&base, |e| e == 0).expect("subset");
    let v = sub.view(&base);
    v.check_references().expect("valid subset");
    assert_eq!((sub.kept, sub.dropped), (1, 1));
    // The new root's one placement and TLAS A's three: nothing of B or the old root.
    assert_eq!(v.instances.len(), 4);
    assert_eq!(v.pis.len(), 1);
    assert_eq!(v.pis[0].target, 1);
    assert_eq!(v.tlases[2].instance_count, 0, "TLAS B is empty");
    assert_eq!(v.tlases[0].instance_count, 0, "the old root is empty");
    assert_eq!(v.blases[2].item_count, 0, "element 1's PI BLAS is empty");
    let (reach_tlas, reach_blas) = v.reachable();
    assert_eq!(reach_tlas, vec![false, true, false, true]);
    assert_eq!(reach_blas, vec![true, true, false]);
}
