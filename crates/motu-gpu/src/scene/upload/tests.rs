use motu_alloc::{AllocKind, MemoryClass};

use super::Uploader;
use crate::testutil::{assert_no_validation_errors, context_or_skip, test_heap};
use motu_vk::BufferUsage;
use motu_vk::Requirement;

/// Values written in place by `upload_with` land in order across several ring regions, each
/// region's written by several pool tasks (the last ones partial), at an offset, next to a
/// plain upload queued before them.
#[test]
fn values_written_in_place_span_ring_regions_in_order() {
    let Some(ctx) = context_or_skip("upload_with_regions", Requirement::Compute) else {
        return;
    };
    let mut heap = test_heap(&ctx, 64 << 20);
    let mut up = Uploader::new(&mut heap, 64 << 10).expect("ring");
    assert_eq!(up.region_bytes(), 64 << 10);
    // 40,000 [u32; 6] values: 960,000 bytes, 15 regions of 2,730 values (3 tasks each), the
    // last one partial.
    let count = 40_000usize;
    let dst = heap
        .alloc_buffer(
            "upload-with-dst",
            16 + (count * 24) as u64,
            BufferUsage::TRANSFER_DST,
            AllocKind::Staging,
            MemoryClass::HostVisible,
            16,
        )
        .expect("destination");
    let value = |k: usize| -> [u32; 6] { std::array::from_fn(|j| (k * 6 + j) as u32 ^ 0x5a5a) };
    up.upload(&ctx, &dst, 0, &[7u8; 16]).expect("head");
    up.upload_with(&ctx, &dst, 16, count, value)
        .expect("values");
    up.flush(&ctx).expect("flush");
    let mut got = vec![0u8; 16 + count * 24];
    dst.read_bytes(0, &mut got).expect("read back");
    assert_eq!(&got[..16], &[7u8; 16]);
    let words: &[u32] = bytemuck::cast_slice(&got[16..]);
    for (k, v) in words.chunks_exact(6).enumerate() {
        assert_eq!(v, value(k), "value {k}");
    }
    assert!(up.flushes >= 15, "{} flushes", up.flushes);
    heap.free(dst);
    heap.free(up.staging);
    assert_no_validation_errors(&ctx);
}

/// Pieces of a group upload (cut for threads, some straddling the ring's regions) land once
/// each, byte for byte, through the ring and straight into a host-mapped buffer alike.
#[test]
fn group_pieces_filled_in_parallel_land_exactly_once_through_the_ring_and_in_place() {
    use super::group::{cut, write_mapped_parallel, Piece};
    let Some(ctx) = context_or_skip("upload_pieces", Requirement::Compute) else {
        return;
    };
    let mut heap = test_heap(&ctx, 64 << 20);
    let mut up = Uploader::new(&mut heap, 64 << 10).expect("ring");
    let size = 300_000usize;
    let src: Vec<u8> = (0..size).map(|i| (i * 31 % 251) as u8).collect();
    let alloc = |heap: &mut motu_vk::GpuHeap, name: &str| {
        heap.alloc_buffer(
            name,
            size as u64 + 64,
            BufferUsage::TRANSFER_DST,
            AllocKind::Staging,
            MemoryClass::HostVisible,
            16,
        )
        .expect("destination")
    };
    let (ringed, direct) = (alloc(&mut heap, "ringed"), alloc(&mut heap, "direct"));
    // Uneven pieces, out of order, one empty, one larger than a region.
    let spans = [
        (0, 7),
        (200_000, 100_000),
        (7, 0),
        (7, 99_993),
        (100_000, 100_000),
    ];
    let pieces = |dst| -> Vec<Piece<'_>> {
        spans
            .iter()
            .map(|&(at, n)| Piece {
                dst,
                dst_offset: 64 + at as u64,
                src: &src[at..at + n],
            })
            .collect()
    };
    let cut_ringed = cut(&pieces(&ringed), 40_000);
    assert!(cut_ringed.iter().all(|p| p.src.len() <= 40_000));
    assert_eq!(
        cut_ringed.iter().map(|p| p.src.len()).sum::<usize>(),
        size,
        "cutting keeps every byte, drops the empty piece"
    );
    ringed.write_bytes(0, &vec![0xee; size + 64]).expect("mark");
    up.upload_pieces(&ctx, &cut_ringed)
        .expect("through the ring");
    up.flush(&ctx).expect("flush");
    assert!(up.flushes >= 4, "{} flushes: regions reused", up.flushes);
    write_mapped_parallel(&cut(&pieces(&direct), 40_000)).expect("in place");
    for buf in [&ringed, &direct] {
        let mut got = vec![0u8; size + 64];
        buf.read_bytes(0, &mut got).expect("read back");
        if std::ptr::eq(buf, &ringed) {
            assert_eq!(&got[..64], &[0xee; 64], "nothing written before the pieces");
        }
        assert!(got[64..] == src[..], "every byte once, in place");
    }
    heap.free(ringed);
    heap.free(direct);
    heap.free(up.staging);
    assert_no_validation_errors(&ctx);
}
