use super::*;
use motu_abi::{BlasRecord, GeometryRecord, MeshRecord, BLAS_AABBS, BLAS_TRIANGLES};
use motu_compile::proxy_boxes::{
    blas_boxes, decode_section, push_triangle_boxes, Box6, Stored, TriangleBox,
};
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
        let t = make_table(&view, batch, &HashMap::new(), |c, buf| {
            reads.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            w.read_back_chunk_into(c, buf)
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
    // A BLAS of one cluster takes the boxes made as it was cut: the same bits.
    let cut = |m: u32, triangle_count: u32, boxes: Vec<Box6>| {
        let r = &meshes[m as usize];
        let k = crate::precut::ClusterBoxes {
            chunk: r.chunk,
            vertex_count: r.vertex_count,
            triangle_count,
            boxes,
        };
        HashMap::from([(m, k)])
    };
    let (p, i) = mesh(1, counts[1]);
    let made =
        motu_compile::proxy_boxes::boxes_from_meshes(&[(&p[..], &i[..])], fan(counts[1]) as usize);
    let t = make_table(&view, 2, &cut(1, counts[1], made.clone()), |c, buf| {
        w.read_back_chunk_into(c, buf)
    })
    .unwrap();
    assert_eq!(t, tables[0]);
    // Taken, not made again (other boxes show it); not taken when made for other counts.
    let other = vec![[7.0f32; 6]; made.len()];
    let t = make_table(&view, 2, &cut(1, counts[1], other.clone()), |c, buf| {
        w.read_back_chunk_into(c, buf)
    })
    .unwrap();
    assert_eq!(
        t.boxes[t.entries[1].first_box as usize..][..made.len()],
        other[..]
    );
    let t = make_table(&view, 2, &cut(1, counts[1] + 1, other), |c, buf| {
        w.read_back_chunk_into(c, buf)
    })
    .unwrap();
    assert_eq!(t, tables[0]);
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

#[test]
fn a_mesh_read_in_place_and_one_copied_out_of_unaligned_bytes_give_the_same_triangles() {
    let (p, ix) = mesh(3, 200);
    let mut raw = le_bytes(p.iter().flatten().map(|v| v.to_bits()));
    let indices_offset = raw.len() as u64;
    raw.extend(le_bytes(ix.iter().copied()));
    let record = |shift: u64| MeshRecord {
        vertex_count: p.len() as u32,
        triangle_count: 200,
        positions_offset: shift,
        indices_offset: indices_offset + shift,
        ..MeshRecord::default()
    };
    // The same bytes one byte further on: no longer 4-aligned, so copied out.
    let mut shifted = vec![0u8];
    shifted.extend_from_slice(&raw);
    let view_of = |meshes: &[MeshRecord]| -> Option<Vec<TriangleBox>> {
        let view = HierarchyView {
            meshes,
            ..HierarchyView::default()
        };
        let bytes = if meshes[0].positions_offset == 0 {
            &raw
        } else {
            &shifted
        };
        let (p, i) = mesh_slices(&view, 0, bytes)?;
        // Borrowed where the bytes are 4-aligned, copied out where not.
        assert_eq!(
            matches!((&p, &i), (Cow::Borrowed(_), Cow::Borrowed(_))),
            meshes[0].positions_offset == 0
        );
        let mut tris = Vec::new();
        push_triangle_boxes(&p, &i, &mut tris);
        Some(tris)
    };
    let in_place = view_of(&[record(0)]).unwrap();
    let copied = view_of(&[record(1)]).unwrap();
    // The in-place read is the one taken for `raw` (4-aligned), the copy for `shifted`.
    assert!(bytemuck::try_cast_slice::<u8, u32>(&raw).is_ok());
    assert!(bytemuck::try_cast_slice::<u8, u32>(&shifted[1..]).is_err());
    // An index out of range drops only its vertex: every triangle keeps a box.
    assert_eq!(in_place.len(), 200);
    assert_eq!(in_place, copied);
    let mut expected = Vec::new();
    push_triangle_boxes(&p, &ix, &mut expected);
    assert_eq!(in_place, expected);
    // Arrays that do not fit the chunk's bytes: unreadable.
    let mut long = record(0);
    long.triangle_count = 10_000;
    assert_eq!(view_of(&[long]), None);
}

/// A pbrt `trianglemesh` of an `n` × `m` grid of unit quads at `x0` (their centroids tie along
/// both axes of the grid: the median splits fall inside runs of equal keys).
fn grid_shape(n: u32, m: u32, x0: f32) -> String {
    let mut p = String::new();
    for j in 0..=m {
        for i in 0..=n {
            let (x, z) = (x0 + i as f32, j as f32);
            p += &format!("{x} {} {z} ", 0.25 * (x * 0.3).sin());
        }
    }
    let mut ix = String::new();
    for j in 0..m {
        for i in 0..n {
            let v = j * (n + 1) + i;
            ix += &format!(
                "{} {} {} {} {} {} ",
                v,
                v + 1,
                v + n + 1,
                v + 1,
                v + n + 2,
                v + n + 1
            );
        }
    }
    format!("Shape \"trianglemesh\" \"point3 P\" [{p}] \"integer indices\" [{ix}]\n")
}

#[test]
fn an_imported_packages_stored_boxes_equal_the_boxes_made_from_its_meshes() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.pbrt");
    let text = format!(
        "WorldBegin\nObjectBegin \"rocks\"\n{}{}{}ObjectEnd\n\
         AttributeBegin\nTranslate 0 0 5\nObjectInstance \"rocks\"\nAttributeEnd\n\
         AttributeBegin\nTranslate 3 0 5\nObjectInstance \"rocks\"\nAttributeEnd\n{}",
        grid_shape(12, 9, 0.0),
        grid_shape(5, 30, 20.0),
        grid_shape(8, 3, 40.0),
        grid_shape(100, 100, -150.0),
    );
    std::fs::write(&scene, text).unwrap();
    // The automatic bound (the large grid cut while parsing), a given one, compressed chunks.
    let runs = [(None, None), (Some(8192), Some(1))];
    for (bound, zstd) in runs {
        let out = dir.path().join("scene.motu");
        let o = crate::ImportOptions {
            max_blas_triangles: bound,
            zstd_level: zstd,
            chunk_bytes: 1 << 16,
            ..Default::default()
        };
        crate::import(&scene, &out, &o).unwrap();
        let pkg = motu_pack::ScenePackage::open(&out).unwrap();
        let view = pkg.view().unwrap();
        let stored = decode_section(pkg.stored_proxy_boxes().unwrap().unwrap()).unwrap();
        let (mut checked, mut joined, mut widest) = (0, 0, 0);
        for b in (0..view.blases.len()).filter(|&b| has_boxes(&view.blases[b])) {
            let f = fan(view.blases[b].primitive_count);
            let made = blas_boxes(&view, b, f as usize, |m| pkg.mesh_slices(m));
            let Stored::Valid(boxes) = stored.boxes_of(&view, b) else {
                panic!("bound {bound:?}: BLAS {b} has no valid stored entry");
            };
            assert_eq!(bytemuck_bits(boxes), bytemuck_bits(&made), "BLAS {b}");
            checked += 1;
            joined += usize::from(view.blases[b].item_count > 1);
            widest = widest.max(f);
        }
        assert_eq!(checked, stored.entries.len(), "bound {bound:?}");
        // The scene reaches the paths it is for: several meshes in one BLAS, fans over 2.
        assert!(
            joined > 0 && widest >= 4,
            "bound {bound:?}: {joined} joined, fan {widest}"
        );
        std::fs::remove_file(&out).unwrap();
    }
}

#[test]
fn the_read_back_batch_is_bounded_by_bytes_and_threads() {
    let mib = 1u64 << 20;
    // The default bound: four 64 MiB chunks, whatever the pool (main read 16 at 16 threads).
    assert_eq!(
        readback_batch(16, DEFAULT_PROXY_READBACK_BYTES, 64 * mib),
        4
    );
    assert_eq!(
        readback_batch(64, DEFAULT_PROXY_READBACK_BYTES, 64 * mib),
        4
    );
    // A small pool still reads one chunk per thread, at least two.
    assert_eq!(readback_batch(3, DEFAULT_PROXY_READBACK_BYTES, 64 * mib), 3);
    assert_eq!(readback_batch(1, DEFAULT_PROXY_READBACK_BYTES, 64 * mib), 2);
    // Small chunks: the thread count (at most 16) bounds it.
    assert_eq!(readback_batch(16, DEFAULT_PROXY_READBACK_BYTES, mib), 16);
    assert_eq!(readback_batch(32, DEFAULT_PROXY_READBACK_BYTES, mib), 16);
    // A bound under two chunks still reads two; 1 GiB gives main's batch back.
    assert_eq!(readback_batch(16, 0, 64 * mib), 2);
    assert_eq!(readback_batch(16, 1 << 30, 64 * mib), 16);
    assert_eq!(readback_batch(16, u64::MAX, 0), 16);
}
