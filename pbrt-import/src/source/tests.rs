use super::*;
use std::io::Write;

#[test]
fn plain_and_gz() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("a.pbrt");
    std::fs::write(&p, b"WorldBegin").unwrap();
    assert_eq!(SourceBytes::open(&p).unwrap().bytes(), b"WorldBegin");
    let gz = dir.path().join("a.pbrt.gz");
    let mut enc =
        flate2::write::GzEncoder::new(File::create(&gz).unwrap(), flate2::Compression::fast());
    enc.write_all(b"Shape \"sphere\"").unwrap();
    enc.finish().unwrap();
    assert_eq!(SourceBytes::open(&gz).unwrap().bytes(), b"Shape \"sphere\"");
    let empty = dir.path().join("e.pbrt");
    std::fs::write(&empty, b"").unwrap();
    assert!(SourceBytes::open(&empty).unwrap().bytes().is_empty());
    assert!(SourceBytes::open(&dir.path().join("missing.pbrt")).is_err());
}

#[test]
fn regression_include_of_directory_fifo_device_or_loop_is_named() {
    let dir = tempfile::tempdir().unwrap();
    assert_eq!(classify(dir.path()), FileKind::Other("a directory"));
    assert_eq!(
        classify(Path::new("/dev/zero")),
        FileKind::Other("a character device")
    );
    let a = dir.path().join("a");
    let b = dir.path().join("b");
    std::os::unix::fs::symlink(&a, &b).unwrap();
    std::os::unix::fs::symlink(&b, &a).unwrap();
    assert_eq!(classify(&a), FileKind::Other("a symbolic-link loop"));
    assert_eq!(classify(&dir.path().join("none")), FileKind::Missing);
    let e = SourceBytes::open(dir.path()).err().unwrap();
    assert!(e.to_string().contains("a directory"), "{e}");
}

/// Released pages of a mapped file read back the same bytes; an owned (gz) source ignores it.
#[test]
fn released_text_reads_back_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("big.pbrt");
    let text: Vec<u8> = (0..3 << 20).map(|i: u32| b'a' + (i % 26) as u8).collect();
    std::fs::write(&p, &text).unwrap();
    let src = SourceBytes::open(&p).unwrap();
    assert_eq!(src.bytes(), &text[..]);
    src.release(0, 1 << 20);
    src.release(4097, text.len() + 100); // unaligned start, end past the map: clamped
    src.release(10, 5); // empty range
    assert_eq!(src.bytes(), &text[..]);
    let gz = dir.path().join("a.pbrt.gz");
    let mut enc =
        flate2::write::GzEncoder::new(File::create(&gz).unwrap(), flate2::Compression::fast());
    enc.write_all(&text[..1000]).unwrap();
    enc.finish().unwrap();
    let owned = SourceBytes::open(&gz).unwrap();
    owned.release(0, 1000);
    assert_eq!(owned.bytes(), &text[..1000]);
}
