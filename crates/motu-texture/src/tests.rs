use super::*;

#[test]
fn environment_maps_halve_to_the_cap() {
    let (w, h, t) = cap_width(256, 1024, 512, vec![[1.0, 2.0, 3.0]; 1024 * 512]);
    assert_eq!((w, h, t.len()), (256, 128, 256 * 128));
    assert_eq!(t[77], [1.0, 2.0, 3.0]);
    let (w, h, _) = cap_width(256, 200, 100, vec![[0.0; 3]; 200 * 100]);
    assert_eq!((w, h), (200, 100));
}

#[test]
fn png_round_trip_and_mips() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.png");
    let mut img = image::RgbaImage::new(8, 4);
    for (x, _, p) in img.enumerate_pixels_mut() {
        *p = if x < 4 {
            image::Rgba([255, 0, 0, 255])
        } else {
            image::Rgba([0, 0, 255, 0])
        };
    }
    img.save(&path).unwrap();
    let chain = load(&path, 1024, false).unwrap();
    assert_eq!((chain.width, chain.height), (8, 4));
    assert_eq!(chain.levels.len(), 4); // 8×4, 4×2, 2×1, 1×1
    assert_eq!(chain.texel_count(), 32 + 8 + 2 + 1);
    assert_eq!(chain.levels[0][0], 0xff00_00ff);
    assert_eq!(chain.levels[0][7], 0x00ff_0000);
    // The 1×1 level: half red, half blue in linear light, half covered.
    let top = chain.levels[3][0];
    assert_eq!(top & 0xff, linear_to_srgb8(0.5));
    assert_eq!(top >> 24, 128);
    // The cap halves level 0 until it fits.
    let capped = load(&path, 2, false).unwrap();
    assert_eq!((capped.width, capped.height), (2, 1));
    assert!(load(&dir.path().join("missing.png"), 16, false).is_err());
}

#[test]
fn pfm_reads_bottom_up_little_endian() {
    let mut bytes = b"PF\n2 2\n-1.0\n".to_vec();
    for v in [
        [1.0f32, 0.0, 0.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.5, 0.5, 0.5],
    ] {
        for c in v {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    let img = read_pfm(&bytes).unwrap();
    // Row 0 (top) is the file's last row.
    assert_eq!(img.texels[0], [0.0, 0.0, 1.0, 1.0]);
    assert_eq!(img.texels[2], [1.0, 0.0, 0.0, 1.0]);
    assert!(read_pfm(b"PF\n2 2\n-1.0\n").is_err());
    assert!(read_pfm(b"P6\n2 2\n255\n").is_err());
}

/// Errors keep their cause (issue 46): an unreadable file's I/O error is the source.
#[test]
fn an_unreadable_texture_keeps_its_io_error() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["gone.png", "gone.pfm"] {
        let e = read_linear(&dir.path().join(name)).unwrap_err();
        assert!(matches!(e, TextureError::Io { .. }), "{e}");
        let cause = std::error::Error::source(&e).expect("the I/O error is the source");
        assert!(cause.downcast_ref::<std::io::Error>().is_some(), "{cause}");
        assert!(e.to_string().contains(name), "{e}");
    }
}
