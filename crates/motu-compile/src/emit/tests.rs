//! Each pass on tiny hand-made graphs.

use crate::testutil::{assert_same_placements, builder, compile_ok, grid_mesh, triangle};
use crate::{compile, flatten_compiled, flatten_source, CompileError, CompileOptions, Levels};
use glam::{Mat4, Quat, Vec3};
use motu_abi::{BLAS_AABBS, BLAS_TRIANGLES, NONE_U32, PI_LOD_SELECTOR, PI_TLAS};
use motu_scene::{ElementId, MaterialId, MeshData, PrototypeId, Scene, SceneBuilder, Transform34};

fn t(x: f32, y: f32, z: f32) -> Transform34 {
    Transform34::from_translation(Vec3::new(x, y, z))
}

fn rot(angle: f32, x: f32) -> Transform34 {
    Transform34::from_mat4(Mat4::from_scale_rotation_translation(
        Vec3::new(1.0, 2.0, 0.5),
        Quat::from_rotation_y(angle),
        Vec3::new(x, 1.0, -2.0),
    ))
}

/// A builder holding a `leaf` prototype (one triangle) in the main element, with the default
/// material and that element for the rest of the scene.
fn with_leaf() -> (SceneBuilder, MaterialId, ElementId, PrototypeId) {
    let mut b = builder();
    let (m, main) = (b.default_material(), Scene::MAIN_ELEMENT);
    let leaf = b.add_prototype("leaf", main).unwrap();
    b.add_mesh(leaf, "leaf", m, main, &triangle()).unwrap();
    (b, m, main, leaf)
}

/// leaf (one triangle) ← tree (trunk mesh + 3 leaves) ← root (4 trees + 1 leaf).
fn forest() -> (Scene, PrototypeId, PrototypeId) {
    let (mut b, m, main, leaf) = with_leaf();
    let tree = b.add_prototype("tree", main).unwrap();
    b.add_mesh(tree, "trunk", m, main, &triangle()).unwrap();
    for i in 0..3 {
        b.add_instance(tree, leaf, rot(i as f32, i as f32), main)
            .unwrap();
    }
    for i in 0..4 {
        b.add_instance(b.root(), tree, rot(0.3 * i as f32, 10.0 * i as f32), main)
            .unwrap();
    }
    b.add_instance(b.root(), leaf, t(0.0, 0.0, 5.0), main)
        .unwrap();
    (b.finish().unwrap(), leaf, tree)
}

fn check_flatten(scene: &Scene, opts: &CompileOptions) -> crate::CompiledScene {
    let c = compile_ok(scene, opts);
    assert_same_placements(&flatten_source(scene), &flatten_compiled(&c.view(), 0));
    c
}

fn opts(levels: Levels) -> CompileOptions {
    CompileOptions {
        levels,
        ..Default::default()
    }
}

#[test]
fn ml_puts_plain_geometry_in_instance_lists_and_the_rest_behind_pis() {
    let (scene, _, _) = forest();
    let c = check_flatten(&scene, &opts(Levels::Ml));
    // TLAS(root) and the shared TLAS(tree); G(leaf), G(tree) and A(root).
    assert_eq!(c.tlases.len(), 2);
    assert_eq!(c.root_tlas, 0);
    assert_eq!(c.blases.len(), 3);
    let root = c.tlases[0];
    assert_eq!(root.instance_count, 2, "G(leaf) + A(root)");
    let tree = c.tlases[1];
    assert_eq!(
        tree.instance_count, 4,
        "G(tree) + 3 × G(leaf): an instance list"
    );
    let aabb: Vec<_> = c.blases.iter().filter(|b| b.kind == BLAS_AABBS).collect();
    assert_eq!(aabb.len(), 1);
    assert_eq!(aabb[0].item_count, 4);
    assert!(c.pis.iter().all(|p| p.kind == PI_TLAS && p.target == 1));
    // G(leaf) is shared by the root (level 0) and TLAS(tree) (level 2): level 3.
    let g_leaf = c.instances[root.instance_base as usize].blas as usize;
    assert_eq!(c.blases[g_leaf].kind, BLAS_TRIANGLES);
    assert_eq!(c.blases[g_leaf].level, 3);
    assert_eq!(tree.level, 2);
    assert_eq!(c.report.tlas_levels, 2);
    assert_eq!(
        c.report.flattened_instances,
        scene.stats().flattened_instances
    );
    assert_eq!(c.meshes.len(), 2);
}

#[test]
fn sl_flattens_everything_into_the_root() {
    let (scene, _, _) = forest();
    let c = check_flatten(&scene, &opts(Levels::Sl));
    assert_eq!(c.tlases.len(), 1);
    assert!(c.pis.is_empty());
    // 4 trees × (trunk + 3 leaves) + 1 leaf.
    assert_eq!(c.instances.len(), 17);
    assert_eq!(c.report.tlas_levels, 1);
}

/// root → a → b → c → leaf, two edges per level, no identities: 4 TLAS levels in ML.
fn chain() -> Scene {
    let (mut b, _, main, leaf) = with_leaf();
    let mut child = leaf;
    for name in ["c", "b", "a"] {
        let p = b.add_prototype(name, main).unwrap();
        b.add_instance(p, child, t(1.0, 0.0, 0.0), main).unwrap();
        b.add_instance(p, child, rot(0.5, -3.0), main).unwrap();
        child = p;
    }
    b.add_instance(b.root(), child, t(0.0, 2.0, 0.0), main)
        .unwrap();
    b.add_instance(b.root(), child, t(0.0, -2.0, 0.0), main)
        .unwrap();
    b.finish().unwrap()
}

#[test]
fn levels_n_inlines_the_top_levels_and_keeps_the_bottom() {
    let scene = chain();
    let ml = check_flatten(&scene, &opts(Levels::Ml));
    assert_eq!(ml.report.tlas_levels, 4);
    for n in 1..=5 {
        let c = check_flatten(&scene, &opts(Levels::N(n)));
        assert_eq!(c.report.tlas_levels, n.min(4), "N({n})");
    }
    let n2 = check_flatten(&scene, &opts(Levels::N(2)));
    // The bottom TLAS(c) is kept and shared; a and b are inlined into the root.
    assert_eq!(n2.tlases.len(), 2);
    assert_eq!(n2.pis.len(), 8);
}

