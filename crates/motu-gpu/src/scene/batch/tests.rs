use motu_alloc::{AllocKind, BuildSize, MemoryClass};

use super::build_batched;
use crate::scene::{BuildOptions, ResourceReport};
use crate::testutil::{assert_no_validation_errors, context_or_skip, test_heap};
use motu_vk::AsLevel;
use motu_vk::BlasGeometry;
use motu_vk::BufferUsage;
use motu_vk::GpuHeap;
use motu_vk::Requirement;

fn scratch_bytes(heap: &GpuHeap) -> u64 {
    heap.report()
        .kinds
        .get(&AllocKind::Scratch)
        .map_or(0, |k| k.bytes)
}

/// `inputs_done` runs once, after the last batch is built, with the scratch pool already
/// freed: the inputs it frees and the scratch never stack on the compacted copies.
#[test]
fn inputs_are_released_once_the_last_batch_is_built() {
    let Some(ctx) = context_or_skip("inputs_done", Requirement::RayTracing) else {
        return;
    };
    let mut heap = test_heap(&ctx, 64 << 20);
    // Three BLASes of 8 boxes each, one batch each.
    let boxes: Vec<[f32; 6]> = (0..24)
        .map(|i| {
            let x = i as f32;
            [x, 0.0, 0.0, x + 0.5, 1.0, 1.0]
        })
        .collect();
    let input = heap
        .alloc_buffer(
            "aabbs",
            (boxes.len() * 24) as u64,
            BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT,
            AllocKind::Geometry,
            MemoryClass::HostVisible,
            16,
        )
        .expect("input");
    input.write(0, &boxes).expect("write boxes");
    let base = input.device_address().expect("address").0;
    let shape = [BlasGeometry::Aabbs {
        aabb_count: 8,
        opaque: true,
    }];
    let opts = BuildOptions {
        max_batch_result_bytes: 1,
        ..Default::default()
    };
    let sz = ctx
        .blas_build_sizes(&shape, opts.blas_build.flags())
        .expect("sizes");
    let sizes = vec![
        BuildSize {
            result_bytes: sz.acceleration_structure_size_bytes,
            scratch_bytes: sz.build_scratch_size_bytes,
        };
        3
    ];
    let mut input = Some(input);
    let prepared = std::cell::Cell::new(0u32);
    let mut done_calls = 0u32;
    let mut scratch_while_preparing = 0u64;
    let mut scratch_when_done = u64::MAX;
    let mut report = ResourceReport::default();
    let built = build_batched(
        &ctx,
        &mut heap,
        &mut report,
        &sizes,
        AsLevel::Bottom,
        &opts,
        |k| {
            (
                vec![crate::scene::aabbs_geometry(base + k as u64 * 8 * 24, true)],
                vec![8],
            )
        },
        |heap, _| {
            prepared.set(prepared.get() + 1);
            scratch_while_preparing = scratch_while_preparing.max(scratch_bytes(heap));
            Ok(())
        },
        &mut |heap| {
            done_calls += 1;
            assert_eq!(
                prepared.get(),
                3,
                "every batch prepared before the inputs go"
            );
            scratch_when_done = scratch_bytes(heap);
            if let Some(b) = input.take() {
                heap.free(b);
            }
        },
    )
    .expect("build");
    assert_eq!(report.build_batches, 3);
    assert_eq!(done_calls, 1);
    assert!(input.is_none(), "the inputs were released by the callback");
    assert!(
        scratch_while_preparing > 0,
        "the scratch pool lives while batches build"
    );
    assert_eq!(
        scratch_when_done, 0,
        "the scratch pool is freed before the inputs"
    );
    assert_eq!(built.len(), 3);
    for (_, a) in built {
        a.release(&mut heap);
    }
    assert_eq!(
        heap.report().budget_in_use_bytes,
        0,
        "nothing left allocated"
    );
    assert_no_validation_errors(&ctx);
}
