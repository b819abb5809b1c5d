use super::*;

#[test]
fn regression_special_input_files_are_named_before_opening() {
    let dir = tempfile::tempdir().unwrap();
    let named = |p: &Path| check_input(p, None).unwrap_err().to_string();
    assert_eq!(named(dir.path()), "a directory, not a regular file");
    assert_eq!(
        named(Path::new("/dev/zero")),
        "a character device, not a regular file"
    );
    assert_eq!(
        named(Path::new("/dev/null")),
        "a character device, not a regular file"
    );
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    std::os::unix::fs::symlink(&a, &b).unwrap();
    std::os::unix::fs::symlink(&b, &a).unwrap();
    assert_eq!(named(&a), "a symbolic-link loop, not a regular file");
    let dangling = dir.path().join("dangling");
    std::os::unix::fs::symlink(dir.path().join("gone"), &dangling).unwrap();
    assert_eq!(
        named(&dangling),
        "a dangling symbolic link, not a regular file"
    );
    assert_eq!(named(&dir.path().join("none")), "no such file");
    // A FIFO is refused without opening it (opening would block this test forever).
    let fifo = dir.path().join("fifo");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status();
    if made.is_ok_and(|s| s.success()) {
        assert_eq!(named(&fifo), "a FIFO, not a regular file");
        assert!(open_input(&fifo, None).is_err());
    } else {
        eprintln!("SKIPPED the FIFO case: mkfifo is not available");
    }
    let f = dir.path().join("f");
    std::fs::write(&f, [0u8; 100]).unwrap();
    assert_eq!(open_input(&f, Some(100)).unwrap().1, 100);
    let e = check_input(&f, Some(99)).unwrap_err().to_string();
    assert!(e.contains("100 bytes, more than the 99"), "{e}");
}
