use super::*;
use motu_abi::{BlasRecord, GeometryRecord, MeshRecord, BLAS_AABBS, BLAS_TRIANGLES};
use motu_compile::proxy_boxes::{decode_section, Box6, Stored};
use motu_package::WriterOptions;

/// Mesh `i` of `n` triangles: scattered positions (deterministic), an index out of range.
fn mesh(i: u32, n: u32) -> (Vec<[f32; 3]>, Vec<u32>) {
    let positions = (0..n + 2)
        .map(|v| {
            let t = (v * 7 + i * 13) as f32;
            [
                (t * 0.37).sin() * 10.0 + i as f32,
                (t * 1.3).cos(),
                t * 0.01,
            ]
        })
        .collect();
    let mut indices: Vec<u32> = (0..n)
        .flat_map(|t| [t, (t * 5 + 1) % (n + 2), t + 2])
        .collect();
    indices[4] = u32::MAX;
    (positions, indices)
}

fn le_bytes(words: impl IntoIterator<Item = u32>) -> Vec<u8> {
    words.into_iter().flat_map(u32::to_le_bytes).collect()
}

#[test]
fn boxes_made_a_chunk_at_a_time_equal_the_streamers_bit_for_bit() {
    let dir = tempfile::tempdir().unwrap();
    let options = WriterOptions {
        zstd_level: Some(1),
        ..WriterOptions::default()
    };
    let mut w = PackageWriter::create(dir.path().join("p.motu"), options).unwrap();
    let s = w.open_stream(0, 0);
    let counts = [600u32, 150, 520, 300, 90];
    let mut meshes = Vec::new();
    for (i, &n) in counts.iter().enumerate() {
        let (p, ix) = mesh(i as u32, n);
        let pos = w
            .append(s, &le_bytes(p.iter().flatten().map(|v| v.to_bits())), 16)
            .unwrap();
        let idx = w.append(s, &le_bytes(ix.iter().copied()), 16).unwrap();
        assert_eq!(pos.chunk, idx.chunk);
        meshes.push(MeshRecord {
            vertex_count: p.len() as u32,
            triangle_count: n,
            chunk: pos.chunk.0,
            positions_offset: pos.offset_in_chunk,
            indices_offset: idx.offset_in_chunk,
            ..MeshRecord::default()
        });
        // Chunks of two meshes; the last stays open (read from memory).
        if i % 2 == 1 {
            w.seal_chunk(s).unwrap();
        }
    }
    let geometry = |m: u32| GeometryRecord {
        mesh: m,
        ..GeometryRecord::default()
    };
    let geometries: Vec<GeometryRecord> = [0, 3, 1, 2, 4, 0].into_iter().map(geometry).collect();
    let blas = |kind, base: u32, items: &[u32]| BlasRecord {
        kind,
        item_base: base,
        item_count: items.len() as u32,
        primitive_count: items.iter().map(|&m| counts[m as usize]).sum(),
        bounds_min: [-20.0; 3],
        bounds_max: [20.0; 3],
        ..BlasRecord::default()
    };
    // Across chunks 0 and 1; an AABB BLAS; one mesh; the open chunk's; a mesh shared.
    let blases = vec![
        blas(BLAS_TRIANGLES, 0, &[0, 3]),
        blas(BLAS_AABBS, 0, &[]),
        blas(BLAS_TRIANGLES, 2, &[1]),
        blas(BLAS_TRIANGLES, 3, &[2, 4]),
        blas(BLAS_TRIANGLES, 5, &[0]),
    ];
    let view = HierarchyView {
        blases: &blases,
        geometries: &geometries,
        meshes: &meshes,
        ..HierarchyView::default()
    };
    let reads = std::sync::atomic::AtomicUsize::new(0);
    let mut tables = Vec::new();
    for batch in [1, 2, 8] {
        reads.store(0, std::sync::atomic::Ordering::Relaxed);
        let t = make_table(&view, batch, |c| {
            reads.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            w.read_back_chunk(c)
        })
        .unwrap();
        // Each of the three chunks read once.
        assert_eq!(
            reads.load(std::sync::atomic::Ordering::Relaxed),
            3,
            "batch {batch}"
        );
        tables.push(t);
    }
    assert!(tables.windows(2).all(|t| t[0] == t[1]));
    // Through the section's bytes, against what the streamer makes from each mesh.
    let stored = decode_section(&encode_section(&tables[0])).unwrap();
    assert_eq!(stored.entries.len(), 4);
    for b in [0usize, 2, 3, 4] {
        let f = fan(blases[b].primitive_count) as usize;
        let runtime = blas_boxes(&view, b, f, |m| {
            let r = &meshes[m as usize];
            let (p, i) = mesh(m, r.triangle_count);
            Ok::<_, ()>((p.into(), i.into()))
        });
        let Stored::Valid(boxes) = stored.boxes_of(&view, b) else {
            panic!("BLAS {b}: no valid entry");
        };
        assert_eq!(
            bytemuck_bits(boxes),
            bytemuck_bits(&runtime),
            "BLAS {b} (fan {f})"
        );
        assert!(f > 1 || b == 2, "BLAS {b}: fan {f}");
    }
    assert_eq!(stored.boxes_of(&view, 1), Stored::Absent);
}

fn bytemuck_bits(boxes: &[Box6]) -> Vec<u32> {
    boxes.iter().flatten().map(|v| v.to_bits()).collect()
}