#[test]
fn identity_edges_to_single_parent_prototypes_are_collapsed() {
    let (m, main) = (motu_scene::MaterialId(0), Scene::MAIN_ELEMENT);
    let build = |shared: bool| {
        let mut b = builder();
        let el = b.element("isBeach").unwrap();
        let leaf = b.add_prototype("leaf", el).unwrap();
        b.add_mesh(leaf, "leaf", m, main, &triangle()).unwrap();
        let tree = b.add_prototype("tree", el).unwrap();
        b.add_instance(tree, leaf, t(1.0, 0.0, 0.0), el).unwrap();
        b.add_instance(tree, leaf, t(2.0, 0.0, 0.0), el).unwrap();
        let element = b.add_prototype("isBeach", el).unwrap();
        b.add_instance(element, tree, t(0.0, 0.0, 3.0), el).unwrap();
        b.add_instance(element, tree, t(0.0, 0.0, 6.0), el).unwrap();
        b.add_instance(b.root(), element, Transform34::IDENTITY, el)
            .unwrap();
        if shared {
            b.add_instance(b.root(), element, Transform34::IDENTITY, el)
                .unwrap();
        }
        b.finish().unwrap()
    };
    let c = check_flatten(&build(false), &opts(Levels::Ml));
    assert_eq!(c.report.collapsed_prototypes, 1);
    assert_eq!(
        c.tlases.len(),
        2,
        "root (with isBeach inlined) and TLAS(tree)"
    );
    assert_eq!(c.report.tlas_levels, 2);
    let el = c.tlases[0].element;
    assert_ne!(el, NONE_U32, "all root content is from one element");
    assert!(c.instances[c.tlases[0].instance_base as usize..]
        [..c.tlases[0].instance_count as usize]
        .iter()
        .all(|i| i.element == el));
    // Shared by two edges: a PI level again (inlining would duplicate it).
    let shared = check_flatten(&build(true), &opts(Levels::Ml));
    assert_eq!(shared.report.collapsed_prototypes, 0);
    assert_eq!(shared.tlases.len(), 3);
}

#[test]
fn prunes_empty_subtrees_and_drops_degenerate_instances() {
    let (mut b, _, main, leaf) = with_leaf();
    let empty = b.add_prototype("empty", main).unwrap();
    let holder = b.add_prototype("holder", main).unwrap();
    b.add_instance(holder, empty, t(1.0, 0.0, 0.0), main)
        .unwrap();
    b.add_instance(b.root(), holder, t(1.0, 0.0, 0.0), main)
        .unwrap();
    b.add_instance(b.root(), empty, t(2.0, 0.0, 0.0), main)
        .unwrap();
    let mut flat = t(3.0, 0.0, 0.0);
    flat.rows[1][1] = 0.0;
    b.add_instance(b.root(), leaf, flat, main).unwrap();
    b.add_instance(b.root(), leaf, t(4.0, 0.0, 0.0), main)
        .unwrap();
    let scene = b.finish().unwrap();
    let c = check_flatten(&scene, &opts(Levels::Ml));
    assert_eq!(c.report.dropped_degenerate_instances, 1);
    assert_eq!(c.tlases.len(), 1);
    assert_eq!(c.instances.len(), 1);
    assert_eq!(c.blases.len(), 1);
}

fn scattered(n: usize, same_place: bool) -> Scene {
    let (mut b, _, main, leaf) = with_leaf();
    let mut state = 12345u32;
    let mut rnd = || {
        state = state.wrapping_mul(1664525).wrapping_add(1013904223);
        (state >> 8) as f32 / (1u32 << 24) as f32 * 100.0
    };
    for _ in 0..n {
        let at = if same_place {
            t(1.0, 2.0, 3.0)
        } else {
            t(rnd(), rnd(), rnd())
        };
        b.add_instance(b.root(), leaf, at, main).unwrap();
    }
    b.finish().unwrap()
}

#[test]
fn split_10000_instances_under_a_cap_of_1000() {
    for same_place in [false, true] {
        let scene = scattered(10_000, same_place);
        let o = CompileOptions {
            max_instances_per_tlas: 1000,
            ..Default::default()
        };
        let c = check_flatten(&scene, &o);
        assert!(c.tlases.iter().all(|t| t.instance_count <= 1000));
        assert!(c.tlases.len() >= 11, "{}", c.tlases.len());
        assert_eq!(flatten_compiled(&c.view(), 0).len(), 10_000);
        assert_eq!(c.report.split_tlases, 1);
        // SAH pieces: within the cap, a few leaves of which the root keeps what fits.
        let leaves: Vec<_> = c.tlases[1..].iter().map(|t| t.instance_count).collect();
        assert!(leaves.len() <= 140, "{leaves:?}");
        let root = c.tlases[c.root_tlas as usize];
        let kept = c.instances[root.instance_base as usize..][..root.instance_count as usize]
            .iter()
            .filter(|i| c.blases[i.blas as usize].kind == BLAS_TRIANGLES)
            .count();
        // The root is filled up to the cap beside its pieces' AABB instances.
        assert!(kept + leaves.len() >= 500, "root keeps {kept}");
        // The pieces' instances are spatially separated when positions differ.
        if !same_place {
            let vol = |t: &motu_abi::TlasRecord| {
                (0..3)
                    .map(|k| t.bounds_max[k] - t.bounds_min[k])
                    .product::<f32>()
            };
            assert!(c.tlases[1..]
                .iter()
                .all(|t| vol(t) < 0.5 * vol(&c.tlases[0])));
        }
    }
}

#[test]
fn tiny_caps_recurse_and_split_aabb_blases() {
    let scene = scattered(200, false);
    let o = CompileOptions {
        max_instances_per_tlas: 2,
        max_primitives_per_blas: 2,
        ..Default::default()
    };
    let c = check_flatten(&scene, &o);
    assert!(c.report.tlas_levels >= 4, "{:?}", c.report);
    let (forest, _, _) = forest();
    check_flatten(&forest, &o);
    let scratch = CompileOptions {
        max_tlas_scratch_bytes: 3 * 128,
        ..Default::default()
    };
    let c = check_flatten(&scattered(50, false), &scratch);
    assert!(c.tlases.iter().all(|t| t.instance_count <= 3));
}

#[test]
fn invalid_options_are_errors() {
    let scene = scattered(3, false);
    let mut sink = |_: u32, _: &MeshData, _: Option<&[u32]>| Ok(());
    for o in [
        CompileOptions {
            max_instances_per_tlas: 1,
            ..Default::default()
        },
        CompileOptions {
            max_primitives_per_blas: 0,
            ..Default::default()
        },
        CompileOptions {
            levels: Levels::N(0),
            ..Default::default()
        },
    ] {
        assert!(matches!(
            compile(&scene, &o, &mut sink),
            Err(CompileError::InvalidOptions(_))
        ));
    }
}

/// Two elements under the root, each with a tree and a root mesh.
fn two_elements() -> (Scene, motu_scene::ElementId, motu_scene::ElementId) {
    let mut b = builder();
    let m = b.default_material();
    let ea = b.element("a").unwrap();
    let eb = b.element("b").unwrap();
    let leaf = b.add_prototype("leaf", ea).unwrap();
    b.add_mesh(leaf, "leaf", m, ea, &triangle()).unwrap();
    let tree = b.add_prototype("tree", ea).unwrap();
    b.add_instance(tree, leaf, t(1.0, 0.0, 0.0), ea).unwrap();
    b.add_instance(tree, leaf, t(0.0, 1.0, 0.0), ea).unwrap();
    for (i, el) in [ea, eb, ea, eb].into_iter().enumerate() {
        b.add_instance(b.root(), tree, t(5.0 * i as f32, 0.0, 0.0), el)
            .unwrap();
    }
    b.add_mesh(b.root(), "ground-a", m, ea, &triangle())
        .unwrap();
    b.add_mesh(b.root(), "ground-b", m, eb, &triangle())
        .unwrap();
    (b.finish().unwrap(), ea, eb)
}

