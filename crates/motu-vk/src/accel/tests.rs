use super::*;
use crate::conv::build_flags;
use crate::error::VkError;
use crate::testutil::{assert_no_validation_errors, context_or_skip};
use crate::Context;
use crate::{ContextOptions, LimitOverrides, Requirement, ValidationRequest};

#[test]
fn blas_build_modes_ask_for_what_they_name() {
    use vk::BuildAccelerationStructureFlagsKHR as F;
    // Fast trace is what every other build (TLASes, the size model) uses.
    assert_eq!(BlasBuild::FastTrace.flags(), AsBuildFlags::default());
    assert_eq!(
        build_flags(BlasBuild::FastTrace.flags()),
        F::PREFER_FAST_TRACE | F::ALLOW_COMPACTION
    );
    // Small: fast build and low memory, still compacted (streamed BLASes are compacted).
    assert_eq!(
        build_flags(BlasBuild::Small.flags()),
        F::PREFER_FAST_BUILD | F::LOW_MEMORY | F::ALLOW_COMPACTION
    );
    assert_eq!(BlasBuild::default(), BlasBuild::FastTrace);
    assert_eq!(BlasBuild::Small.name(), "small");
    assert_eq!(BlasBuild::FastTrace.name(), "fast-trace");
}

#[test]
fn tlas_build_modes_ask_for_what_they_name() {
    use vk::BuildAccelerationStructureFlagsKHR as F;
    // Fast trace is the TLAS flags every build had before the choice.
    assert_eq!(TlasBuild::FastTrace.flags(true), AsBuildFlags::tlas(true));
    assert_eq!(
        build_flags(TlasBuild::FastTrace.flags(true)),
        F::PREFER_FAST_TRACE | F::ALLOW_COMPACTION
    );
    assert_eq!(
        build_flags(TlasBuild::FastBuild.flags(false)),
        F::PREFER_FAST_BUILD
    );
    assert_eq!(TlasBuild::default(), TlasBuild::FastTrace);
    assert_eq!(TlasBuild::FastBuild.name(), "fast-build");
    assert_eq!(TlasBuild::FastTrace.name(), "fast-trace");
}

fn tris(n: u32) -> BlasGeometry {
    BlasGeometry::Triangles {
        vertex_count: n * 3,
        triangle_count: n,
        indexed: true,
        opaque: true,
    }
}

#[test]
fn build_sizes_grow_with_primitive_and_instance_counts() {
    let Some(ctx) = context_or_skip("as_build_sizes", Requirement::RayTracing) else {
        return;
    };
    let flags = AsBuildFlags::default();
    let small = ctx
        .blas_build_sizes(&[tris(64)], flags)
        .expect("small BLAS");
    let large = ctx
        .blas_build_sizes(&[tris(65_536)], flags)
        .expect("large BLAS");
    assert!(small.acceleration_structure_size_bytes > 0);
    assert!(small.build_scratch_size_bytes > 0);
    assert!(
        large.acceleration_structure_size_bytes > 100 * small.acceleration_structure_size_bytes / 2,
        "{small:?} vs {large:?}"
    );
    let per_triangle = large.acceleration_structure_size_bytes as f64 / 65_536.0;
    assert!(
        (8.0..1024.0).contains(&per_triangle),
        "{per_triangle} bytes per triangle"
    );

    let aabbs = ctx
        .blas_build_sizes(
            &[BlasGeometry::Aabbs {
                aabb_count: 4096,
                opaque: false,
            }],
            flags,
        )
        .expect("AABB BLAS");
    assert!(aabbs.acceleration_structure_size_bytes > 0);
    let two = ctx
        .blas_build_sizes(&[tris(64), tris(64)], flags)
        .expect("two triangle geometries");
    assert!(two.acceleration_structure_size_bytes > small.acceleration_structure_size_bytes);
    let mixed = ctx.blas_build_sizes(
        &[
            tris(64),
            BlasGeometry::Aabbs {
                aabb_count: 1,
                opaque: true,
            },
        ],
        flags,
    );
    assert!(mixed.is_err(), "triangles and AABBs cannot share a BLAS");

    let t1 = ctx.tlas_build_sizes(1, flags).expect("TLAS 1");
    let t4k = ctx.tlas_build_sizes(4096, flags).expect("TLAS 4096");
    assert!(t1.acceleration_structure_size_bytes > 0);
    assert!(
        t4k.acceleration_structure_size_bytes > 1000 * t1.acceleration_structure_size_bytes.min(64)
    );
    assert!(t4k.acceleration_structure_size_bytes > t1.acceleration_structure_size_bytes);
    let max = u32::try_from(ctx.limits().max_instance_count).unwrap_or(u32::MAX);
    ctx.tlas_build_sizes(max, flags)
        .expect("TLAS at the instance limit");
    assert_no_validation_errors(&ctx);
}

#[test]
fn build_sizes_respect_lowered_limits() {
    let Some(probe) = context_or_skip("as_build_size_limits", Requirement::RayTracing) else {
        return;
    };
    let validation = if probe.validation_enabled() {
        ValidationRequest::Required
    } else {
        ValidationRequest::Off
    };
    drop(probe);
    let ctx = Context::new(&ContextOptions {
        validation,
        require: Requirement::RayTracing,
        limit_overrides: LimitOverrides {
            max_instance_count: Some(100),
            max_primitive_count: Some(1000),
            ..Default::default()
        },
        ..Default::default()
    })
    .expect("context");
    let flags = AsBuildFlags::default();
    ctx.tlas_build_sizes(100, flags).expect("at the limit");
    let err = ctx
        .tlas_build_sizes(101, flags)
        .expect_err("over the limit");
    assert!(
        matches!(
            err,
            VkError::LimitExceeded {
                requested: 101,
                limit: 100,
                ..
            }
        ),
        "{err}"
    );
    ctx.blas_build_sizes(&[tris(600), tris(400)], flags)
        .expect("1000 primitives");
    let err = ctx
        .blas_build_sizes(&[tris(600), tris(401)], flags)
        .expect_err("1001 primitives");
    assert!(err.to_string().contains("max_primitive_count"), "{err}");
    assert!(ctx.blas_build_sizes(&[], flags).is_err());
    assert_no_validation_errors(&ctx);
}
