//! Compile passes on a synthetic 1M-edge graph: 1,000 clusters of 1,000 leaf placements each
//! (instance lists), placed 1,000 times under the root (PIs); and the same flattened (`sl`,
//! 1M leaf instances in one TLAS, split under a 2^16 cap).

use criterion::{criterion_group, criterion_main, Criterion};
use motu_compile::{compile, CompileOptions, Levels};
use motu_scene::{MeshData, Scene, SceneBuilder, Transform34};
use std::hint::black_box;

fn synthetic(clusters: u32, per_cluster: u32, leaves: u32) -> Scene {
    let mut b = SceneBuilder::default();
    let (m, main) = (b.default_material(), Scene::MAIN_ELEMENT);
    let tri = MeshData {
        positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
        indices: vec![0, 1, 2],
        ..Default::default()
    };
    let leaf_ids: Vec<_> = (0..leaves)
        .map(|i| {
            let p = b.add_prototype(&format!("leaf{i}"), main).unwrap();
            b.add_mesh(p, "tri", m, main, &tri).unwrap();
            p
        })
        .collect();
    let mut state = 1u32;
    let mut rnd = move || {
        state = state.wrapping_mul(1664525).wrapping_add(1013904223);
        (state >> 8) as f32 / (1u32 << 24) as f32
    };
    let at = |x: f32, y: f32, z: f32| Transform34::from_translation(glam::Vec3::new(x, y, z));
    for c in 0..clusters {
        let cluster = b.add_prototype(&format!("cluster{c}"), main).unwrap();
        for _ in 0..per_cluster {
            let leaf = leaf_ids[(rnd() * leaves as f32) as usize % leaves as usize];
            b.add_instance(cluster, leaf, at(rnd() * 50.0, rnd() * 50.0, rnd()), main)
                .unwrap();
        }
        b.add_instance(
            b.root(),
            cluster,
            at(rnd() * 1000.0, rnd() * 1000.0, 0.0),
            main,
        )
        .unwrap();
    }
    b.finish().unwrap()
}

fn bench(c: &mut Criterion) {
    let scene = synthetic(1000, 1000, 1000);
    let mut g = c.benchmark_group("compile_1M_edges");
    g.sample_size(10);
    for (name, opts) in [
        ("ml", CompileOptions::default()),
        (
            "sl_split_65535",
            CompileOptions {
                levels: Levels::Sl,
                max_instances_per_tlas: 65_535,
                ..Default::default()
            },
        ),
    ] {
        g.bench_function(name, |b| {
            b.iter(|| {
                let mut sink = |_: u32, _: &MeshData, _: Option<&[u32]>| Ok(());
                black_box(compile(&scene, &opts, &mut sink).unwrap())
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