#[test]
fn root_placements_carry_their_element() {
    let (scene, ea, eb) = two_elements();
    let c = check_flatten(&scene, &opts(Levels::Ml));
    let root = c.tlases[c.root_tlas as usize];
    assert_eq!(root.element, NONE_U32, "mixed");
    let insts = &c.instances[root.instance_base as usize..][..root.instance_count as usize];
    // G(root) is split per element, and A(root) too.
    assert_eq!(insts.len(), 4);
    for el in [ea, eb] {
        assert_eq!(insts.iter().filter(|i| i.element == el.0).count(), 2);
    }
    // Below the root the parent decides.
    let tree = c.tlases[1];
    assert!(c.instances[tree.instance_base as usize..][..2]
        .iter()
        .all(|i| i.element == NONE_U32));
    // Splitting the root keeps every placement's tag (in whichever piece it lands), and a
    // piece of one element says so.
    let tags = |c: &crate::CompiledScene| {
        let mut v: Vec<u32> = c
            .instances
            .iter()
            .map(|i| i.element)
            .filter(|&e| e != NONE_U32)
            .collect();
        v.sort_unstable();
        v
    };
    let sl = |cap| CompileOptions {
        levels: Levels::Sl,
        max_instances_per_tlas: cap,
        ..Default::default()
    };
    let whole = check_flatten(&scene, &sl(crate::DEFAULT_MAX_PER_NODE));
    let c = check_flatten(&scene, &sl(3));
    assert!(c.report.split_tlases >= 1);
    assert_eq!(tags(&c), tags(&whole));
    for piece in &c.tlases[1..] {
        let range = piece.instance_range();
        let insts = &c.instances[range];
        if piece.element != NONE_U32 {
            assert!(insts.iter().all(|i| i.element == piece.element));
        }
    }
}

#[test]
fn split_keeps_huge_instances_in_the_parent_and_pieces_apart() {
    // An ocean-like huge slab under 2000 small boxes scattered in a grid: the slab stays in
    // the root (any piece holding it would span the scene) and the pieces barely overlap.
    let (mut b, m, main, leaf) = with_leaf();
    let slab = b.add_prototype("slab", main).unwrap();
    b.add_mesh(slab, "slab", m, main, &triangle()).unwrap();
    let huge = Transform34::from_mat4(Mat4::from_scale(Vec3::new(200.0, 200.0, 1.0)));
    b.add_instance(b.root(), slab, huge, main).unwrap();
    for i in 0..2000 {
        let (x, y) = ((i % 50) as f32 * 4.0, (i / 50) as f32 * 4.0);
        b.add_instance(b.root(), leaf, t(x, y, 0.5), main).unwrap();
    }
    let scene = b.finish().unwrap();
    let o = CompileOptions {
        levels: Levels::Sl,
        max_instances_per_tlas: 100,
        ..Default::default()
    };
    let c = check_flatten(&scene, &o);
    assert_eq!(flatten_compiled(&c.view(), 0).len(), 2001);
    let root = c.tlases[c.root_tlas as usize];
    let x_extent = |i: &motu_abi::InstanceRecord| {
        let b = crate::tables::instance_bounds(&c.blases, i);
        b.max[0] - b.min[0]
    };
    let root_range = root.instance_range();
    assert!(
        c.instances[root_range.clone()]
            .iter()
            .any(|i| c.blases[i.blas as usize].kind == BLAS_TRIANGLES && x_extent(i) > 100.0),
        "the slab stays in the root"
    );
    for piece in &c.tlases[1..] {
        let range = piece.instance_range();
        assert!(
            c.instances[range].iter().all(|i| x_extent(i) < 10.0),
            "a piece holds the slab"
        );
    }
    // Pieces' footprints (x-y areas) sum to little more than the grid's.
    let pieces: Vec<_> = c.tlases[1..].to_vec();
    assert!(pieces.len() >= 20 && pieces.len() <= 80, "{}", pieces.len());
    let area = |t: &motu_abi::TlasRecord| {
        (t.bounds_max[0] - t.bounds_min[0]) * (t.bounds_max[1] - t.bounds_min[1])
    };
    let sum: f32 = pieces.iter().map(area).sum();
    let grid = 197.0 * 157.0;
    assert!(sum < 1.3 * grid, "pieces overlap: {sum} vs {grid}");
}

#[test]
fn subset_keeps_only_the_selected_elements() {
    let (scene, ea, _) = two_elements();
    let o = CompileOptions {
        subset: Some(vec![ea]),
        ..Default::default()
    };
    let c = compile_ok(&scene, &o);
    let placed = flatten_compiled(&c.view(), 0);
    // Two trees of two leaves, and ground-a.
    assert_eq!(placed.len(), 5);
    assert_eq!(c.report.flattened_instances, 4);
    assert_eq!(c.tlases[c.root_tlas as usize].element, ea.0);
    assert!(c.meshes.iter().all(|m| m.element == ea.0));
}

#[test]
fn node_order_is_depth_first_with_children_contiguous() {
    // root → {x, y} (non-plain, distinct), x → z, y → z: children of root are TLAS 1, 2.
    let (mut b, _, main, leaf) = with_leaf();
    let z = b.add_prototype("z", main).unwrap();
    b.add_instance(z, leaf, t(1.0, 0.0, 0.0), main).unwrap();
    let mut xy = Vec::new();
    for name in ["x", "y"] {
        let p = b.add_prototype(name, main).unwrap();
        b.add_instance(p, z, t(0.0, 1.0, 0.0), main).unwrap();
        b.add_instance(p, z, t(0.0, 2.0, 0.0), main).unwrap();
        xy.push(p);
    }
    for &p in &xy {
        b.add_instance(b.root(), p, t(0.0, 0.0, 1.0), main).unwrap();
        b.add_instance(b.root(), p, t(0.0, 0.0, 2.0), main).unwrap();
    }
    let scene = b.finish().unwrap();
    let c = check_flatten(&scene, &opts(Levels::Ml));
    let root = c.tlases[0];
    let a = c.blases[c.instances[root.instance_base as usize].blas as usize];
    let targets: Vec<u32> = c.pis[a.item_base as usize..][..a.item_count as usize]
        .iter()
        .map(|p| p.target)
        .collect();
    assert_eq!(targets, vec![1, 1, 2, 2]);
    // z is first referenced by x (TLAS 1), so it is numbered right after the root's children
    // and emitted (instance table) before y.
    assert_eq!(c.tlases.len(), 4);
    assert!(c.tlases[3].instance_base < c.tlases[2].instance_base);
}

