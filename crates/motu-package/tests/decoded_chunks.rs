//! `Package::chunk_shared`: a zstd chunk is decoded once while it stays among the recently
//! decoded, however many readers take pieces of it from however many threads (a streamed
//! build group's meshes: before, each mesh read decoded its whole chunk, three times).

use motu_package::{ChunkId, Codec, Package, PackageWriter, WriterOptions};

#[test]
fn shared_chunks_decode_once_per_chunk_and_give_the_plain_reads_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("zstd.motu");
    let options = WriterOptions {
        target_chunk_bytes: 8192,
        zstd_level: Some(3),
        direct_io: false,
    };
    let mut writer = PackageWriter::create(&path, options).unwrap();
    let stream = writer.open_stream(10, 0);
    let blobs: Vec<_> = (0..40u32)
        .map(|i| {
            // Compressible: zstd pays, so the chunks are stored compressed.
            let blob: Vec<u8> = (0..1000u32).map(|k| ((k / 7 + i) % 13) as u8).collect();
            (writer.append(stream, &blob, 4).unwrap(), blob)
        })
        .collect();
    writer.finish().unwrap();
    let package = Package::open(&path).unwrap();
    let zstd: Vec<ChunkId> = package
        .chunks()
        .iter()
        .filter(|c| c.codec == Codec::Zstd)
        .map(|c| c.id)
        .collect();
    assert!(zstd.len() >= 3, "{:?}", package.chunks());
    let before = package.chunk_decodes();
    // Every blob read three times (positions, map, attributes), from four threads.
    std::thread::scope(|scope| {
        for t in 0..4 {
            let (package, blobs) = (&package, &blobs);
            scope.spawn(move || {
                for _ in 0..3 {
                    for (at, blob) in blobs.iter().skip(t).step_by(4) {
                        let chunk = package.chunk_shared(at.chunk).unwrap();
                        let start = at.offset_in_chunk as usize;
                        assert_eq!(&chunk[start..start + blob.len()], &blob[..]);
                        assert_eq!(chunk.as_ptr() as usize % 64, 0, "aligned");
                    }
                }
            });
        }
    });
    assert_eq!(
        package.chunk_decodes() - before,
        zstd.len() as u64,
        "one decode per compressed chunk"
    );
    // The plain read decodes every time.
    let before = package.chunk_decodes();
    for _ in 0..3 {
        let shared = package.chunk_shared(zstd[0]).unwrap();
        assert_eq!(&package.chunk(zstd[0]).unwrap()[..], &shared[..]);
    }
    assert_eq!(package.chunk_decodes() - before, 3);
}
