use super::*;

#[test]
fn blob_round_trip() {
    let m = MeshData {
        positions: vec![[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.0]],
        normals: Some(vec![[0.0, 0.0, 1.0]; 3]),
        uvs: None,
        indices: vec![0, 1, 2],
    };
    let l = MeshBlobLayout::of(&m);
    assert_eq!((l.indices, l.normals, l.len), (48, 64, 100));
    assert_eq!(l.decode(&l.encode(&m)).unwrap(), m);
    assert!(l.decode(&[0u8; 10]).is_err());
    let with_uvs = MeshData {
        uvs: Some(vec![[0.0, 1.0], [0.5, 0.5], [1.0, 0.0]]),
        ..m.clone()
    };
    let l = MeshBlobLayout::of(&with_uvs);
    assert_eq!((l.normals, l.uvs, l.len), (64, 112, 136));
    assert_eq!(l.decode(&l.encode(&with_uvs)).unwrap(), with_uvs);
    assert_eq!(l.decode_primitive_map(&l.encode(&m)).unwrap(), None);
}

#[test]
fn mapped_blob_round_trip() {
    let m = MeshData {
        positions: vec![[0.0, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.0]],
        normals: None,
        uvs: None,
        indices: vec![0, 1, 2, 2, 1, 0],
    };
    let map = [7u32, 3];
    let l = MeshBlobLayout::of_mapped(&m, Some(&map));
    // positions 36 → 48, indices 24 → 80 (normals: none) → map at 80, 8 bytes.
    assert_eq!(
        (l.indices, l.normals, l.primitive_map, l.len),
        (48, 80, 80, 88)
    );
    let blob = l.encode_mapped(&m, Some(&map));
    assert_eq!(l.decode(&blob).unwrap(), m);
    assert_eq!(l.decode_primitive_map(&blob).unwrap(), Some(map.to_vec()));
    assert!(l.decode_primitive_map(&blob[..84]).is_err());
}

/// A blob pushed onto a buffer (the arrays in offset order, zeros between) is the indexed
/// encoding's bytes, after what the buffer held, with or without normals, uvs and a map.
#[test]
fn blobs_pushed_in_order_equal_indexed_ones() {
    let m = MeshData {
        positions: vec![[0.5, 1.0, 2.0], [3.0, 4.0, 5.0], [6.0, 7.0, 8.0], [9.0; 3]],
        normals: None,
        uvs: None,
        indices: vec![0, 1, 2, 2, 1, 3, 3, 0, 1],
    };
    let with_n = MeshData {
        normals: Some(vec![[0.0, 0.0, 1.0]; 4]),
        ..m.clone()
    };
    let with_uv = MeshData {
        uvs: Some(vec![[0.25, 0.75]; 4]),
        ..with_n.clone()
    };
    let map = [5u32, 6, 7];
    for mesh in [&m, &with_n, &with_uv] {
        for pm in [None, Some(&map[..])] {
            let l = MeshBlobLayout::of_mapped(mesh, pm);
            let mut out = vec![0xAB; 5];
            l.encode_mapped_onto(mesh, pm, &mut out);
            assert_eq!(out[..5], [0xAB; 5]);
            assert_eq!(out[5..], l.encode_mapped(mesh, pm)[..]);
        }
    }
}