#[test]
fn lod_chains_replace_heavy_meshes_with_selectors() {
    let mut b = builder();
    let (m, main) = (b.default_material(), Scene::MAIN_ELEMENT);
    let dense = b.add_prototype("dense", main).unwrap();
    let grid = grid_mesh(64, false);
    b.add_mesh(dense, "grid", m, main, &grid).unwrap();
    b.add_mesh(dense, "small", m, main, &triangle()).unwrap();
    for i in 0..4 {
        b.add_instance(b.root(), dense, rot(i as f32, 3.0 * i as f32), main)
            .unwrap();
    }
    let scene = b.finish().unwrap();
    let o = CompileOptions {
        lod_levels: Some(3),
        lod_triangle_threshold: 1000,
        ..Default::default()
    };
    let mut got: Vec<(u32, usize)> = Vec::new();
    let mut sink = |record: u32, data: &MeshData, _: Option<&[u32]>| {
        got.push((record, data.triangle_count()));
        Ok(())
    };
    let c = compile(&scene, &o, &mut sink).unwrap();
    crate::validate(&c.view()).unwrap();
    assert_eq!(
        c.lod_selectors.len(),
        1,
        "one chain, shared by 4 placements"
    );
    let s = c.lod_selectors[0];
    assert_eq!(s.level_count, 3);
    assert_eq!(got.len(), 2);
    assert_eq!(c.report.lod_meshes_made, 2);
    let mut tris = vec![grid.triangle_count()];
    for (lod, &(record, n)) in got.iter().enumerate() {
        let r = c.meshes[record as usize];
        assert_eq!(
            (r.lod, r.source_mesh, r.triangle_count as usize),
            (lod as u32 + 1, 0, n)
        );
        tris.push(n);
    }
    for w in tris.windows(2) {
        let ratio = w[0] as f64 / w[1] as f64;
        assert!((2.5..=6.0).contains(&ratio), "{tris:?}");
    }
    assert_eq!(
        c.pis.iter().filter(|p| p.kind == PI_LOD_SELECTOR).count(),
        4
    );
    // The finest level reproduces the scene; coarser levels keep the placements.
    assert_same_placements(&flatten_source(&scene), &flatten_compiled(&c.view(), 0));
    assert_eq!(flatten_compiled(&c.view(), 2).len(), 8);
    // The selector's sphere encloses the mesh.
    let half_diag = (Vec3::from_array(scene.mesh(motu_scene::MeshId(0)).bounds.max)
        - Vec3::from_array(scene.mesh(motu_scene::MeshId(0)).bounds.min))
    .length()
        * 0.5;
    assert!((s.radius - half_diag).abs() < 1e-5);
    // Sink errors surface, the sink's own error kept as the cause.
    let mut failing =
        |_: u32, _: &MeshData, _: Option<&[u32]>| Err(std::io::Error::other("disk full").into());
    let err = compile(&scene, &o, &mut failing).unwrap_err();
    assert!(matches!(err, CompileError::Sink { .. }), "{err}");
    let cause = std::error::Error::source(&err).expect("the sink's error is the source");
    assert_eq!(cause.to_string(), "disk full");
    assert!(err.to_string().ends_with(": disk full"), "{err}");
}

#[test]
fn buddha_fractal_shape_splits_into_at_least_26_tlases() {
    // The acceptance shape: one plain prototype placed 25,250 times under the root.
    let scene = scattered(25_250, false);
    let o = CompileOptions {
        max_instances_per_tlas: 1000,
        ..Default::default()
    };
    let c = compile_ok(&scene, &o);
    assert!(c.tlases.len() >= 26, "{}", c.tlases.len());
    assert!(c.tlases.iter().all(|t| t.instance_count <= 1000));
    assert_eq!(c.report.flattened_instances, 25_250);
    assert_eq!(flatten_compiled(&c.view(), 0).len(), 25_250);
}

#[test]
fn singular_compositions_are_inlined_not_dropped() {
    // Every edge is invertible, but root∘a∘b underflows the determinant: the PI to c that
    // `N(2)` would make cannot store an inverse, so c is inlined instead.
    let (mut b, _, main, leaf) = with_leaf();
    let tiny = Transform34::from_mat4(Mat4::from_scale(Vec3::splat(1e-6)));
    let mut child = leaf;
    for name in ["c", "b", "a"] {
        let p = b.add_prototype(name, main).unwrap();
        b.add_instance(p, child, tiny, main).unwrap();
        b.add_instance(p, child, tiny.mul(&t(1.0, 0.0, 0.0)), main)
            .unwrap();
        child = p;
    }
    b.add_instance(b.root(), child, tiny, main).unwrap();
    b.add_instance(b.root(), child, t(1.0, 0.0, 0.0), main)
        .unwrap();
    let scene = b.finish().unwrap();
    for levels in [Levels::Ml, Levels::N(2), Levels::Sl] {
        let c = check_flatten(&scene, &opts(levels));
        assert_eq!(c.report.dropped_degenerate_instances, 0);
    }
}

