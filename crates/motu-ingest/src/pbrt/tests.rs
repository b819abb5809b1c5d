use super::*;
use motu_scene::InMemoryGeometry;

/// World-space triangles of every mesh reachable from the root, sorted.
fn flatten(scene: &Scene) -> Vec<[[f32; 3]; 3]> {
    fn walk(scene: &Scene, proto: PrototypeId, world: Mat4, out: &mut Vec<[[f32; 3]; 3]>) {
        for &mesh in scene.meshes_of(proto) {
            let data = scene.mesh_data(mesh).expect("in-memory mesh");
            for t in data.indices.chunks_exact(3) {
                out.push(std::array::from_fn(|k| {
                    let p = Vec3::from_array(data.positions[t[k] as usize]);
                    world.transform_point3(p).to_array()
                }));
            }
        }
        for edge in scene.edges(proto) {
            walk(
                scene,
                edge.child,
                world * edge.parent_from_child.to_mat4(),
                out,
            );
        }
    }
    let mut out = Vec::new();
    walk(scene, scene.root(), Mat4::IDENTITY, &mut out);
    out.sort_by(|a, b| a.partial_cmp(b).expect("finite"));
    out
}

#[test]
fn include_used_twice_is_one_prototype_with_two_edges() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(
        dir.path().join("copy.pbrt"),
        r#"AttributeBegin
  Translate 0 0 2
  Rotate 30 0 1 0
  Shape "trianglemesh" "point P" [0 0 0 1 0 0 0 1 0] "integer indices" [0 1 2]
AttributeEnd
Shape "trianglemesh" "point P" [0 0 0 0 0 1 1 0 0] "integer indices" [0 1 2]
"#,
    )
    .unwrap();
    let main = dir.path().join("main.pbrt");
    std::fs::write(
        &main,
        r#"WorldBegin
AttributeBegin
  Translate 10 0 0
  Include "copy.pbrt"
AttributeEnd
AttributeBegin
  Rotate 90 0 0 1
  Scale 2 2 2
  Include "copy.pbrt"
AttributeEnd
"#,
    )
    .unwrap();
    let options = IngestOptions::default();
    let ingest = |share| {
        ingest_pbrt_with(&main, &options, Box::new(InMemoryGeometry::new()), share)
            .unwrap()
            .0
    };
    let (shared, copied) = (ingest(true), ingest(false));
    // Root plus the file's prototype; two edges from the root; the meshes stored once.
    assert_eq!(shared.prototypes().len(), 2);
    assert_eq!(shared.edges(shared.root()).len(), 2);
    assert!(shared.meshes_of(shared.root()).is_empty());
    let proto = shared.edges(shared.root())[0].child;
    assert_eq!(shared.meshes_of(proto).len(), 2);
    assert_eq!(copied.prototypes().len(), 1);
    assert_eq!(copied.meshes_of(copied.root()).len(), 4);
    // Flattening both gives the same world-space triangles.
    let (a, b) = (flatten(&copied), flatten(&shared));
    assert_eq!(a.len(), 4);
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        for k in 0..3 {
            let d = Vec3::from_array(x[k]) - Vec3::from_array(y[k]);
            assert!(d.length() < 1e-4, "{x:?} vs {y:?}");
        }
    }
}
