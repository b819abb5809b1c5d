//! Device-layer tests that need raw Vulkan calls (which only this crate may make).

use std::sync::Arc;

use ash::vk;

use crate::testutil::{assert_no_validation_errors, context_or_skip};
use crate::*;

#[test]
fn validation_messenger_records_an_invalid_call() {
    let Some(ctx) = context_or_skip("validation_messenger", Requirement::Compute) else {
        return;
    };
    if !ctx.validation_enabled() {
        eprintln!("SKIPPED: validation_messenger: validation layer not installed");
        return;
    }
    assert!(ctx.validation_errors().is_empty());
    // A buffer with no usage bits violates VUID-VkBufferCreateInfo-usage-requiredbitmask; the
    // driver ignores usage for creation, so the call is harmless beyond the message.
    let info = vk::BufferCreateInfo::default()
        .size(64)
        .usage(vk::BufferUsageFlags::empty())
        .sharing_mode(vk::SharingMode::EXCLUSIVE);
    let device = &ctx.shared.device;
    // SAFETY: deliberately invalid usage (see above); the buffer is destroyed right away and
    // never bound or used.
    unsafe {
        if let Ok(buffer) = device.create_buffer(&info, None) {
            device.destroy_buffer(buffer, None);
        }
    }
    let errors = ctx.validation_errors();
    assert!(!errors.is_empty(), "the validation layer reported nothing");
    assert!(errors.iter().any(|e| e.contains("usage")), "{errors:?}");
    let err = ctx.check_validation().expect_err("check must fail");
    assert!(matches!(err, VkError::Validation { .. }), "{err}");
    let _ = Arc::strong_count(&ctx.shared);
}

#[test]
fn encoded_instances_pick_hit_group_and_opacity() {
    let m = [1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0];
    let word = |b: &[u8; 64], at: usize| u32::from_le_bytes(b[at..at + 4].try_into().unwrap());
    let opaque = encode_instance(&m, InstanceHit::Triangles { any_hit: false }, 0x1000, 7);
    assert_eq!(word(&opaque, 48), 0xFF00_0007, "mask 0xFF, custom index 7");
    let flags = vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE
        | vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE;
    assert_eq!(
        word(&opaque, 52),
        flags.as_raw() << 24,
        "hit group 0, forced opaque"
    );
    let pi = encode_instance(&m, InstanceHit::Procedural, 0x1000, 7);
    assert_eq!(
        word(&pi, 52),
        1 | (vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE.as_raw() << 24),
        "hit group 1, never opaque"
    );
    let proxy = encode_instance(&m, InstanceHit::Proxy, 0x1000, 7);
    assert_eq!(
        word(&proxy, 52),
        2 | (vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE.as_raw() << 24),
        "hit group 2, never opaque"
    );
    let inactive = encode_instance(&m, InstanceHit::Triangles { any_hit: true }, 0, 3);
    assert_eq!(word(&inactive, 48) >> 24, 0, "no BLAS: mask 0");
    assert_eq!(
        u64::from_le_bytes(opaque[56..64].try_into().unwrap()),
        0x1000
    );
}