#[test]
fn auto_inlines_grouping_levels_but_keeps_geometry_shared() {
    // world → 3 groups → 4 trees each; a tree = trunk mesh + 5 leaf placements.
    let mut b = motu_scene::SceneBuilder::default();
    let main = motu_scene::Scene::MAIN_ELEMENT;
    let mat = b.default_material();
    let tri = motu_scene::MeshData {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        indices: vec![0, 1, 2],
        ..Default::default()
    };
    let leaf = b.add_prototype("leaf", main).unwrap();
    b.add_mesh(leaf, "leaf", mat, main, &tri).unwrap();
    let tree = b.add_prototype("tree", main).unwrap();
    b.add_mesh(tree, "trunk", mat, main, &tri).unwrap();
    let t = |x: f32, y: f32| motu_scene::Transform34::from_translation(glam::Vec3::new(x, y, 0.0));
    for i in 0..5 {
        b.add_instance(tree, leaf, t(i as f32, 1.0), main).unwrap();
    }
    let group = b.add_prototype("group", main).unwrap();
    for i in 0..4 {
        b.add_instance(group, tree, t(0.0, 3.0 * i as f32), main)
            .unwrap();
    }
    for i in 0..3 {
        b.add_instance(b.root(), group, t(10.0 * i as f32, 0.0), main)
            .unwrap();
    }
    let scene = b.finish().unwrap();
    let no_bake = |levels| CompileOptions {
        auto_bake_max_triangles: 0,
        auto_inline_max_instances: 0,
        ..opts(levels)
    };
    let ml = check_flatten(&scene, &opts(Levels::Ml));
    let auto = check_flatten(&scene, &no_bake(Levels::Auto));
    // Ml: root → group TLAS → tree TLAS. Auto: root holds the 12 tree PIs directly.
    assert_eq!(ml.report.tlas_levels, 3, "{:?}", ml.report);
    assert_eq!(auto.report.tlas_levels, 2, "{:?}", auto.report);
    assert_eq!(auto.pis.len(), 12);
    // The trees stay shared: one tree TLAS.
    assert_eq!(auto.tlases.len(), 2);
    // A tight entry cap keeps the group level.
    let tight = check_flatten(
        &scene,
        &CompileOptions {
            auto_inline_max_entries: 3,
            ..no_bake(Levels::Auto)
        },
    );
    assert_eq!(tight.report.tlas_levels, 3);
    // Cheap inlining without baking: a tree TLAS (trunk BLAS + 5 leaf instances) is used by 4
    // edges (the group's, inlined into the root), 6 × 4 = 24 entries: at a cap of 24 it is
    // inlined (one level, 3 × 4 × 6 instances), at 23 it stays a shared TLAS.
    let cap = |n| CompileOptions {
        auto_inline_max_instances: n,
        ..no_bake(Levels::Auto)
    };
    let inlined = check_flatten(&scene, &cap(24));
    assert_eq!(inlined.report.tlas_levels, 1, "{:?}", inlined.report);
    assert!(inlined.pis.is_empty());
    assert_eq!(inlined.tlases[0].instance_count, 72);
    // The group (a grouping level) and the tree (cheap).
    assert_eq!(inlined.report.inlined_prototypes, 2);
    assert_eq!(auto.report.inlined_prototypes, 1);
    assert_eq!(check_flatten(&scene, &cap(23)).report.tlas_levels, 2);
    // Baking (the default): a tree is 6 triangles, so its copies become one triangle BLAS,
    // instanced 12 times in the root: one level, no PI, the same triangles as the source.
    let (baked, captured) = crate::testutil::compile_capturing(&scene, &opts(Levels::Auto));
    assert_eq!(baked.report.baked_prototypes, 1, "{:?}", baked.report);
    assert_eq!(baked.tlases.len(), 1);
    assert!(baked.pis.is_empty());
    assert_eq!(baked.tlases[0].instance_count, 12);
    crate::testutil::assert_same_triangles(
        &crate::testutil::source_triangles(&scene),
        &crate::testutil::compiled_triangles(&scene, &baked, &captured),
    );
}

#[test]
fn baking_keeps_source_triangles_normals_and_winding_under_mirroring() {
    // A leaf with normals placed twice in a tree, once mirrored; the tree placed twice.
    let mut b = builder();
    let main = Scene::MAIN_ELEMENT;
    let mat = b.default_material();
    let leaf = b.add_prototype("leaf", main).unwrap();
    let leaf_mesh = b
        .add_mesh(leaf, "leaf", mat, main, &grid_mesh(2, true))
        .unwrap();
    let tree = b.add_prototype("tree", main).unwrap();
    // (A trunk of its own: a mesh-less two-entry tree would be inlined, not baked.)
    b.add_mesh(tree, "trunk", mat, main, &triangle()).unwrap();
    let mirror = motu_scene::Transform34::from_mat4(glam::Mat4::from_scale_rotation_translation(
        glam::Vec3::new(-1.0, 2.0, 1.0),
        glam::Quat::from_rotation_z(0.5),
        glam::Vec3::new(3.0, 0.0, 0.0),
    ));
    b.add_instance(tree, leaf, Transform34::IDENTITY, main)
        .unwrap();
    b.add_instance(tree, leaf, mirror, main).unwrap();
    for i in 0..2 {
        b.add_instance(b.root(), tree, rot(i as f32, 5.0 * i as f32), main)
            .unwrap();
    }
    let scene = b.finish().unwrap();
    let (c, captured) = crate::testutil::compile_capturing(&scene, &opts(Levels::Auto));
    assert_eq!(c.report.baked_prototypes, 1, "{:?}", c.report);
    crate::testutil::assert_same_triangles(
        &crate::testutil::source_triangles(&scene),
        &crate::testutil::compiled_triangles(&scene, &c, &captured),
    );
    // The baked record: the leaf's two copies, mapped to the leaf's 8 triangles twice.
    let (r, rec) = c
        .meshes
        .iter()
        .enumerate()
        .find(|(_, m)| m.source_mesh == leaf_mesh.0)
        .unwrap();
    assert_ne!(rec.flags & motu_abi::FLAG_PRIMITIVE_MAP, 0);
    let (data, map) = &captured[&(r as u32)];
    let map = map.as_ref().unwrap();
    assert_eq!(map, &(0..8).chain(0..8).collect::<Vec<u32>>());
    // Winding and normals agree in both copies: the geometric normal of every triangle points
    // the way its vertex normals do (the mirrored copy's winding was flipped back).
    let normals = data.normals.as_ref().unwrap();
    for t in data.indices.chunks_exact(3) {
        let p: Vec<glam::Vec3> = t
            .iter()
            .map(|&i| glam::Vec3::from(data.positions[i as usize]))
            .collect();
        let ng = (p[1] - p[0]).cross(p[2] - p[0]);
        let ns = glam::Vec3::from(normals[t[0] as usize]);
        assert!(ng.dot(ns) > 0.0, "winding {ng} against normal {ns}");
        assert!((ns.length() - 1.0).abs() < 1e-5);
    }
}

/// A big mesh (`grid_mesh(64)`: 8,192 triangles) in a prototype placed 3 times, 40 small meshes
/// (32 triangles each) at the root in two elements, and one root mesh over the bound.
fn partition_scene() -> Scene {
    let mut b = builder();
    let m = b.default_material();
    let main = Scene::MAIN_ELEMENT;
    let other = b.element("other").unwrap();
    let big = b.add_prototype("big", main).unwrap();
    b.add_mesh(big, "terrain", m, main, &grid_mesh(64, true))
        .unwrap();
    for i in 0..3 {
        b.add_instance(b.root(), big, rot(i as f32, 3.0 * i as f32), main)
            .unwrap();
    }
    for i in 0..40 {
        let mut g = grid_mesh(4, false);
        for p in &mut g.positions {
            p[0] += (i % 10) as f32 * 2.0;
            p[1] += (i / 10) as f32 * 2.0;
        }
        let element = if i % 4 == 0 { other } else { main };
        b.add_mesh(b.root(), &format!("small{i}"), m, element, &g)
            .unwrap();
    }
    b.add_mesh(b.root(), "root-big", m, main, &grid_mesh(40, false))
        .unwrap();
    b.finish().unwrap()
}

type Made = Vec<(u32, usize, Option<Vec<u32>>)>;

fn compile_recording(scene: &Scene, o: &CompileOptions) -> (crate::CompiledScene, Made) {
    let mut made: Made = Vec::new();
    let mut sink = |record: u32, data: &MeshData, map: Option<&[u32]>| {
        data.validate().unwrap();
        made.push((record, data.triangle_count(), map.map(<[u32]>::to_vec)));
        Ok(())
    };
    let c = compile(scene, o, &mut sink).unwrap();
    crate::validate(&c.view()).unwrap_or_else(|e| panic!("{e}"));
    (c, made)
}

