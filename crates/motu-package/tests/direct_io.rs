//! Writes past the page cache (`WriterOptions::direct_io`) make the same file as buffered
//! writes, and read-backs during the write see every byte, staged or on the file.

use std::path::Path;

use motu_package::{Package, PackageWriter, WriterOptions};

mod common;
use common::noise;

/// Writes blobs across several 2 MiB stages (chunks of about `target` bytes, some blobs
/// larger than it, odd lengths and alignments), reading back every sealed chunk as it goes;
/// returns whether the writes were direct. Panics where a read-back differs from what was
/// written.
fn write(path: &Path, direct_io: bool, zstd_level: Option<i32>, target: u64) -> bool {
    let options = WriterOptions {
        target_chunk_bytes: target,
        zstd_level,
        direct_io,
    };
    let mut w = PackageWriter::create(path, options).unwrap();
    let direct = w.writes_direct();
    let streams = [w.open_stream(1, 0), w.open_stream(2, 1)];
    let mut written = Vec::new();
    for i in 0..40u64 {
        let len = if i % 13 == 5 {
            (1 << 20) + 4099
        } else {
            200_000 + 7 * i as usize
        };
        let blob = if i % 2 == 0 {
            noise(i, len)
        } else {
            (0..len).map(|k| (k / 5) as u8).collect()
        };
        let align = [1, 8, 64, 4096][i as usize % 4];
        let at = w.append(streams[i as usize % 2], &blob, align).unwrap();
        written.push((at, blob));
        // Every blob written so far reads back, from the file, the stage or an open chunk.
        for (at, blob) in &written {
            let back = w
                .read_back(at.chunk, at.offset_in_chunk, at.len_bytes)
                .unwrap();
            assert!(back == *blob, "read-back of {at:?} after blob {i}");
        }
    }
    w.add_section(motu_package::SectionKind(7), "tail", 1, &noise(99, 5001))
        .unwrap();
    w.finish().unwrap();
    let p = Package::open(path).unwrap();
    for (at, blob) in &written {
        let chunk = p.chunk(at.chunk).unwrap();
        let start = at.offset_in_chunk as usize;
        assert!(chunk[start..start + blob.len()] == blob[..], "{at:?}");
    }
    direct
}

#[test]
fn direct_writes_make_the_same_file_as_buffered_ones() {
    let dir = tempfile::tempdir().unwrap();
    // Raw chunks go to the file in place (page-aligned chunk buffers), smaller and larger
    // than a stage; zstd chunks through the stage.
    for (zstd, target) in [(None, 768 << 10), (None, 3 << 20), (Some(1), 768 << 10)] {
        let (a, b) = (dir.path().join("a.motu"), dir.path().join("b.motu"));
        assert!(!write(&a, false, zstd, target), "buffered writes asked for");
        let direct = write(&b, true, zstd, target);
        if !direct {
            eprintln!(
                "{}: O_DIRECT refused here; compared buffered with buffered",
                dir.path().display()
            );
        }
        let (a, b) = (std::fs::read(a).unwrap(), std::fs::read(b).unwrap());
        assert_eq!(a.len(), b.len());
        assert!(
            a == b,
            "direct and buffered packages differ (zstd {zstd:?}, target {target})"
        );
    }
}