#[test]
fn buffers_sub_allocated_in_one_block_copy_on_the_gpu() {
    let Some(ctx) = context_or_skip("sub_allocated_buffers", Requirement::Compute) else {
        return;
    };
    let usage = BufferUsage::TRANSFER_SRC | BufferUsage::TRANSFER_DST | BufferUsage::STORAGE;
    let mut a = Buffer::new(
        &ctx,
        "a",
        &BufferDesc {
            size_bytes: 256,
            usage,
        },
    )
    .expect("a");
    let mut b = Buffer::new(
        &ctx,
        "b",
        &BufferDesc {
            size_bytes: 256,
            usage,
        },
    )
    .expect("b");
    let (ra, rb) = (a.memory_requirements(), b.memory_requirements());
    let type_index = ctx
        .memory_type_index(
            MemoryLocation::Upload,
            ra.memory_type_bits & rb.memory_type_bits,
        )
        .expect("a host-visible type for both");
    let offset_b = ra
        .size_bytes
        .next_multiple_of(rb.alignment_bytes)
        .max(rb.alignment_bytes);
    let before = ctx.allocation_count();
    let block = DeviceMemory::allocate(
        &ctx,
        offset_b + rb.size_bytes,
        type_index,
        MemoryLocation::Upload,
    )
    .expect("block");
    assert_eq!(ctx.allocation_count(), before + 1);
    a.bind(&block, 0).expect("bind a");
    // A misaligned or overlapping-the-end bind is refused before reaching Vulkan.
    if rb.alignment_bytes > 1 {
        let mut c = Buffer::new(
            &ctx,
            "c",
            &BufferDesc {
                size_bytes: 256,
                usage,
            },
        )
        .expect("c");
        let err = c.bind(&block, 1).expect_err("misaligned");
        assert!(err.to_string().contains("alignment"), "{err}");
        let err = c
            .bind(&block, block.size_bytes())
            .expect_err("past the end");
        assert!(err.to_string().contains("memory holds"), "{err}");
    }
    b.bind(&block, offset_b).expect("bind b");
    assert_eq!(b.binding().map(|(_, o)| o), Some(offset_b));

    let data: Vec<u32> = (0..64).map(|i| i * 7 + 1).collect();
    a.write(0, &data).expect("write a");
    b.write(0, &[0u32; 64]).expect("zero b");
    let mut rec = ctx.record("copy").expect("recorder");
    rec.copy_buffer(&a, 16, &b, 0, 240).expect("copy");
    let err = rec
        .copy_buffer(&a, 200, &b, 0, 100)
        .expect_err("out of range copy");
    assert!(err.to_string().contains("out of range"), "{err}");
    rec.submit_and_wait().expect("submit");
    let got: Vec<u32> = b.read_vec(0, 60).expect("read b");
    assert_eq!(got, data[4..].to_vec());
    // Host writes outside the buffer are refused.
    assert!(a.write_bytes(250, &[0u8; 8]).is_err());
    drop((a, b));
    assert_eq!(
        ctx.allocation_count(),
        before + 1,
        "buffers do not own the block"
    );
    drop(block);
    assert_eq!(ctx.allocation_count(), before);
    assert_no_validation_errors(&ctx);
}

#[test]
fn mapped_ranges_of_one_block_are_lent_at_once_disjoint_and_filled_exactly() {
    let Some(ctx) = context_or_skip("mapped_ranges", Requirement::Compute) else {
        return;
    };
    let desc = BufferDesc {
        size_bytes: 4096,
        usage: BufferUsage::TRANSFER_SRC,
    };
    let mut a = Buffer::new(&ctx, "a", &desc).expect("a");
    let mut b = Buffer::new(&ctx, "b", &desc).expect("b");
    let r = a.memory_requirements();
    let type_index = ctx
        .memory_type_index(MemoryLocation::Upload, r.memory_type_bits)
        .expect("host-visible type");
    let offset_b = r.size_bytes.next_multiple_of(r.alignment_bytes);
    let block = DeviceMemory::allocate(
        &ctx,
        offset_b + r.size_bytes,
        type_index,
        MemoryLocation::Upload,
    )
    .expect("block");
    a.bind(&block, 0).expect("bind a");
    b.bind(&block, offset_b).expect("bind b");
    a.write_bytes(0, &[0u8; 4096]).expect("zero a");
    b.write_bytes(0, &[0u8; 4096]).expect("zero b");
    // Ranges in both buffers of the block, out of order, each filled from its own thread with
    // its index: every byte of every range is written once, nothing outside them.
    fn mapped<'b>(ranges: &[(&'b Buffer, u64, usize)]) -> Vec<MappedRange<'b>> {
        ranges
            .iter()
            .map(|&(buffer, offset, len)| MappedRange {
                buffer,
                offset,
                len,
            })
            .collect()
    }
    let list = mapped(&[(&b, 1000, 24), (&a, 0, 100), (&a, 100, 3000), (&b, 0, 1000)]);
    let lens = with_mapped_ranges_mut(&list, |slices| {
        std::thread::scope(|s| {
            for (i, slice) in slices.iter_mut().enumerate() {
                s.spawn(move || {
                    for byte in slice.iter_mut() {
                        *byte += i as u8 + 1;
                    }
                });
            }
        });
        slices.iter().map(|s| s.len()).collect::<Vec<_>>()
    })
    .expect("disjoint ranges");
    assert_eq!(lens, vec![24, 100, 3000, 1000], "slices in the order given");
    let (mut got_a, mut got_b) = (vec![0u8; 4096], vec![0u8; 4096]);
    a.read_bytes(0, &mut got_a).expect("read a");
    b.read_bytes(0, &mut got_b).expect("read b");
    let mut want_a = vec![0u8; 4096];
    want_a[..100].fill(2);
    want_a[100..3100].fill(3);
    let mut want_b = vec![0u8; 4096];
    want_b[..1000].fill(4);
    want_b[1000..1024].fill(1);
    assert!(
        got_a == want_a && got_b == want_b,
        "each range filled exactly once"
    );
    // Overlap (inside one buffer) and a range past its buffer's end are refused unfilled.
    for (bad, why) in [
        ([(&a, 0, 100), (&a, 99, 10)], "overlap"),
        ([(&b, 0, 10), (&b, 4090, 10)], "exceeds"),
    ] {
        let list = mapped(&bad);
        let err = with_mapped_ranges_mut(&list, |_| panic!("filled despite {why}")).expect_err(why);
        assert!(err.to_string().contains(why), "{why}: {err}");
    }
    drop((a, b, block));
    assert_no_validation_errors(&ctx);
}

