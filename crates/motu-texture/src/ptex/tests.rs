use super::*;

fn face(ulog2: u8, vlog2: u8, enc: Encoding, px: impl Fn(usize, usize) -> [u8; 3]) -> WriteFace {
    let mut data = Vec::new();
    for y in 0..1usize << vlog2 {
        for x in 0..1usize << ulog2 {
            data.extend_from_slice(&px(x, y));
        }
    }
    WriteFace {
        ulog2,
        vlog2,
        data,
        encoding: enc,
    }
}

#[test]
fn every_encoding_reads_back() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.ptx");
    let grad = |x: usize, y: usize| [(x * 16) as u8, (y * 16) as u8, 7];
    let faces = vec![
        face(0, 0, Encoding::Constant, |_, _| [200, 10, 30]),
        face(3, 2, Encoding::Zipped, grad),
        face(2, 3, Encoding::DiffZipped, grad),
        face(4, 3, Encoding::Tiled(2, 1), grad),
        face(2, 2, Encoding::Constant, |_, _| [1, 2, 3]),
    ];
    write(&path, DataType::U8, 3, None, 1, &faces).unwrap();
    let img = parse(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!((img.channels, img.alpha, img.faces.len()), (3, None, 5));
    for (f, got) in faces.iter().zip(&img.faces) {
        // A constant face reads as its one pixel.
        let (res, bytes) = if f.encoding == Encoding::Constant {
            ((0, 0), &f.data[..3])
        } else {
            ((f.ulog2, f.vlog2), &f.data[..])
        };
        assert_eq!((got.0, got.1), res);
        let want: Vec<f32> = bytes.iter().map(|&b| f32::from(b) / 255.0).collect();
        assert_eq!(got.2, want, "face {:?}", f.encoding);
    }
    // Resampled to at most 4 an edge (each edge on its own): the 16×8 face becomes 4×4;
    // RGBA8 with sRGB colour.
    let faces = resample(&img, 4);
    assert_eq!((faces[3].ulog2, faces[3].vlog2), (2, 2));
    assert_eq!((faces[2].ulog2, faces[2].vlog2), (2, 2));
    let faces8 = resample(&img, 8);
    assert_eq!((faces8[3].ulog2, faces8[3].vlog2), (3, 3));
    assert_eq!((faces8[2].ulog2, faces8[2].vlog2), (2, 3));
    assert_eq!(faces[0].texels, vec![200 | 10 << 8 | 30 << 16 | 0xff << 24]);
    assert_eq!(faces[4].texels.len(), 1);
    assert_eq!((faces[1].ulog2, faces[1].vlog2), (2, 2));
}

#[test]
fn float_and_half_data_read_as_linear() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("f.ptx");
    let data: Vec<u8> = [0.5f32, 0.25, 1.0]
        .iter()
        .flat_map(|v| v.to_le_bytes())
        .collect();
    let f = WriteFace {
        ulog2: 0,
        vlog2: 0,
        data,
        encoding: Encoding::Zipped,
    };
    write(&path, DataType::F32, 3, None, 1, &[f]).unwrap();
    let img = parse(&std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(img.faces[0].2, vec![0.5, 0.25, 1.0]);
    assert_eq!(half_to_f32(0x3c00), 1.0);
    assert_eq!(half_to_f32(0x3800), 0.5);
    assert_eq!(half_to_f32(0xc000), -2.0);
}

#[test]
fn corrupt_files_are_errors_not_panics() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.ptx");
    let faces = vec![face(3, 3, Encoding::Zipped, |x, y| [x as u8, y as u8, 0])];
    write(&path, DataType::U8, 3, None, 1, &faces).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    assert!(parse(&bytes[..10]).is_err());
    for cut in [70, 100, bytes.len() - 20] {
        assert!(parse(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    let mut flipped = bytes.clone();
    let n = flipped.len();
    flipped[n - 30] ^= 0xff;
    flipped[n - 31] ^= 0x5a;
    assert!(parse(&flipped).is_err());
    let e = load(&dir.path().join("missing.ptx"), 16).unwrap_err();
    assert!(e.to_string().contains("missing.ptx"), "{e}");
    std::fs::write(
        &path,
        b"not a ptex file at all, but long enough to have a header..........",
    )
    .unwrap();
    let e = load(&path, 16).unwrap_err();
    assert!(
        e.to_string().contains("c.ptx") && e.to_string().contains("Ptex"),
        "{e}"
    );
}
