//! Random DAGs: every compile mode yields a hierarchy that passes `validate` and flattens to
//! exactly the source's leaf placements.

use crate::testutil::{
    assert_same_placements, assert_same_triangles, compile_capturing, compile_ok,
    compiled_triangles, source_triangles,
};
use crate::{flatten_compiled, flatten_source, CompileOptions, Levels};
use glam::{Mat4, Quat, Vec3};
use motu_scene::{MeshData, PrototypeId, Scene, SceneBuilder, Transform34};
use proptest::prelude::*;

#[derive(Clone, Debug)]
struct Xf {
    identity: bool,
    axis: [f32; 3],
    angle: f32,
    scale: [f32; 3],
    translation: [f32; 3],
}

impl Xf {
    fn transform(&self) -> Transform34 {
        if self.identity {
            return Transform34::IDENTITY;
        }
        let axis = Vec3::from_array(self.axis);
        let q = if axis.length() > 1e-3 {
            Quat::from_axis_angle(axis.normalize(), self.angle)
        } else {
            Quat::IDENTITY
        };
        Transform34::from_mat4(Mat4::from_scale_rotation_translation(
            Vec3::from_array(self.scale),
            q,
            Vec3::from_array(self.translation),
        ))
    }
}

fn xf() -> impl Strategy<Value = Xf> {
    (
        prop::bool::weighted(0.25),
        prop::array::uniform3(-1.0f32..1.0),
        -3.2f32..3.2,
        prop::array::uniform3(0.5f32..2.0),
        prop::array::uniform3(-10.0f32..10.0),
    )
        .prop_map(|(identity, axis, angle, scale, translation)| Xf {
            identity,
            axis,
            angle,
            scale,
            translation,
        })
}

/// Prototype `i` (0 = root) has meshes and edges to prototypes `j > i` (so a DAG), each
/// edge tagged with an element (only the root's tags matter).
#[derive(Clone, Debug)]
struct Dag {
    /// Per prototype: mesh count and edges `(child, transform, element)`.
    protos: Vec<(u8, Vec<EdgeSpec>)>,
}

type EdgeSpec = (usize, Xf, u8);

fn dag() -> impl Strategy<Value = Dag> {
    (2usize..9)
        .prop_flat_map(|n| {
            let protos: Vec<_> = (0..n)
                .map(|i| {
                    let children = prop::collection::vec(
                        ((i + 1)..n.max(i + 2), xf(), 0u8..2),
                        if i + 1 < n { 0..6 } else { 0..1 },
                    );
                    (if i + 1 == n { 1u8..3 } else { 0u8..3 }, children)
                })
                .collect();
            protos
        })
        .prop_map(|protos| Dag {
            protos: protos
                .into_iter()
                .map(|(m, edges)| (m, edges.into_iter().filter(|e| e.0 > 0).collect()))
                .collect(),
        })
}

fn mesh(seed: usize) -> MeshData {
    let s = seed as f32;
    MeshData {
        positions: vec![
            [s, 0.0, 0.0],
            [s + 1.0, 0.5, 0.0],
            [s, 1.0, 0.25 * s],
            [s + 0.5, 0.5, 1.0],
        ],
        indices: vec![0, 1, 2, 0, 2, 3],
        ..Default::default()
    }
}

fn build(d: &Dag) -> Scene {
    let mut b = SceneBuilder::default();
    let m = b.default_material();
    let elements = [Scene::MAIN_ELEMENT, b.element("other").unwrap()];
    let mut ids = vec![b.root()];
    for i in 1..d.protos.len() {
        ids.push(b.add_prototype(&format!("p{i}"), elements[0]).unwrap());
    }
    let mut seed = 0;
    for (i, (meshes, edges)) in d.protos.iter().enumerate() {
        for _ in 0..*meshes {
            seed += 1;
            b.add_mesh(
                ids[i],
                &format!("m{seed}"),
                m,
                elements[seed % 2],
                &mesh(seed),
            )
            .unwrap();
        }
        for (child, x, el) in edges {
            let child: PrototypeId = ids[(*child).min(d.protos.len() - 1)];
            if child != ids[i] {
                b.add_instance(ids[i], child, x.transform(), elements[*el as usize])
                    .unwrap();
            }
        }
    }
    b.finish().unwrap()
}

fn modes() -> Vec<CompileOptions> {
    let capped = |levels| CompileOptions {
        levels,
        max_instances_per_tlas: 3,
        max_primitives_per_blas: 2,
        ..Default::default()
    };
    vec![
        CompileOptions::default(),
        CompileOptions {
            levels: Levels::Sl,
            ..Default::default()
        },
        CompileOptions {
            levels: Levels::N(2),
            ..Default::default()
        },
        CompileOptions {
            levels: Levels::Auto,
            auto_inline_max_entries: 3,
            ..Default::default()
        },
        capped(Levels::Ml),
        capped(Levels::Sl),
        capped(Levels::N(2)),
        capped(Levels::Auto),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn random_dags_compile_to_valid_equivalent_hierarchies(d in dag()) {
        let scene = build(&d);
        prop_assume!(scene.stats().flattened_instances < 3000);
        let source = flatten_source(&scene);
        let mut source_tris = None;
        for opts in modes() {
            let (c, captured) = compile_capturing(&scene, &opts);
            if c.report.baked_prototypes > 0 {
                // Baked copies live in the vertices: the same triangles, not placements.
                let want = source_tris.get_or_insert_with(|| source_triangles(&scene));
                assert_same_triangles(want, &compiled_triangles(&scene, &c, &captured));
            } else {
                assert_same_placements(&source, &flatten_compiled(&c.view(), 0));
            }
            prop_assert_eq!(c.report.flattened_instances, scene.stats().flattened_instances);
            if let Levels::N(n) = opts.levels {
                if opts.max_instances_per_tlas > 1000 {
                    prop_assert!(c.report.tlas_levels <= n);
                }
            }
        }
    }

    #[test]
    fn subsets_keep_exactly_their_root_edges(d in dag()) {
        let scene = build(&d);
        prop_assume!(scene.stats().flattened_instances < 3000);
        let el = Scene::MAIN_ELEMENT;
        let opts = CompileOptions { subset: Some(vec![el]), ..Default::default() };
        let c = compile_ok(&scene, &opts);
        // Expected: the source flattening minus what hangs off other elements' root items.
        let mut b = 0usize;
        let root_meshes = scene
            .meshes_of(Scene::ROOT)
            .iter()
            .zip(scene.root_mesh_elements())
            .filter(|(_, e)| **e == el)
            .count();
        for (e, tag) in scene.edges(Scene::ROOT).iter().zip(scene.root_edge_elements()) {
            if *tag == el && crate::xform::is_invertible(&e.parent_from_child) {
                b += placements_below(&scene, e.child);
            }
        }
        prop_assert_eq!(flatten_compiled(&c.view(), 0).len(), b + root_meshes);
    }
}

fn placements_below(scene: &Scene, p: PrototypeId) -> usize {
    scene.meshes_of(p).len()
        + scene
            .edges(p)
            .iter()
            .filter(|e| crate::xform::is_invertible(&e.parent_from_child))
            .map(|e| placements_below(scene, e.child))
            .sum::<usize>()
}
