use super::*;

fn rgba(r: u8, g: u8, b: u8) -> u32 {
    u32::from(r) | u32::from(g) << 8 | u32::from(b) << 16 | 0xff << 24
}

#[test]
fn faces_tables_and_samples() {
    let faces = vec![
        PtexFace {
            ulog2: 0,
            vlog2: 0,
            texels: vec![rgba(255, 0, 0)],
        },
        PtexFace {
            ulog2: 1,
            vlog2: 0,
            texels: vec![rgba(0, 255, 0), rgba(0, 0, 255)],
        },
    ];
    let meshes = vec![
        (7, MeshFaces::Table(vec![1 | PTEX_SECOND_HALF, 0])),
        (3, MeshFaces::Quads),
    ];
    let mut words = vec![9u32; 5];
    let enc = encode(&faces, &meshes);
    words.extend_from_slice(&enc);
    let tex = record(5, enc.len(), faces.len());
    assert!(is_ptex(&tex));
    assert_eq!(tex.texel_count(), enc.len() as u64);
    assert_eq!(ptex_face(&tex, &words, 7, 0), (1, true));
    assert_eq!(ptex_face(&tex, &words, 7, 1), (0, false));
    assert_eq!(ptex_face(&tex, &words, 3, 5), (2, true));
    assert_eq!(ptex_face(&tex, &words, 4, 5), (5, false));
    let red = sample_ptex(&tex, &words, 0, [0.3, 0.9]).unwrap();
    assert_eq!(red, [1.0, 0.0, 0.0, 1.0]);
    // Face 1: green on the left texel's centre, blue on the right's, clamped beyond.
    let left = sample_ptex(&tex, &words, 1, [0.25, 0.5]).unwrap();
    let right = sample_ptex(&tex, &words, 1, [1.0, 0.5]).unwrap();
    assert_eq!((left[1], left[2]), (1.0, 0.0));
    assert_eq!((right[1], right[2]), (0.0, 1.0));
    assert_eq!(sample_ptex(&tex, &words, 2, [0.5; 2]), None);
    assert_eq!(default_face_uv([1.0, 0.0, 0.0], false), [0.0, 0.0]);
    assert_eq!(default_face_uv([0.0, 0.0, 1.0], false), [1.0, 1.0]);
    assert_eq!(default_face_uv([0.0, 0.0, 1.0], true), [0.0, 1.0]);
    assert_eq!(default_face_uv([0.0, 1.0, 0.0], true), [1.0, 1.0]);
}