#[test]
fn partitioner_bounds_every_triangle_blas_and_keeps_source_identity() {
    let scene = partition_scene();
    let bound = 1000u32;
    for levels in [Levels::Ml, Levels::Sl, Levels::Auto] {
        let o = CompileOptions {
            levels,
            max_blas_triangles: bound,
            ..Default::default()
        };
        let (c, made) = compile_recording(&scene, &o);
        // Every triangle BLAS within the bound.
        for b in c.blases.iter().filter(|b| b.kind == BLAS_TRIANGLES) {
            assert!(
                b.primitive_count <= bound,
                "{levels:?}: {}",
                b.primitive_count
            );
        }
        assert_eq!(c.report.max_blas_triangles, u64::from(bound));
        assert!(c.report.max_triangles_per_blas <= u64::from(bound));
        // The two big meshes (8,192 and 3,200 triangles) became clusters, handed to the sink
        // with maps that cover each source triangle exactly once.
        assert_eq!(c.report.partitioned_meshes, 2);
        for (source, tris) in [(0u32, 8192usize), (41, 3200)] {
            let mut seen = vec![0u32; tris];
            let mut clusters = 0;
            for (record, n, map) in &made {
                let r = c.meshes[*record as usize];
                if r.source_mesh != source {
                    continue;
                }
                clusters += 1;
                assert_eq!(
                    r.flags & motu_abi::FLAG_PRIMITIVE_MAP,
                    motu_abi::FLAG_PRIMITIVE_MAP
                );
                assert_eq!((r.lod, r.triangle_count as usize), (0, *n));
                let map = map.as_ref().expect("a cluster has a map");
                assert_eq!(map.len(), *n);
                for &p in map {
                    seen[p as usize] += 1;
                }
            }
            assert_eq!(
                clusters as u64,
                crate::partition::cluster_count(tris as u64, bound)
            );
            assert!(seen.iter().all(|&s| s == 1), "mesh {source}: coverage");
            // No whole record of a partitioned mesh is left.
            assert!(!c
                .meshes
                .iter()
                .any(|r| r.source_mesh == source && r.flags & motu_abi::FLAG_PRIMITIVE_MAP == 0));
        }
        // Small meshes: each in exactly one BLAS, grouped by location per element: 30 main
        // meshes (960 triangles) fit one group, 10 "other" ones another — never one BLAS per
        // mesh. With a bound of 500 they need several groups each, still far fewer than 40.
        let small_blases = |c: &crate::CompiledScene| {
            let mut owner = vec![u32::MAX; 40];
            for (bi, b) in c.blases.iter().enumerate() {
                if b.kind != BLAS_TRIANGLES {
                    continue;
                }
                for g in &c.geometries[b.item_base as usize..(b.item_base + b.item_count) as usize]
                {
                    let s = c.meshes[g.mesh as usize].source_mesh;
                    if (1..=40).contains(&s) {
                        assert_eq!(owner[s as usize - 1], u32::MAX, "mesh {s} in two BLASes");
                        owner[s as usize - 1] = bi as u32;
                    }
                }
            }
            assert!(owner.iter().all(|&o| o != u32::MAX));
            let mut distinct = owner.clone();
            distinct.sort_unstable();
            distinct.dedup();
            distinct.len()
        };
        assert_eq!(small_blases(&c), 2, "{levels:?}");
        let tight = CompileOptions {
            max_blas_triangles: 500,
            ..o.clone()
        };
        let (c2, _) = compile_recording(&scene, &tight);
        let groups = small_blases(&c2);
        assert!((3..=8).contains(&groups), "{groups} groups");
        // Placements: each source placement once per cluster of its mesh.
        let mut expected = Vec::new();
        for (t, m) in flatten_source(&scene) {
            let k = c
                .meshes
                .iter()
                .filter(|r| r.source_mesh == m.0 && r.lod == 0)
                .count();
            expected.extend(std::iter::repeat_n((t, m), k));
        }
        assert_same_placements(&expected, &flatten_compiled(&c.view(), 0));
    }
}

#[test]
fn partitioner_splits_every_lod_level_over_the_bound() {
    let mut b = builder();
    let (m, main) = (b.default_material(), Scene::MAIN_ELEMENT);
    let dense = b.add_prototype("dense", main).unwrap();
    b.add_mesh(dense, "grid", m, main, &grid_mesh(64, false))
        .unwrap();
    for i in 0..2 {
        b.add_instance(b.root(), dense, rot(i as f32, 3.0 * i as f32), main)
            .unwrap();
    }
    let scene = b.finish().unwrap();
    let o = CompileOptions {
        lod_levels: Some(3),
        lod_triangle_threshold: 1000,
        max_blas_triangles: 1500,
        ..Default::default()
    };
    let (c, made) = compile_recording(&scene, &o);
    assert_eq!(c.lod_selectors.len(), 1);
    let s = c.lod_selectors[0];
    assert_eq!(s.level_count, 3);
    for (level, &tlas) in c.lod_levels[s.level_base as usize..][..3]
        .iter()
        .enumerate()
    {
        let t = c.tlases[tlas as usize];
        let insts = &c.instances[t.instance_base as usize..][..t.instance_count as usize];
        let mut tris = 0u64;
        let mut seen: Vec<u32> = Vec::new();
        for inst in insts {
            let blas = c.blases[inst.blas as usize];
            assert_eq!(blas.kind, BLAS_TRIANGLES);
            assert!(blas.primitive_count <= 1500);
            tris += u64::from(blas.primitive_count);
            for g in &c.geometries[blas.item_base as usize..][..blas.item_count as usize] {
                let r = c.meshes[g.mesh as usize];
                assert_eq!((r.source_mesh, r.lod), (0, level as u32));
                if let Some((_, _, Some(map))) = made.iter().find(|x| x.0 == g.mesh) {
                    seen.extend_from_slice(map);
                }
            }
        }
        if level == 0 {
            assert_eq!(tris, 8192);
            assert!(
                insts.len() >= 8,
                "level 0 partitioned: {} units",
                insts.len()
            );
        }
        if insts.len() > 1 {
            // The level's clusters cover its triangles once.
            seen.sort_unstable();
            assert_eq!(seen, (0..tris as u32).collect::<Vec<_>>(), "level {level}");
        }
    }
    assert!(
        c.report.partitioned_meshes >= 2,
        "levels 0 and 1 are over 1,500"
    );
}

#[test]
fn partitioner_bound_of_zero_is_an_error() {
    let scene = partition_scene();
    let o = CompileOptions {
        max_blas_triangles: 0,
        ..Default::default()
    };
    let mut sink = |_: u32, _: &MeshData, _: Option<&[u32]>| Ok(());
    assert!(matches!(
        compile(&scene, &o, &mut sink),
        Err(CompileError::InvalidOptions(_))
    ));
}

