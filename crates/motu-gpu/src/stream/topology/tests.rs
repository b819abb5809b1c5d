use super::*;
use motu_abi::InstanceRecord;

/// Parents and instance counts per BLAS: each TLAS once, in order, however its instances
/// interleave BLASes.
#[test]
fn parents_and_counts_follow_each_tlas_once() {
    let inst = |blas: u32| InstanceRecord {
        blas,
        ..Default::default()
    };
    // TLAS 0: BLAS 0, 1, 0; TLAS 1: BLAS 2; TLAS 2: BLAS 1, 0, 1, 1.
    let instances = [0, 1, 0, 2, 1, 0, 1, 1].map(inst);
    let range = |base: u32, count: u32| TlasRecord {
        instance_base: base,
        instance_count: count,
        ..Default::default()
    };
    let tlases = [range(0, 3), range(3, 1), range(4, 4)];
    let blases = [BlasRecord::default(); 3];
    let view = HierarchyView {
        tlases: &tlases,
        instances: &instances,
        blases: &blases,
        ..Default::default()
    };
    let plan = StreamPlan {
        clusters: vec![Vec::new(); 3],
        instances: instances.len(),
        source: ClustersSource::Computed,
        stale_tlases: 0,
    };
    let (topo, records) = Topology::derive(&view, plan).unwrap();
    assert_eq!(topo.parents(0), &[0, 2]);
    assert_eq!(topo.parents(1), &[0, 2]);
    assert_eq!(topo.parents(2), &[1]);
    assert_eq!(topo.parent_counts, vec![vec![2, 1], vec![1, 3], vec![1]]);
    let mut counts = [0u64; 3];
    topo.add_instance_counts(1, &mut counts);
    assert_eq!(counts, [1, 0, 3]);
    assert_eq!(records.instances.len(), instances.len());
}
