use super::*;
use crate::stream::topology::ClustersSource;
use motu_trace::testutil::{srt, uv_sphere, HierarchyBuilder};

/// A root of many instances of two BLASes: clusters with members.
fn scene() -> motu_trace::testutil::OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let mat = b.material([0.5, 0.5, 0.5]);
    let big = b.mesh(0, 0, mat, uv_sphere(8));
    let small = b.mesh(1, 0, mat, uv_sphere(5));
    let a = b.triangle_blas(&[big]);
    let c = b.triangle_blas(&[small]);
    let insts: Vec<_> = (0..300)
        .map(|i| {
            let (x, z) = ((i % 20) as f32 * 3.0, (i / 20) as f32 * 3.0);
            (srt(1.0, 0.0, [x, 0.0, z]), if i % 3 == 0 { c } else { a })
        })
        .collect();
    let root = b.tlas(&insts);
    b.finish(root)
}

#[test]
fn a_plan_round_trips_and_refuses_another_view() {
    let h = scene();
    let view = h.view();
    let plan = StreamPlan::new(&view);
    assert!(plan.clusters.iter().map(Vec::len).sum::<usize>() > 0);
    let blob = encode(&plan);
    let back = decode(&blob, &view).expect("decodes");
    assert_eq!(back.instances, plan.instances);
    assert_eq!(back.clusters.len(), plan.clusters.len());
    for (a, b) in back.clusters.iter().zip(&plan.clusters) {
        assert_eq!(a.len(), b.len());
        for (x, y) in a.iter().zip(b) {
            assert_eq!(
                (x.blas, x.bounds, &x.members, x.member_first),
                (y.blas, y.bounds, &y.members, y.member_first)
            );
        }
    }
    // Cut short, trailing bytes, another header, another view: refused.
    assert!(decode(&blob[..blob.len() - 1], &view).is_none());
    let mut long = blob.to_vec();
    long.push(0);
    assert!(decode(&long, &view).is_none());
    let mut other = blob.to_vec();
    other[0] ^= 1;
    assert!(decode(&other, &view).is_none());
    let mut fewer = view;
    fewer.instances = &view.instances[..view.instances.len() - 1];
    assert!(decode(&blob, &fewer).is_none());
    // The key covers the tables: another instance table, another key.
    assert_ne!(plan_key(&view, b"pkg"), plan_key(&fewer, b"pkg"));
    assert_ne!(plan_key(&view, b"pkg"), plan_key(&view, b"other"));
}

/// A cluster's BLAS, bounds and members.
type Comparable = (u32, [f32; 6], Vec<u32>);

/// The clusters of two plans, comparable.
fn clusters_of(plan: &StreamPlan) -> Vec<Vec<Comparable>> {
    plan.clusters
        .iter()
        .map(|t| {
            t.iter()
                .map(|c| (c.blas, c.bounds, c.members.clone()))
                .collect()
        })
        .collect()
}

/// The package's section for `view` (as `motu import` writes it).
fn section(view: &HierarchyView<'_>) -> Vec<u8> {
    use motu_compile::proxy_clusters::{all_clusters, encode_section, StoredProxyClusters};
    encode_section(&StoredProxyClusters::new(view, &all_clusters(view)))
}

#[test]
fn a_stored_table_is_used_where_it_matches_and_made_again_where_not() {
    let h = scene();
    let view = h.view();
    let made = StreamPlan::new(&view);
    let bytes = section(&view);
    let stored = StreamPlan::load(&view, Some(&bytes), None);
    assert_eq!(stored.source(), ClustersSource::Package);
    assert_eq!(stored.stale_tlases(), 0);
    assert_eq!(clusters_of(&stored), clusters_of(&made));

    // The view changed since the table was made (an instance moved): that TLAS is stale and
    // made again, so the plan is the new view's.
    let mut instances = view.instances.to_vec();
    instances[7].tlas_from_blas[3] += 40.0;
    let moved = HierarchyView {
        instances: &instances,
        ..view
    };
    let again = StreamPlan::load(&moved, Some(&bytes), None);
    assert_eq!(again.source(), ClustersSource::Computed);
    assert_eq!(again.stale_tlases(), 1);
    assert_eq!(clusters_of(&again), clusters_of(&StreamPlan::new(&moved)));
    assert_ne!(clusters_of(&again), clusters_of(&made));

    // Damaged, or made for another shape: not used, made.
    let mut damaged = bytes.clone();
    damaged.truncate(bytes.len() - 3);
    // One instance fewer (a valid view of another shape).
    let mut tlases = view.tlases.to_vec();
    let last = view.instances.len() - 1;
    assert_eq!(
        tlases[view.root_tlas as usize].instance_range().end,
        last + 1
    );
    tlases[view.root_tlas as usize].instance_count -= 1;
    let fewer = HierarchyView {
        tlases: &tlases,
        instances: &view.instances[..last],
        ..view
    };
    for (v, b) in [(view, &damaged[..]), (fewer, &bytes[..])] {
        let p = StreamPlan::load(&v, Some(b), None);
        assert_eq!(p.source(), ClustersSource::Computed);
        assert_eq!(p.stale_tlases(), 0);
        assert_eq!(clusters_of(&p), clusters_of(&StreamPlan::new(&v)));
    }
}
