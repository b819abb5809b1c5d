use super::*;
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