#[test]
fn device_address_is_stable_and_offset_in_a_block() {
    let Some(ctx) = context_or_skip("device_address", Requirement::Compute) else {
        return;
    };
    if !ctx.caps().buffer_device_address {
        eprintln!(
            "SKIPPED: device_address: {} lacks bufferDeviceAddress",
            ctx.device_name()
        );
        return;
    }
    let usage = BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS;
    let buf = Buffer::new_dedicated(
        &ctx,
        "bda",
        &BufferDesc {
            size_bytes: 1024,
            usage,
        },
        MemoryLocation::DeviceLocal,
    )
    .expect("buffer");
    let addr = buf.device_address().expect("address");
    assert_ne!(addr.0, 0);
    assert_eq!(buf.device_address().expect("address again"), addr);
    let plain = Buffer::new_dedicated(
        &ctx,
        "plain",
        &BufferDesc {
            size_bytes: 64,
            usage: BufferUsage::STORAGE,
        },
        MemoryLocation::DeviceLocal,
    )
    .expect("plain");
    assert!(plain.device_address().is_err(), "no DEVICE_ADDRESS usage");
    assert!(
        plain.write_bytes(0, &[1]).is_err(),
        "device-local memory is not mapped"
    );
    assert_no_validation_errors(&ctx);
}

#[test]
fn allocation_count_override_is_enforced() {
    let Some(probe) = context_or_skip("allocation_count_override", Requirement::Compute) else {
        return;
    };
    let device_count = probe.device_limits().max_memory_allocation_count;
    drop(probe);
    let ctx = Context::new(&ContextOptions {
        validation: ValidationRequest::Preferred,
        limit_overrides: LimitOverrides {
            max_memory_allocation_count: Some(2),
            max_memory_allocation_size: Some(1 << 20),
            max_instance_count: Some(1000),
            // Above the device's: must be ignored, not raise the limit.
            max_primitive_count: Some(u64::MAX),
            ..Default::default()
        },
        ..Default::default()
    })
    .expect("context with overrides");
    assert_eq!(
        ctx.limits().max_memory_allocation_count,
        2.min(device_count)
    );
    assert_eq!(
        ctx.limits().max_memory_allocation_size,
        (1 << 20).min(ctx.device_limits().max_memory_allocation_size)
    );
    assert_eq!(
        ctx.limits().max_primitive_count,
        ctx.device_limits().max_primitive_count
    );
    if ctx.caps().acceleration_structure {
        assert_eq!(ctx.limits().max_instance_count, 1000);
    }
    assert!(ctx
        .lowered_limits()
        .contains(&"max_memory_allocation_count"));
    let report = ctx.report();
    assert_eq!(report.name, ctx.device_name());
    assert_eq!(
        report.limits.max_memory_allocation_count,
        2.min(device_count)
    );
    assert!(report
        .limit_overrides
        .contains(&"max_memory_allocation_count"));

    let type_index = ctx
        .memory_type_index(MemoryLocation::Upload, u32::MAX)
        .expect("type");
    let too_big = DeviceMemory::allocate(&ctx, (1 << 20) + 1, type_index, MemoryLocation::Upload);
    assert!(
        matches!(too_big, Err(VkError::AllocationTooLarge { .. })),
        "{too_big:?}"
    );
    let m1 = DeviceMemory::allocate(&ctx, 4096, type_index, MemoryLocation::Upload).expect("1st");
    let m2 = DeviceMemory::allocate(&ctx, 4096, type_index, MemoryLocation::Upload).expect("2nd");
    let third = DeviceMemory::allocate(&ctx, 4096, type_index, MemoryLocation::Upload);
    match third {
        Err(VkError::AllocationCountExceeded {
            limit: 2,
            requested: 3,
        }) => {}
        other => panic!("expected AllocationCountExceeded, got {other:?}"),
    }
    assert_eq!(ctx.allocation_count(), 2);
    assert_eq!(ctx.peak_allocation_count(), 2);
    drop(m1);
    let m3 =
        DeviceMemory::allocate(&ctx, 4096, type_index, MemoryLocation::Upload).expect("slot freed");
    assert_eq!(ctx.allocated_bytes(), 8192);
    drop((m2, m3));
    assert_eq!(ctx.allocation_count(), 0);
    assert_no_validation_errors(&ctx);
}

