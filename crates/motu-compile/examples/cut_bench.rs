//! Times the import's cut of one large mesh (`partition::partition_mesh`) and the proxy boxes of
//! its clusters (`proxy_boxes::boxes_from_meshes`, as `motu-import`'s cutting thread makes
//! them), on a synthetic terrain grid, and prints a hash of everything they made so that two
//! builds can be compared for equal output (issue 48 item 1).
//!
//! `cargo run --release -p motu-compile --example cut_bench -- [GRID] [ROUNDS] [THREADS]`
//! (GRID² quads, two triangles each; default 1024, 3 rounds, 1 thread: callgrind-friendly).

use motu_compile::partition::{partition_mesh, Cluster};
use motu_compile::proxy_boxes::{boxes_from_meshes, fan};
use motu_scene::MeshData;
use std::hash::Hasher;
use std::time::Instant;

/// A GRID × GRID terrain: jittered heights, vertices row by row, two triangles a quad.
fn terrain(grid: u32) -> MeshData {
    let n = grid + 1;
    let mut state = 0x1234_5678u32;
    let mut rnd = move || {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        (state >> 8) as f32 / (1u32 << 24) as f32
    };
    let mut positions = Vec::with_capacity((n * n) as usize);
    let mut normals = Vec::with_capacity((n * n) as usize);
    for y in 0..n {
        for x in 0..n {
            let h = (x as f32 * 0.01).sin() * (y as f32 * 0.013).cos() * 20.0 + rnd() * 0.1;
            positions.push([x as f32 * 0.5, h, y as f32 * 0.5]);
            normals.push([0.0, 1.0, 0.0]);
        }
    }
    let mut indices = Vec::with_capacity((6 * grid * grid) as usize);
    for y in 0..grid {
        for x in 0..grid {
            let v = y * n + x;
            indices.extend_from_slice(&[v, v + 1, v + n, v + 1, v + n + 1, v + n]);
        }
    }
    MeshData {
        positions,
        normals: Some(normals),
        uvs: None,
        indices,
    }
}

fn main() {
    let args: Vec<u32> = std::env::args()
        .skip(1)
        .map(|a| a.parse().unwrap())
        .collect();
    let grid = args.first().copied().unwrap_or(1024);
    let rounds = args.get(1).copied().unwrap_or(3);
    let threads = args.get(2).copied().unwrap_or(1) as usize;
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build_global()
        .unwrap();
    let mesh = terrain(grid);
    let bound = 1u32 << 16;
    for round in 0..rounds {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        let t = Instant::now();
        let mut clusters: Vec<Cluster> = Vec::new();
        partition_mesh(&mesh, bound, &mut |c: Cluster| -> Result<(), ()> {
            clusters.push(c);
            Ok(())
        })
        .unwrap();
        let cut_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let mut boxes = 0usize;
        for c in &clusters {
            let f = fan(c.data.triangle_count() as u32) as usize;
            let b = boxes_from_meshes(&[(&c.data.positions[..], &c.data.indices[..])], f);
            boxes += b.len();
            for x in b.iter().flatten() {
                h.write_u32(x.to_bits());
            }
        }
        let boxes_ms = t.elapsed().as_secs_f64() * 1e3;
        for c in &clusters {
            h.write(bytemuck::cast_slice(&c.data.positions));
            h.write(bytemuck::cast_slice(
                c.data.normals.as_deref().unwrap_or(&[]),
            ));
            h.write(bytemuck::cast_slice(&c.data.indices));
            h.write(bytemuck::cast_slice(&c.primitive_map));
            h.write(bytemuck::bytes_of(&c.bounds.min));
            h.write(bytemuck::bytes_of(&c.bounds.max));
        }
        println!(
            "round {round}: {} triangles, {} clusters, {boxes} boxes: cut {cut_ms:.1} ms, boxes {boxes_ms:.1} ms, hash {:016x}",
            mesh.triangle_count(),
            clusters.len(),
            h.finish()
        );
    }
}
