//! Scene fixtures and the multiset comparison of flattened placements.

use crate::{compile, flatten_compiled_records, flatten_source, CompileOptions, CompiledScene};
use motu_scene::{MeshData, MeshId, Scene, SceneBuilder, Transform34};
use std::collections::{BTreeMap, HashMap};

/// Each mesh record's data and primitive map, as the compiler handed them to its sink.
pub type Captured = HashMap<u32, (MeshData, Option<Vec<u32>>)>;

/// An `n`×`n`-quad grid in the XY plane with a gentle bump (so it is not trivially planar for
/// the simplifier's error metric, but smooth).
pub fn grid_mesh(n: u32, normals: bool) -> MeshData {
    let mut positions = Vec::new();
    for y in 0..=n {
        for x in 0..=n {
            let (u, v) = (x as f32 / n as f32, y as f32 / n as f32);
            positions.push([u, v, 0.01 * (u * 3.0).sin() * (v * 2.0).cos()]);
        }
    }
    let mut indices = Vec::new();
    let w = n + 1;
    for y in 0..n {
        for x in 0..n {
            let a = y * w + x;
            indices.extend_from_slice(&[a, a + 1, a + w + 1, a, a + w + 1, a + w]);
        }
    }
    let count = positions.len();
    MeshData {
        positions,
        normals: normals.then(|| vec![[0.0, 0.0, 1.0]; count]),
        uvs: None,
        indices,
    }
}

pub fn triangle() -> MeshData {
    MeshData {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.5]],
        indices: vec![0, 1, 2],
        ..Default::default()
    }
}

pub fn builder() -> SceneBuilder {
    SceneBuilder::default()
}

pub fn compile_ok(scene: &Scene, opts: &CompileOptions) -> CompiledScene {
    let mut sink = |_: u32, _: &MeshData, _: Option<&[u32]>| Ok(());
    validated(compile(scene, opts, &mut sink).unwrap(), opts)
}

/// `c` after `validate_with` under `opts`' limits (panics with the report when invalid).
fn validated(c: CompiledScene, opts: &CompileOptions) -> CompiledScene {
    crate::validate_with(
        &c.view(),
        &crate::Limits {
            max_instances_per_tlas: opts.effective_instance_cap().min(u32::MAX as u64) as u32,
            max_primitives_per_blas: opts.max_primitives_per_blas,
        },
    )
    .unwrap_or_else(|e| panic!("invalid hierarchy: {e}\n{:#?}", c.report));
    c
}

/// [`compile_ok`] keeping what the sink received.
pub fn compile_capturing(scene: &Scene, opts: &CompileOptions) -> (CompiledScene, Captured) {
    let mut captured = Captured::new();
    let mut sink = |r: u32, d: &MeshData, map: Option<&[u32]>| {
        captured.insert(r, (d.clone(), map.map(<[u32]>::to_vec)));
        Ok(())
    };
    let c = validated(compile(scene, opts, &mut sink).unwrap(), opts);
    (c, captured)
}

/// World-space triangles keyed by (source mesh, source triangle).
type Triangles = BTreeMap<(u32, u32), Vec<[[f32; 3]; 3]>>;

fn place(t: &Transform34, p: [f32; 3]) -> [f32; 3] {
    t.to_mat4().transform_point3(glam::Vec3::from(p)).to_array()
}

/// Every source placement's triangles in world space.
pub fn source_triangles(scene: &Scene) -> Triangles {
    let mut out = Triangles::new();
    for (t, m) in flatten_source(scene) {
        let d = scene.mesh_data(m).unwrap();
        for (k, tri) in d.indices.chunks_exact(3).enumerate() {
            let v = [0, 1, 2].map(|i| place(&t, d.positions[tri[i] as usize]));
            out.entry((m.0, k as u32)).or_default().push(v);
        }
    }
    out
}

