use super::*;

#[test]
fn shadow_offset_moves_along_the_normal() {
    for p in [[0.0, 0.0, 0.0], [100.0, -2000.0, 3.5], [1e-3, 5.0, -0.01]] {
        let n = [0.0, 1.0, 0.0];
        let o = shadow_offset(p, n, 0.0);
        assert!(o[1] > p[1], "{p:?} -> {o:?}");
        assert_eq!(o[0], p[0]);
    }
    let n = normalize([1.0, -1.0, 0.5]);
    let o = shadow_offset([10.0, 10.0, 10.0], n, 0.0);
    // Far hits move further: the reach term covers the error of o + t·d.
    let far = shadow_offset([0.0, 0.0, 0.0], [0.0, 1.0, 0.0], 1000.0);
    assert!(far[1] >= 1000.0 / 262_144.0, "{far:?}");
    assert!(o[0] > 10.0 && o[1] < 10.0 && o[2] > 10.0);
}

#[test]
fn colours_and_views() {
    assert_ne!(id_colour(1, 2), id_colour(1, 3));
    assert_eq!(id_colour(4, 5), id_colour(4, 5));
    assert_eq!(heat_colour(0.0), [0.0, 0.0, 1.0]);
    assert_eq!(heat_colour(1.0), [1.0, 0.0, 0.0]);
    assert_ne!(lod_colour(0), lod_colour(1));
    assert_eq!("heatmap".parse::<View>(), Ok(View::Heatmap));
    assert!("x".parse::<View>().is_err());
    let d: Vec<f32> = (0..100).map(|i| pixel_dither(i, 7)).collect();
    assert!(d.iter().all(|&u| (0.0..1.0).contains(&u)));
}

#[test]
fn png_round_trip_size_check() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("a.png");
    write_png(&path, 2, 1, &[255, 0, 0, 255, 0, 255, 0, 255]).unwrap();
    let dec = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(&path).unwrap()));
    let reader = dec.read_info().unwrap();
    assert_eq!((reader.info().width, reader.info().height), (2, 1));
    assert!(write_png(&path, 3, 3, &[0; 4]).is_err());
}

/// Errors keep their cause (issue 46): a PNG that cannot be written keeps the I/O error.
#[test]
fn a_png_write_failure_keeps_its_io_error() {
    let dir = tempfile::tempdir().unwrap();
    let e = write_png(dir.path(), 1, 1, &[0; 4]).unwrap_err();
    assert!(matches!(e, TraceError::PngWrite { .. }), "{e}");
    let cause = std::error::Error::source(&e).expect("the I/O error is the source");
    assert!(cause.downcast_ref::<std::io::Error>().is_some(), "{cause}");
}
