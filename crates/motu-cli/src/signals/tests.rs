use super::*;
use std::io::Write;

#[test]
fn regression_late_interrupt_names_the_completed_output() {
    let c = motu_package::atomic::SignalCleanup {
        removed: 0,
        completed: vec!["/tmp/out.motu".into()],
    };
    let m = interrupted_message("SIGINT", &c);
    assert!(
        m.contains("removed 0") && m.contains("already completed") && m.contains("/tmp/out.motu"),
        "{m}"
    );
    let m = interrupted_message("SIGTERM", &Default::default());
    assert!(!m.contains("completed"), "{m}");
}

#[test]
fn maps_lines_resolve_path_and_offset() {
    let line = b"7f0000001000-7f0000003000 r--s 00002000 08:01 1234   /tmp/a b.motu";
    let (path, off) = maps_line_match(line, 0x7f0000001010).unwrap();
    assert_eq!(path, b"/tmp/a b.motu");
    assert_eq!(off, 0x2010);
    assert!(maps_line_match(line, 0x7f0000003000).is_none());
    let mut m = Msg {
        buf: [0; 1024],
        len: 0,
    };
    m.push_u64(0);
    m.push(b" ");
    m.push_u64(18446744073709551615);
    assert_eq!(&m.buf[..m.len], b"0 18446744073709551615");
}

/// The child half of the SIGBUS test: maps a file, truncates it, reads the lost page.
#[test]
fn sigbus_child() {
    let Some(path) = std::env::var_os("MOTU_SIGBUS_CHILD") else {
        return;
    };
    install();
    let mut f = std::fs::File::create(&path).unwrap();
    f.write_all(&[7u8; 8192]).unwrap();
    f.sync_all().unwrap();
    let f = std::fs::File::open(&path).unwrap();
    // SAFETY: the test truncates the file on purpose to raise SIGBUS.
    let map = unsafe { memmap2::Mmap::map(&f).unwrap() };
    std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(0)
        .unwrap();
    let v = std::hint::black_box(map[4096]);
    println!("read {v} from a truncated map without a fault");
}

#[test]
fn regression_sigbus_on_truncated_mapped_file_names_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("truncated.motu");
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "signals::tests::sigbus_child", "--nocapture"])
        .env("MOTU_SIGBUS_CHILD", &path)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "stderr: {stderr}");
    assert!(
        stderr.contains(&format!("bus error reading {}", path.display()))
            && stderr.contains("truncated or overwritten"),
        "{stderr}"
    );
}