/// The streamer's load-time split makes what `--max-instances` makes at compile time: the
/// same placements, every TLAS within the cap, a valid hierarchy, the same tables' sizes and
/// levels; and nothing at all when no TLAS is over the cap.
#[test]
fn split_for_streaming_matches_the_compile_time_split() {
    for same_place in [false, true] {
        let scene = scattered(10_000, same_place);
        let whole = check_flatten(&scene, &CompileOptions::default());
        assert_eq!(whole.report.split_tlases, 0);
        assert!(crate::split_for_streaming(&whole.view(), 20_000)
            .unwrap()
            .is_none());
        let split = crate::split_for_streaming(&whole.view(), 1000)
            .unwrap()
            .expect("a TLAS over the cap");
        let v = split.view(&whole.view());
        assert_same_placements(&flatten_source(&scene), &flatten_compiled(&v, 0));
        crate::validate(&v).unwrap();
        assert!(v.tlases.iter().all(|t| t.instance_count <= 1000));
        let capped = compile_ok(
            &scene,
            &CompileOptions {
                max_instances_per_tlas: 1000,
                ..Default::default()
            },
        );
        assert_eq!(v.tlases.len(), capped.tlases.len());
        assert_eq!(v.instances.len(), capped.instances.len());
        assert_eq!(v.blases.len(), capped.blases.len());
        assert_eq!(v.pis.len(), capped.pis.len());
        let levels = |v: &motu_abi::HierarchyView<'_>| -> Vec<u32> {
            v.tlases.iter().map(|t| t.level).collect()
        };
        assert_eq!(levels(&v), levels(&capped.view()));
        assert_eq!(split.counts(), (1, capped.report.split_pieces));
    }
}

/// A TLAS over the cap that is not the instance table's tail (a shared prototype's, with the
/// root's instances after it) is moved there, the other ranges kept consistent.
#[test]
fn split_for_streaming_moves_a_range_that_is_not_the_tail() {
    let (mut b, m, main, leaf) = with_leaf();
    let tree = b.add_prototype("tree", main).unwrap();
    b.add_mesh(tree, "trunk", m, main, &triangle()).unwrap();
    for i in 0..3000 {
        let (x, y) = ((i % 60) as f32, (i / 60) as f32);
        b.add_instance(tree, leaf, t(x, y, 0.0), main).unwrap();
    }
    for i in 0..3 {
        b.add_instance(b.root(), tree, t(0.0, 0.0, 100.0 * i as f32), main)
            .unwrap();
    }
    for i in 0..2500 {
        b.add_instance(b.root(), leaf, t(i as f32, -50.0, 0.0), main)
            .unwrap();
    }
    let scene = b.finish().unwrap();
    let whole = check_flatten(&scene, &CompileOptions::default());
    let split = crate::split_for_streaming(&whole.view(), 700)
        .unwrap()
        .expect("two TLASes over the cap");
    let v = split.view(&whole.view());
    crate::validate(&v).unwrap();
    assert_same_placements(&flatten_source(&scene), &flatten_compiled(&v, 0));
    assert!(v.tlases.iter().all(|t| t.instance_count <= 700));
    assert_eq!(split.counts().0, 2);
    // Rotated, not copied: the table grows only by the pieces' AABB instances.
    assert!(v.instances.len() < whole.instances.len() + 100);
    // In place: the stored split of the copy, and the instance table back in its order.
    let mut in_place = whole.clone();
    let s = crate::stored_stream_split_in_place(&mut in_place, 700).unwrap();
    assert_eq!(s, crate::stored_stream_split(&whole.view(), 700).unwrap());
    assert_eq!(in_place.instances, whole.instances);
    assert_eq!(in_place.tlases, whole.tlases);
}

/// The split a package stores (`stored_stream_split`) rebuilds exactly the split a reader
/// would make (every table equal, `_pad` cleared), for a root split in place and for a
/// shared range moved to the tail; a damaged map is an error, not a panic.
#[test]
fn a_stored_stream_split_rebuilds_the_same_split() {
    let scene = scattered(10_000, false);
    let whole = check_flatten(&scene, &CompileOptions::default());
    assert!(crate::stored_stream_split(&whole.view(), 20_000)
        .unwrap()
        .is_none());
    for cap in [1000, 3000] {
        let made = crate::split_for_streaming(&whole.view(), cap)
            .unwrap()
            .expect("a TLAS over the cap");
        let stored = crate::stored_stream_split(&whole.view(), cap)
            .unwrap()
            .expect("stored");
        assert!(stored.extra_instances.iter().all(|i| i._pad == 0));
        assert!(stored.instance_source.iter().any(|&s| s != NONE_U32));
        // Made in place (no copy of the instance table): the same, the table put back.
        let mut in_place = whole.clone();
        let s = crate::stored_stream_split_in_place(&mut in_place, cap).unwrap();
        assert_eq!(s.as_ref(), Some(&stored));
        assert_eq!(in_place.instances, whole.instances);
        let back = crate::StreamSplit::from_stored(&whole.view(), &stored).unwrap();
        let (a, b) = (made.view(&whole.view()), back.view(&whole.view()));
        assert_eq!(a.tlases, b.tlases);
        assert_eq!(a.instances, b.instances);
        assert!(a.instances.iter().all(|i| i._pad == 0));
        assert_eq!(a.blases, b.blases);
        assert_eq!(a.pis, b.pis);
        assert_eq!(a.meshes, b.meshes);
        assert_eq!(made.counts(), back.counts());
        // Kept by the caller, holding the table (the import's proxy tables are made over
        // it): the reader's records, and the table given back in its order.
        let mut taken = whole.clone();
        let (s, kept) = crate::stream_split_taking_instances(&mut taken, cap)
            .unwrap()
            .expect("a TLAS over the cap");
        assert_eq!(s, stored);
        assert!(taken.instances.is_empty());
        let k = kept.view(&whole.view());
        assert_eq!(k.instances, b.instances);
        assert_eq!((k.tlases, k.blases, k.pis), (b.tlases, b.blases, b.pis));
        assert_eq!(kept.counts(), back.counts());
        kept.give_back(&mut taken, &s).unwrap();
        assert_eq!(taken.instances, whole.instances);
        let mut bad = stored.clone();
        bad.instance_source[0] = whole.instances.len() as u32;
        assert!(crate::StreamSplit::from_stored(&whole.view(), &bad).is_err());
        let mut bad = stored.clone();
        bad.extra_instances.pop();
        assert!(crate::StreamSplit::from_stored(&whole.view(), &bad).is_err());
    }
}

