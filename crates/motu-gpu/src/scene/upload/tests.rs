use motu_alloc::{AllocKind, MemoryClass};

use super::Uploader;
use crate::testutil::{assert_no_validation_errors, context_or_skip, test_heap};
use motu_vk::BufferUsage;
use motu_vk::Requirement;

/// Values written in place by `upload_with` land in order across several ring regions,
/// at an offset, next to a plain upload queued before them.
#[test]
fn values_written_in_place_span_ring_regions_in_order() {
    let Some(ctx) = context_or_skip("upload_with_regions", Requirement::Compute) else {
        return;
    };
    let mut heap = test_heap(&ctx, 64 << 20);
    let mut up = Uploader::new(&mut heap, 64 << 10).expect("ring");
    assert_eq!(up.region_bytes(), 64 << 10);
    // 40,000 [u32; 6] values: 960,000 bytes, 15 regions, the last one partial.
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
