use super::*;

fn lavapipe_like() -> Limits {
    Limits {
        max_instance_count: 16_777_215,
        max_primitive_count: 16_777_215,
        max_geometry_count: 16_777_215,
        max_memory_allocation_count: u32::MAX,
        max_memory_allocation_size: 1 << 31,
        max_storage_buffer_range: u32::MAX,
        max_buffer_size: Some(u32::MAX as u64),
        min_acceleration_structure_scratch_offset_alignment: 8,
        max_descriptor_set_acceleration_structures: 1_000_000,
        shader_group_handle_size: 32,
        shader_group_base_alignment: 32,
        shader_group_handle_alignment: 16,
        max_shader_group_stride: 4096,
        max_ray_recursion_depth: 31,
        max_ray_hit_attribute_size: 32,
        max_ray_dispatch_invocation_count: 1 << 26,
        timestamp_period_ns: 1.0,
        timestamp_valid_bits: 64,
        max_push_constants_size: 256,
        max_compute_work_group_count: [65535; 3],
        max_compute_work_group_invocations: 1024,
        min_storage_buffer_offset_alignment: 16,
        non_coherent_atom_size: 64,
    }
}

#[test]
fn parse_size_accepts_units_and_rejects_garbage() {
    let cases: &[(&str, Result<u64, ()>)] = &[
        ("4096", Ok(4096)),
        ("64MiB", Ok(64 << 20)),
        ("2 GiB", Ok(2 << 30)),
        ("1GB", Ok(1_000_000_000)),
        ("8k", Ok(8192)),
        ("", Err(())),
        ("MiB", Err(())),
        ("12 parsecs", Err(())),
        ("99999999999999999999", Err(())),
        ("18446744073709551615GiB", Err(())),
    ];
    for (input, expected) in cases {
        assert_eq!(
            parse_size(input).map_err(|_| ()),
            *expected,
            "input {input:?}"
        );
    }
}

#[test]
fn overrides_only_lower() {
    let mut limits = lavapipe_like();
    let o = LimitOverrides {
        max_memory_allocation_count: Some(8),
        max_memory_allocation_size: Some(u64::MAX), // above the device: ignored
        max_instance_count: Some(1000),
        max_primitive_count: None,
        max_storage_buffer_range: Some(1 << 20),
    };
    let lowered = o.apply(&mut limits);
    assert_eq!(limits.max_memory_allocation_count, 8);
    assert_eq!(limits.max_memory_allocation_size, 1 << 31);
    assert_eq!(limits.max_instance_count, 1000);
    assert_eq!(limits.max_primitive_count, 16_777_215);
    assert_eq!(limits.max_storage_buffer_range, 1 << 20);
    assert_eq!(
        lowered,
        vec![
            "max_memory_allocation_count",
            "max_instance_count",
            "max_storage_buffer_range"
        ]
    );
}

#[test]
fn env_lookup_parses_and_reports_bad_values() {
    let o = LimitOverrides::from_lookup(|name| match name {
        ENV_MAX_ALLOCATIONS => Some("8".into()),
        ENV_MAX_ALLOCATION_SIZE => Some("64MiB".into()),
        _ => None,
    })
    .expect("valid env");
    assert_eq!(o.max_memory_allocation_count, Some(8));
    assert_eq!(o.max_memory_allocation_size, Some(64 << 20));
    assert_eq!(o.max_instance_count, None);

    let err = LimitOverrides::from_lookup(|name| {
        (name == ENV_MAX_INSTANCE_COUNT).then(|| "lots".to_string())
    })
    .expect_err("bad value must be an error");
    assert!(err.to_string().contains(ENV_MAX_INSTANCE_COUNT), "{err}");

    let err = LimitOverrides::from_lookup(|name| {
        (name == ENV_MAX_ALLOCATIONS).then(|| "8GiB".to_string())
    })
    .expect_err("count above u32 must be an error");
    assert!(err.to_string().contains("32 bits"), "{err}");
}

#[test]
fn combine_takes_the_smaller() {
    let a = LimitOverrides {
        max_memory_allocation_count: Some(8),
        max_instance_count: Some(100),
        ..Default::default()
    };
    let b = LimitOverrides {
        max_memory_allocation_count: Some(4),
        max_primitive_count: Some(7),
        ..Default::default()
    };
    let c = a.combine(&b);
    assert_eq!(c.max_memory_allocation_count, Some(4));
    assert_eq!(c.max_instance_count, Some(100));
    assert_eq!(c.max_primitive_count, Some(7));
    assert!(!c.is_empty());
    assert!(LimitOverrides::default().is_empty());
}

/// Errors keep their cause (issue 46): a size that does not parse is the source, typed.
#[test]
fn a_bad_size_in_the_environment_is_the_source() {
    let err = LimitOverrides::from_lookup(|name| {
        (name == ENV_MAX_ALLOCATION_SIZE).then(|| "99999999999999999999999".to_string())
    })
    .unwrap_err();
    let cause = std::error::Error::source(&err).expect("the parse error is the source");
    assert!(matches!(
        cause.downcast_ref::<SizeParseError>(),
        Some(SizeParseError::Digits(_))
    ));
    assert!(err.to_string().contains(ENV_MAX_ALLOCATION_SIZE), "{err}");
}