/// A TLAS split by key (its records in a scratch file, the partition over their indices:
/// `tlas_split/stash.rs`) is the split made in memory, bit for bit: at compile time (one
/// round, and several under a tiny cap; scattered and coincident instances) and the import's
/// stream split, whose table then goes back in its order.
#[test]
fn keyed_splits_equal_splits_in_memory() {
    fn bytes<T: bytemuck::Pod>(t: &[T]) -> &[u8] {
        bytemuck::cast_slice(t)
    }
    let dir = tempfile::tempdir().unwrap();
    let keyed = |o: &CompileOptions| CompileOptions {
        split_scratch_dir: Some(dir.path().to_path_buf()),
        ..o.clone()
    };
    for (scene, cap) in [
        (scattered(10_000, false), 1000),
        (scattered(2000, false), 30),
        (scattered(500, true), 40),
    ] {
        let o = CompileOptions {
            max_instances_per_tlas: cap,
            ..Default::default()
        };
        let (a, b) = (check_flatten(&scene, &o), check_flatten(&scene, &keyed(&o)));
        // With a scratch directory the table is a mapped file (tests: every table).
        assert!(!a.instances.is_mapped() && b.instances.is_mapped());
        assert_eq!(a.report.split_tlases, 1);
        assert!(a.tlases.len() > 2);
        assert_eq!(bytes(&a.instances), bytes(&b.instances));
        assert_eq!(bytes(&a.tlases), bytes(&b.tlases));
        assert_eq!(bytes(&a.blases), bytes(&b.blases));
        assert_eq!(bytes(&a.pis), bytes(&b.pis));
        let counts = |c: &crate::CompiledScene| {
            let r = &c.report;
            (r.split_pieces, r.split_aabb_blases, r.max_level)
        };
        assert_eq!(counts(&a), counts(&b));
    }
    let whole = check_flatten(&scattered(10_000, false), &CompileOptions::default());
    let mapped = |c: &crate::CompiledScene| mapped_copy(c, dir.path());
    for cap in [1000, 3000] {
        let (mut a, mut b, mut c) = (whole.clone(), whole.clone(), mapped(&whole));
        let (sa, ka) = crate::stream_split_taking_instances(&mut a, cap)
            .unwrap()
            .expect("a TLAS over the cap");
        let (sb, kb) = crate::stream_split_taking_instances_in(&mut b, cap, Some(dir.path()))
            .unwrap()
            .expect("a TLAS over the cap");
        assert_eq!(sa, sb);
        let (va, vb) = (ka.view(&whole.view()), kb.view(&whole.view()));
        assert_eq!(bytes(va.instances), bytes(vb.instances));
        assert_eq!(bytes(va.tlases), bytes(vb.tlases));
        assert_eq!(bytes(va.pis), bytes(vb.pis));
        kb.give_back(&mut b, &sb).unwrap();
        assert_eq!(bytes(&b.instances), bytes(&whole.instances));
        // A mapped table (the import's), split by key and rotated through a scratch file.
        let (sc, kc) = crate::stream_split_taking_instances_in(&mut c, cap, Some(dir.path()))
            .unwrap()
            .expect("a TLAS over the cap");
        assert_eq!(sa, sc);
        assert_eq!(bytes(va.instances), bytes(kc.view(&whole.view()).instances));
        kc.give_back(&mut c, &sc).unwrap();
        assert_eq!(bytes(&c.instances), bytes(&whole.instances));
    }
    // Nothing is left in the scratch directory (the files are unnamed).
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// `c` with its instance table in a mapped file in `dir` (the import's).
fn mapped_copy(c: &crate::CompiledScene, dir: &std::path::Path) -> crate::CompiledScene {
    let mut c = c.clone();
    let mut t = crate::InstanceTable::in_file(dir).unwrap();
    for r in c.instances.iter() {
        t.push(*r).unwrap();
    }
    c.instances = t;
    c
}

/// A stream split whose instance table is parked in a mapped scratch file
/// (`StreamSplit::park_instances`, the import's while it makes the proxy clusters) reads the
/// same records, makes the same proxy clusters with its pages dropped after every batch, and
/// gives the table back in its order, bit for bit; the file leaves no name behind.
#[test]
fn parked_stream_split_reads_and_gives_back_the_same_table() {
    fn bytes<T: bytemuck::Pod>(t: &[T]) -> &[u8] {
        bytemuck::cast_slice(t)
    }
    let dir = tempfile::tempdir().unwrap();
    for (whole, cap) in [
        (
            check_flatten(&scattered(10_000, false), &CompileOptions::default()),
            1000,
        ),
        (
            check_flatten(&scattered(2000, true), &CompileOptions::default()),
            300,
        ),
    ] {
        // `b`'s table is a mapped file, as the import's: split in place, parked with no copy.
        let (mut a, mut b) = (whole.clone(), mapped_copy(&whole, dir.path()));
        // The import parks the package's own table before the split and drops the split
        // instead of giving it back: the map is the table given back.
        let package = crate::park_table(&b.instances, dir.path())
            .unwrap()
            .expect("parked");
        let (sa, ka) = crate::stream_split_taking_instances(&mut a, cap)
            .unwrap()
            .expect("a TLAS over the cap");
        let (sb, mut kb) = crate::stream_split_taking_instances_in(&mut b, cap, Some(dir.path()))
            .unwrap()
            .expect("a TLAS over the cap");
        assert_eq!(sa, sb);
        assert!(kb.park_instances(dir.path()).unwrap());
        assert!(!kb.park_instances(dir.path()).unwrap(), "parked once");
        let (va, vb) = (ka.view(&whole.view()), kb.view(&whole.view()));
        assert_eq!(bytes(va.instances), bytes(vb.instances));
        assert_eq!(bytes(va.tlases), bytes(vb.tlases));
        let mut batches = 0;
        let clusters = crate::proxy_clusters::StoredProxyClusters::of_view_then(&vb, &mut || {
            batches += 1;
            kb.release_instance_pages();
        });
        assert!(batches > 0);
        assert_eq!(
            clusters,
            crate::proxy_clusters::StoredProxyClusters::of_view(&va)
        );
        assert_eq!(bytes(vb.instances), bytes(va.instances), "after the drops");
        kb.give_back(&mut b, &sb).unwrap();
        ka.give_back(&mut a, &sa).unwrap();
        assert_eq!(bytes(&b.instances), bytes(&whole.instances));
        assert_eq!(bytes(&a.instances), bytes(&whole.instances));
        assert_eq!(bytes(package.records()), bytes(&whole.instances));
        assert_eq!(package.len(), whole.instances.len());
        package.release_pages().unwrap();
        assert_eq!(bytes(package.records()), bytes(&whole.instances));
        drop(package);
        // A map that names fewer origins than the table holds is an error, not a short table.
        let (mut c, (sc, mut kc)) = {
            let mut c = whole.clone();
            let s = crate::stream_split_taking_instances(&mut c, cap)
                .unwrap()
                .unwrap();
            (c, s)
        };
        kc.park_instances(dir.path()).unwrap();
        let mut bad = sc.clone();
        let first = bad
            .instance_source
            .iter()
            .position(|&s| s != NONE_U32)
            .unwrap();
        bad.instance_source[first] = NONE_U32;
        bad.extra_instances.push(Default::default());
        assert!(kc.give_back(&mut c, &bad).is_err());
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}
