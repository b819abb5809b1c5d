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
