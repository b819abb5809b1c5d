use super::*;
use glam::{Mat4, Quat, Vec3};

fn quad() -> MeshData {
    MeshData {
        positions: vec![
            [0.0, 0.0, 0.0],
            [1.0, 0.0, 0.0],
            [1.0, 1.0, 0.0],
            [0.0, 1.0, 0.0],
        ],
        normals: None,
        uvs: None,
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

#[test]
fn dag_sharing_counts_paths_not_copies() {
    let mut b = SceneBuilder::default();
    let mat = b.default_material();
    let main = Scene::MAIN_ELEMENT;
    let leaf = b.add_prototype("leaf", main).unwrap();
    b.add_mesh(leaf, "quad", mat, main, &quad()).unwrap();
    let tree = b.add_prototype("tree", main).unwrap();
    for i in 0..3 {
        b.add_instance(
            tree,
            leaf,
            Transform34::from_translation(Vec3::X * i as f32),
            main,
        )
        .unwrap();
    }
    for i in 0..4 {
        b.add_instance(
            b.root(),
            tree,
            Transform34::from_translation(Vec3::Y * i as f32),
            main,
        )
        .unwrap();
    }
    // The root also places a leaf directly: the leaf prototype is shared by two parents.
    b.add_instance(b.root(), leaf, Transform34::IDENTITY, main)
        .unwrap();
    let s = b.finish().unwrap();
    let st = s.stats();
    assert_eq!(st.instances, 3 + 4 + 1);
    assert_eq!(st.flattened_instances, 4 * 3 + 1);
    assert_eq!(st.unique_triangles, 2);
    assert_eq!(st.instanced_triangles, (4 * 3 + 1) * 2);
    assert_eq!(st.max_depth, 2);
    let wb = s.world_bounds();
    assert_eq!(wb.min, [0.0, 0.0, 0.0]);
    assert_eq!(wb.max, [3.0, 4.0, 0.0]);
    assert_eq!(s.mesh_data(MeshId(0)).unwrap(), quad());
}

#[test]
fn interleaved_edges_are_sorted_into_csr_in_import_order() {
    let mut b = SceneBuilder::default();
    let main = Scene::MAIN_ELEMENT;
    let a = b.add_prototype("a", main).unwrap();
    let c = b.add_prototype("c", main).unwrap();
    let t = |x: f32| Transform34::from_translation(Vec3::X * x);
    b.add_instance(b.root(), a, t(1.0), main).unwrap();
    b.add_instance(a, c, t(2.0), main).unwrap();
    b.add_instance(b.root(), c, t(3.0), main).unwrap();
    b.add_instance(a, c, t(4.0), main).unwrap();
    let s = b.finish().unwrap();
    let xs = |p| {
        s.edges(p)
            .iter()
            .map(|e| e.parent_from_child.rows[0][3])
            .collect::<Vec<_>>()
    };
    assert_eq!(xs(s.root()), vec![1.0, 3.0]);
    assert_eq!(xs(a), vec![2.0, 4.0]);
    assert!(xs(c).is_empty());
    assert_eq!(s.root_edge_elements().len(), 2);
}

/// The in-place CSR sort (no second edge table) equals a stable sort by parent, on many
/// parents interleaved pseudo-randomly.
#[test]
fn many_interleaved_edges_sort_in_place_as_a_stable_sort_would() {
    let mut b = SceneBuilder::default();
    let main = Scene::MAIN_ELEMENT;
    let protos: Vec<PrototypeId> = (0..7)
        .map(|i| b.add_prototype(&format!("p{i}"), main).unwrap())
        .collect();
    let leaf = b.add_prototype("leaf", main).unwrap();
    let mut parents = vec![b.root()];
    parents.extend(&protos);
    let mut expected: Vec<(PrototypeId, f32)> = Vec::new();
    let mut x = 12345u32;
    for i in 0..5000 {
        x = x.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        let p = parents[(x >> 16) as usize % parents.len()];
        b.add_instance(
            p,
            leaf,
            Transform34::from_translation(Vec3::X * i as f32),
            main,
        )
        .unwrap();
        expected.push((p, i as f32));
    }
    let s = b.finish().unwrap();
    expected.sort_by_key(|&(p, _)| p.0);
    let got: Vec<(PrototypeId, f32)> = parents
        .iter()
        .flat_map(|&p| {
            s.edges(p)
                .iter()
                .map(move |e| (p, e.parent_from_child.rows[0][3]))
        })
        .collect();
    let mut by_id = got.clone();
    by_id.sort_by_key(|&(p, _)| p.0);
    assert_eq!(by_id, expected);
    assert_eq!(s.all_edges().len(), 5000);
}

#[test]
fn cycles_are_rejected() {
    let mut b = SceneBuilder::default();
    let main = Scene::MAIN_ELEMENT;
    let a = b.add_prototype("a", main).unwrap();
    let c = b.add_prototype("c", main).unwrap();
    b.add_instance(a, c, Transform34::IDENTITY, main).unwrap();
    b.add_instance(c, a, Transform34::IDENTITY, main).unwrap();
    b.add_instance(b.root(), a, Transform34::IDENTITY, main)
        .unwrap();
    let err = b.finish().unwrap_err();
    assert!(matches!(err, SceneError::Cycle { .. }), "{err}");
}

#[test]
fn bounds_through_rotated_instances_use_all_corners() {
    let mut b = SceneBuilder::default();
    let main = Scene::MAIN_ELEMENT;
    let m = b.default_material();
    let p = b.add_prototype("unit", main).unwrap();
    let cube = MeshData {
        positions: vec![[-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], [1.0, -1.0, 1.0]],
        normals: None,
        uvs: None,
        indices: vec![0, 1, 2],
    };
    b.add_mesh(p, "tri", m, main, &cube).unwrap();
    let rot = Transform34::from_mat4(Mat4::from_quat(Quat::from_rotation_y(0.7)));
    b.add_instance(b.root(), p, rot, main).unwrap();
    let s = b.finish().unwrap();
    let expect = s.mesh(MeshId(0)).bounds.transformed(&rot);
    assert_eq!(s.world_bounds(), expect);
    // Conservative: every transformed vertex is inside.
    for v in &cube.positions {
        let q = rot.transform_point(Vec3::from_array(*v));
        assert!(s.world_bounds().contains(&Aabb::from_min_max(q, q), 1e-5));
    }
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let mut b = SceneBuilder::default();
    let main = Scene::MAIN_ELEMENT;
    let m = b.default_material();
    let bad = MeshData {
        positions: vec![[0.0; 3]],
        indices: vec![0, 1, 2],
        ..Default::default()
    };
    assert!(b.add_mesh(b.root(), "bad", m, main, &bad).is_err());
    assert!(b
        .add_instance(b.root(), PrototypeId(99), Transform34::IDENTITY, main)
        .is_err());
    let mut nan = Transform34::IDENTITY;
    nan.rows[0][0] = f32::NAN;
    let p = b.add_prototype("p", main).unwrap();
    assert!(b.add_instance(b.root(), p, nan, main).is_err());
}

/// The same edges added to a heap builder and to one that spills them to a file chunk by
/// chunk, with parents interleaved (`interleave`) or in id order (the file is then the
/// table); returns both scenes.
fn heap_and_spilled(dir: &std::path::Path, n: usize, interleave: bool) -> (Scene, Scene) {
    let build = |spill: bool| {
        let mut b = SceneBuilder::default();
        if spill {
            b.spill_edges_to(dir);
        }
        let main = Scene::MAIN_ELEMENT;
        let other = b.element("other").unwrap();
        let leaf = b.add_prototype("leaf", main).unwrap();
        b.add_mesh(leaf, "quad", b.default_material(), main, &quad())
            .unwrap();
        let groups: Vec<PrototypeId> = (0..5)
            .map(|i| b.add_prototype(&format!("g{i}"), main).unwrap())
            .collect();
        for &g in &groups {
            b.add_instance(b.root(), g, Transform34::IDENTITY, main)
                .unwrap();
        }
        let mut x = 777u32;
        for i in 0..n {
            x = x.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            // Runs of a few edges of one parent, as a scene file's blocks make them.
            let g = if interleave {
                (x >> 16) as usize % 6
            } else {
                i * 6 / n
            };
            let t = Transform34::from_translation(Vec3::new(i as f32, g as f32, 0.0));
            if g == 0 {
                let el = if i % 3 == 0 { other } else { main };
                b.add_instance(b.root(), leaf, t, el).unwrap();
            } else {
                b.add_instance(groups[g - 1], leaf, t, main).unwrap();
            }
        }
        b.finish().unwrap()
    };
    (build(false), build(true))
}

/// A spilling builder's scene reads exactly as a heap builder's: every prototype's edges in
/// CSR order (interleaved parents sorted through a second file), the root's elements, the
/// bounds and counts; the walks read the same edges; the files have no names.
#[test]
fn spilled_edges_read_as_heap_ones() {
    let dir = tempfile::tempdir().unwrap();
    let n = 3 * SPILL_CHUNK_EDGES + 123;
    for interleave in [true, false] {
        let (heap, spilled) = heap_and_spilled(dir.path(), n, interleave);
        assert!(!heap.edges_in_file());
        assert!(spilled.edges_in_file(), "interleave {interleave}");
        assert_eq!(heap.all_edges().len(), n + 5);
        assert_eq!(heap.all_edges(), spilled.all_edges());
        assert_eq!(heap.prototypes(), spilled.prototypes());
        assert_eq!(heap.root_edge_elements(), spilled.root_edge_elements());
        assert_eq!(heap.stats(), spilled.stats());
        assert_eq!(heap.world_bounds(), spilled.world_bounds());
        for p in spilled.prototype_ids() {
            let walked: Vec<Edge> = spilled.walk_edges(p).copied().collect();
            assert_eq!(walked, spilled.edges(p));
        }
        spilled.release_edge_pages().unwrap();
        assert_eq!(heap.all_edges(), spilled.all_edges());
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
}

/// Fewer edges than a chunk stay on the heap (the import moves them after parsing).
#[test]
fn a_spilling_builder_under_a_chunk_keeps_its_edges_on_the_heap() {
    let dir = tempfile::tempdir().unwrap();
    let (heap, spilled) = heap_and_spilled(dir.path(), 1000, true);
    assert!(!spilled.edges_in_file());
    assert_eq!(heap.all_edges(), spilled.all_edges());
}

/// A spill directory that cannot hold the file is an error naming it when the first chunk is
/// written, not a panic.
#[test]
fn an_unwritable_spill_directory_is_an_error() {
    let mut b = SceneBuilder::default();
    let missing = std::path::Path::new("/nonexistent/motu-spill");
    b.spill_edges_to(missing);
    let leaf = b.add_prototype("leaf", Scene::MAIN_ELEMENT).unwrap();
    let err = (0..SPILL_CHUNK_EDGES)
        .map(|_| b.add_instance(b.root(), leaf, Transform34::IDENTITY, Scene::MAIN_ELEMENT))
        .find_map(Result::err)
        .expect("the chunk's write fails");
    match err {
        SceneError::EdgeFile { dir, source } => {
            assert_eq!(dir, missing);
            assert_eq!(source.kind(), std::io::ErrorKind::NotFound);
        }
        other => panic!("{other}"),
    }
}

/// A mesh given away is stored as one lent: the same record, the same data back, and a bad
/// one still refused before the store sees it.
#[test]
fn owned_meshes_are_stored_as_lent_ones() {
    let mut b = SceneBuilder::default();
    let (m, main) = (b.default_material(), Scene::MAIN_ELEMENT);
    let lent = b.add_mesh(b.root(), "quad", m, main, &quad()).unwrap();
    let owned = b.add_mesh_owned(b.root(), "quad", m, main, quad()).unwrap();
    let bad = MeshData {
        positions: vec![[0.0; 3]],
        indices: vec![0, 1, 2],
        ..Default::default()
    };
    assert!(b.add_mesh_owned(b.root(), "bad", m, main, bad).is_err());
    let scene = b.finish().unwrap();
    assert_eq!(scene.meshes().len(), 2);
    let (a, o) = (scene.mesh(lent), scene.mesh(owned));
    assert_eq!(
        (a.vertex_count, a.triangle_count, a.bounds, a.has_normals),
        (o.vertex_count, o.triangle_count, o.bounds, o.has_normals)
    );
    let g = scene.geometry();
    assert_eq!(g.load(owned, o.location).unwrap(), quad());
    assert_eq!(g.load(lent, a.location).unwrap(), quad());
    assert_ne!(a.location, o.location);
}
