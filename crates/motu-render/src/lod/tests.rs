use super::*;
use motu_abi::IDENTITY_3X4;
use motu_trace::testutil::{uv_sphere, HierarchyBuilder, OwnedHierarchy, PiTarget};

/// One sphere with two LOD levels behind one selector, placed once (or no LOD at all).
fn scene(with_lod: bool) -> OwnedHierarchy {
    let mut b = HierarchyBuilder::new();
    let levels: Vec<u32> = (0..2)
        .map(|l| {
            let m = b.mesh(0, l, 0, uv_sphere(8 >> l));
            let blas = b.triangle_blas(&[m]);
            b.tlas(&[(IDENTITY_3X4, blas)])
        })
        .collect();
    let root = if with_lod {
        let sel = b.lod_selector(&levels, 0);
        let blas = b.pi_blas(&[(IDENTITY_3X4, PiTarget::LodSelector(sel))]);
        b.tlas(&[(IDENTITY_3X4, blas)])
    } else {
        levels[0]
    };
    b.finish(root)
}

#[test]
fn lod_mode_is_instance_where_the_rule_allows_else_traversal_and_why() {
    let lod = LodParams::default();
    let h = scene(true);
    let c = choose_lod_mode(&h.view(), &lod, LodMode::Instance, false).unwrap();
    assert_eq!((c.mode, c.instance.is_some()), ("instance", true), "{c:?}");
    assert_eq!(c.selector_pis, 1);
    let c = choose_lod_mode(&h.view(), &lod, LodMode::Traversal, false).unwrap();
    assert_eq!((c.mode, c.reason), ("traversal", "--lod-mode traversal"));
    let c = choose_lod_mode(&h.view(), &lod, LodMode::Instance, true).unwrap();
    assert!(
        c.mode == "traversal" && c.reason.contains("--stream"),
        "{c:?}"
    );
    let stochastic = LodParams {
        stochastic: 1,
        ..lod
    };
    let c = choose_lod_mode(&h.view(), &stochastic, LodMode::Instance, false).unwrap();
    assert!(c.reason.contains("--lod-stochastic"), "{c:?}");
    let c = choose_lod_mode(&scene(false).view(), &lod, LodMode::Instance, false).unwrap();
    assert_eq!(
        (c.mode, c.instance.is_none(), c.selector_pis),
        ("none", true, 0)
    );
}