#[test]
fn list_devices_reports_lavapipe_ray_tracing() {
    let devices = match list_devices() {
        Ok(d) => d,
        Err(e) => {
            if std::env::var(testutil::ENV_REQUIRE_GPU).is_ok_and(|v| v == "1") {
                panic!("MOTU_REQUIRE_GPU=1 but list_devices failed: {e}");
            }
            eprintln!("SKIPPED: no Vulkan device: list_devices: {e}");
            return;
        }
    };
    if devices.is_empty() {
        assert!(
            !std::env::var(testutil::ENV_REQUIRE_GPU).is_ok_and(|v| v == "1"),
            "MOTU_REQUIRE_GPU=1 but no device listed"
        );
        eprintln!("SKIPPED: no Vulkan device: list_devices returned none");
        return;
    }
    for (i, d) in devices.iter().enumerate() {
        assert_eq!(d.index, i);
        assert!(!d.name.is_empty());
        assert!(!d.heaps.is_empty(), "{} has no heaps", d.name);
        let table = d.to_table_string();
        assert!(
            table.contains(&d.name) && table.contains("max_instance_count"),
            "{table}"
        );
        // The CLI contract's keys (CLI.md, `motu devices --json`) are checked on the JSON
        // (`motu_render::stats::DeviceReport`, `tests/tests/cli.rs`).
    }
    match devices.iter().find(|d| d.name.starts_with("llvmpipe")) {
        Some(lp) if lp.driver.contains("Mesa") => {
            // Lavapipe from Mesa >= 24.1 (tools/setup.sh) has both RT paths and these limits.
            assert!(
                lp.ray_pipeline,
                "lavapipe without ray_pipeline: {}",
                lp.driver
            );
            assert!(lp.ray_query, "lavapipe without ray_query: {}", lp.driver);
            assert!(lp.acceleration_structure);
            assert!(lp.memory_budget_ext);
            assert_eq!(lp.device_type, "cpu");
            if lp.limit_overrides.is_empty() {
                assert_eq!(lp.limits.max_instance_count, 16_777_215);
            }
            assert_eq!(lp.limits.shader_group_handle_size, 32);
            assert!(lp.heaps[0].budget_bytes.is_some_and(|b| b > 0));
        }
        _ => eprintln!("note: no lavapipe device listed; lavapipe-specific checks skipped"),
    }
}

#[test]
fn device_selection_errors_are_helpful() {
    let Some(ctx) = context_or_skip("device_selection", Requirement::Compute) else {
        return;
    };
    drop(ctx);
    let err = Context::new(&ContextOptions {
        device_index: Some(999),
        validation: ValidationRequest::Off,
        ..Default::default()
    })
    .expect_err("index 999 must not exist");
    assert!(
        matches!(err, VkError::DeviceIndexOutOfRange { index: 999, .. }),
        "{err}"
    );
    assert!(err.to_string().contains("motu devices"), "{err}");
}

#[test]
fn public_types_are_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<Context>();
    check::<Buffer>();
    check::<DeviceMemory>();
    check::<ComputePipeline>();
    check::<TimestampQueries>();
    check::<DeviceReport>();
}
