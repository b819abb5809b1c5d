use super::*;
use crate::context::Requirement;
use crate::testutil::{assert_no_validation_errors, context_or_skip, test_heap};

/// `try_fit` answers as allocating would (the streamed TLAS rebuild's room probe asks it
/// instead of allocating) and allocates nothing: no block, no memory.
#[test]
fn try_fit_answers_as_allocating_would_without_allocating() {
    let Some(ctx) = context_or_skip("heap_try_fit", Requirement::Compute) else {
        return;
    };
    const MIB: u64 = 1 << 20;
    let mut heap = test_heap(&ctx, 64 * MIB);
    let held = heap
        .alloc_buffer(
            "held",
            40 * MIB,
            BufferUsage::STORAGE,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
            16,
        )
        .expect("40 MiB of 64");
    let blocks = heap.block_count();
    let report = heap.report();
    let ask = |label, mib: u64| FitRequest {
        label,
        size_bytes: mib * MIB,
        usage: BufferUsage::STORAGE,
        kind: AllocKind::Scratch,
        class: MemoryClass::DeviceLocal,
        alignment: 16,
    };
    assert!(heap.try_fit(&[ask("small", 8)]).is_ok());
    // Each alone fits; held together the second does not, and the error names it.
    assert!(heap.try_fit(&[ask("second", 16)]).is_ok());
    match heap.try_fit(&[ask("first", 16), ask("second", 16)]) {
        Err(VkError::Budget(refusal)) => {
            assert!(refusal.to_string().starts_with("second:"), "{refusal}");
            // The allocator's refusal is kept as the cause, not only as text.
            let cause = std::error::Error::source(&refusal).expect("a cause");
            assert!(
                refusal.to_string().ends_with(&cause.to_string()),
                "{refusal}"
            );
        }
        other => panic!("expected the budget's refusal of `second`: {other:?}"),
    }
    assert_eq!(heap.block_count(), blocks, "no memory allocated");
    assert_eq!(heap.report(), report, "the policy's state unchanged");
    // The real allocations agree.
    let a = heap
        .alloc_buffer(
            "a",
            16 * MIB,
            BufferUsage::STORAGE,
            AllocKind::Scratch,
            MemoryClass::DeviceLocal,
            16,
        )
        .expect("first fits");
    assert!(heap
        .alloc_buffer(
            "b",
            16 * MIB,
            BufferUsage::STORAGE,
            AllocKind::Scratch,
            MemoryClass::DeviceLocal,
            16
        )
        .is_err());
    heap.free(a);
    heap.free(held);
    assert_no_validation_errors(&ctx);
}

/// With blocks made ahead (`spare.rs`), the host block the policy makes after the first one
/// is the spare, not a `vkAllocateMemory` of the caller's; a destroyed block is kept as the
/// next one; device-local blocks never come from it.
#[test]
fn host_blocks_made_ahead_are_taken_by_the_next_block() {
    let Some(ctx) = context_or_skip("heap_host_blocks_ahead", Requirement::Compute) else {
        return;
    };
    const MIB: u64 = 1 << 20;
    // Standard blocks of 4 MiB (a 16th of the budget); 3 MiB buffers take one each.
    let mut heap = test_heap(&ctx, 64 * MIB);
    heap.set_host_blocks_ahead(true);
    let alloc = |heap: &mut GpuHeap, class| {
        heap.alloc_buffer(
            "b",
            3 * MIB,
            BufferUsage::STORAGE,
            AllocKind::Other,
            class,
            16,
        )
        .expect("3 MiB of 64")
    };
    let wait_ready = |heap: &GpuHeap| {
        while !heap.spare.as_ref().is_some_and(|s| s.ready()) {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
    };
    let first = alloc(&mut heap, MemoryClass::HostVisible);
    assert_eq!(heap.created_blocks(MemoryClass::HostVisible).from_spare, 0);
    wait_ready(&heap);
    let second = alloc(&mut heap, MemoryClass::HostVisible);
    let counts = heap.created_blocks(MemoryClass::HostVisible);
    assert_eq!((counts.created, counts.from_spare), (2, 1), "{counts:?}");
    second.write_bytes(0, &[7u8; 64]).expect("mapped");
    let device = alloc(&mut heap, MemoryClass::DeviceLocal);
    assert_eq!(heap.created_blocks(MemoryClass::DeviceLocal).from_spare, 0);
    // A third host block: the spare made after the second, or the one made in time.
    wait_ready(&heap);
    let third = alloc(&mut heap, MemoryClass::HostVisible);
    assert_eq!(heap.created_blocks(MemoryClass::HostVisible).from_spare, 2);
    heap.free(third);
    heap.free(second);
    heap.free(first);
    heap.free(device);
    heap.set_host_blocks_ahead(false);
    assert!(heap.spare.is_none());
    assert_no_validation_errors(&ctx);
}