/// Every compiled placement's triangles in world space, named through the records' maps (a
/// record the sink never saw is its source mesh, whole).
pub fn compiled_triangles(scene: &Scene, c: &CompiledScene, captured: &Captured) -> Triangles {
    let view = c.view();
    let mut out = Triangles::new();
    for (t, r) in flatten_compiled_records(&view, 0) {
        let source = view.meshes[r as usize].source_mesh;
        let whole;
        let (d, map) = match captured.get(&r) {
            Some((d, map)) => (d, map),
            None => {
                whole = (scene.mesh_data(MeshId(source)).unwrap(), None);
                (&whole.0, &whole.1)
            }
        };
        for (k, tri) in d.indices.chunks_exact(3).enumerate() {
            let prim = map.as_ref().map_or(k as u32, |m| m[k]);
            let v = [0, 1, 2].map(|i| place(&t, d.positions[tri[i] as usize]));
            out.entry((source, prim)).or_default().push(v);
        }
    }
    out
}

/// The same triangles on both sides, per source triangle, as multisets: vertices within a
/// tolerance, in any rotation or winding (a baked mirrored copy flips its winding back).
pub fn assert_same_triangles(source: &Triangles, compiled: &Triangles) {
    let keys = |t: &Triangles| t.keys().copied().collect::<Vec<_>>();
    assert_eq!(keys(source), keys(compiled), "source triangles differ");
    let same = |a: &[[f32; 3]; 3], b: &[[f32; 3]; 3]| {
        let scale = a
            .iter()
            .chain(b)
            .flatten()
            .fold(1.0f32, |m, v| m.max(v.abs()));
        let near = |p: &[f32; 3], q: &[f32; 3]| (0..3).all(|k| (p[k] - q[k]).abs() <= 1e-4 * scale);
        a.iter().all(|p| b.iter().any(|q| near(p, q)))
            && b.iter().all(|q| a.iter().any(|p| near(p, q)))
    };
    for (key, want) in source {
        let have = &compiled[key];
        assert_eq!(want.len(), have.len(), "copies of source triangle {key:?}");
        let mut used = vec![false; have.len()];
        for w in want {
            let i = (0..have.len())
                .find(|&i| !used[i] && same(w, &have[i]))
                .unwrap_or_else(|| panic!("source triangle {key:?} at {w:?} missing"));
            used[i] = true;
        }
    }
}

fn close(a: &Transform34, b: &Transform34) -> bool {
    let scale = a
        .rows
        .iter()
        .flatten()
        .chain(b.rows.iter().flatten())
        .fold(1.0f32, |m, v| m.max(v.abs()));
    a.rows
        .iter()
        .flatten()
        .zip(b.rows.iter().flatten())
        .all(|(x, y)| (x - y).abs() <= 2e-4 * scale)
}

/// Asserts the two placement lists are equal as multisets (transforms within a tolerance).
pub fn assert_same_placements(source: &[(Transform34, MeshId)], compiled: &[(Transform34, u32)]) {
    assert_eq!(source.len(), compiled.len(), "placement counts differ");
    let key = |t: &Transform34| t.rows[0][3] + 0.37 * t.rows[1][3] + 0.11 * t.rows[2][3];
    let mut a: Vec<(u32, f32, Transform34)> =
        source.iter().map(|(t, m)| (m.0, key(t), *t)).collect();
    let mut b: Vec<(u32, f32, Transform34, bool)> = compiled
        .iter()
        .map(|(t, m)| (*m, key(t), *t, false))
        .collect();
    a.sort_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)));
    b.sort_by(|x, y| x.0.cmp(&y.0).then(x.1.total_cmp(&y.1)));
    for (mesh, k, t) in &a {
        // Candidates: same mesh, key within tolerance; the sorted order bounds the scan.
        let lo = b.partition_point(|x| (x.0, x.1) < (*mesh, k - 1e-2 * (1.0 + k.abs())));
        let found = b[lo..]
            .iter_mut()
            .take_while(|x| x.0 == *mesh && x.1 <= k + 1e-2 * (1.0 + k.abs()))
            .find(|x| !x.3 && close(&x.2, t));
        match found {
            Some(x) => x.3 = true,
            None => panic!("source placement of mesh {mesh} at {t:?} missing from compiled"),
        }
    }
}
