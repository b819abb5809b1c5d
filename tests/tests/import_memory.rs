//! An import's peak memory grows with the scene's instances by a bounded number of bytes each
//! (issue 48 item 1: peak RSS independent of scene size beyond a small skeleton). Two
//! generated instancing scenes of different instance counts are imported; the growth of the
//! import's own peak RSS (`peak_rss_bytes` in `motu import --json`: the process's `VmHWM`)
//! per added instance must stay under [`MAX_BYTES_PER_INSTANCE`].

use motu_tests::{motu_json, s};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// What an instance may cost at the import's peak. The edges go to a scratch file as they are
/// parsed (the heap holds a chunk) and are read through a map whose pages every walk drops;
/// the mapped scene text is released as it is scanned and parsed; the compile's instance table
/// is a mapped file from the emitter on, its pages released behind every pass, and the stream
/// split partitions indices while the records wait in a file; the proxy clusters are made a
/// batch of TLASes at a time and written without a copy; after the stream split the package's
/// instance table is a mapped file read a piece at a time. The peak is now the parse.
/// Measured on this scene (20k → 220k instances): 61–64 bytes an instance with the compile's
/// table mapped (session 44: release 64.2, test profile 61.2; main 74.8), 76–77 with the table
/// parked from the split on (session 43), 82–85 with the heap trimmed after the clusters
/// (session 42, 88 before), 88–93 in session 39 (main 96–100 before); 99–101 in session 38, 125
/// before (edges and the compiled instance table side by side), 174 before session 37's
/// copy-free stream split. 76 leaves room for the loaded machine's parse (its include workers)
/// without letting the compile's table come back to the heap.
const MAX_BYTES_PER_INSTANCE: f64 = 76.0;

/// A pbrt scene of `n` instances: a one-triangle object placed `n` times, half of them at the
/// root and half inside a group object that the root places once, the two interleaved in the
/// file (the builder must sort the edges by parent).
fn write_grid(dir: &Path, n: usize) -> PathBuf {
    let mut text = String::with_capacity(n * 64);
    text.push_str("WorldBegin\n");
    text.push_str("ObjectBegin \"leaf\"\n");
    text.push_str(
        "Shape \"trianglemesh\" \"integer indices\" [0 1 2] \"point P\" [0 0 0 1 0 0 0 1 0]\n",
    );
    text.push_str("ObjectEnd\n");
    let half = n / 2;
    // Root instances, a group of nested ones, root instances again: the edges' parents
    // interleave (root, group, root).
    let place = |text: &mut String, i: usize| {
        let (x, y) = (i % 1024, i / 1024);
        writeln!(
            text,
            "AttributeBegin Translate {x} {y} 0 ObjectInstance \"leaf\" AttributeEnd"
        )
        .unwrap();
    };
    for i in 0..half / 2 {
        place(&mut text, i);
    }
    text.push_str("ObjectBegin \"group\"\n");
    for i in 0..n - half {
        place(&mut text, i);
    }
    text.push_str("ObjectEnd\n");
    for i in half / 2..half {
        place(&mut text, i);
    }
    text.push_str("AttributeBegin Translate 0 0 5 ObjectInstance \"group\" AttributeEnd\n");
    let path = dir.join(format!("grid{n}.pbrt"));
    std::fs::write(&path, text).unwrap();
    path
}

/// Imports `scene` and returns (instance edges, peak RSS bytes) from the summary. A small
/// stream-split cap, so the split (and what the import makes over it) runs as on a big scene.
fn import_peak(scene: &Path, pkg: &Path) -> (u64, u64) {
    let j = motu_json(&[
        "import",
        s(scene),
        "-o",
        s(pkg),
        "--stream-split-instances",
        "20000",
        "--json",
    ]);
    let n = j["instances"].as_u64().expect("instances");
    let rss = j["peak_rss_bytes"].as_u64().expect("peak_rss_bytes");
    (n, rss)
}

#[test]
fn import_peak_rss_grows_by_a_bounded_amount_per_instance() {
    if !Path::new("/proc/self/status").exists() {
        eprintln!("skipped: no /proc (peak RSS unknown)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let (small, big) = (20_000, 220_000);
    let a = write_grid(dir.path(), small);
    let b = write_grid(dir.path(), big);
    let (na, ra) = import_peak(&a, &dir.path().join("a.motu"));
    let (nb, rb) = import_peak(&b, &dir.path().join("b.motu"));
    // Every placement and the group's own: an edge each.
    assert_eq!(na, small as u64 + 1);
    assert_eq!(nb, big as u64 + 1);
    assert!(ra > 0 && rb > 0, "peak RSS unknown: {ra} {rb}");
    let per = (rb as f64 - ra as f64) / (nb - na) as f64;
    eprintln!(
        "peak RSS {:.1} MiB at {na} instances, {:.1} MiB at {nb}: {per:.1} bytes an instance",
        ra as f64 / 1048576.0,
        rb as f64 / 1048576.0
    );
    assert!(
        per < MAX_BYTES_PER_INSTANCE,
        "peak RSS grew {per:.1} bytes an instance (bound {MAX_BYTES_PER_INSTANCE}): \
         {ra} bytes at {na} instances, {rb} at {nb}"
    );
}
