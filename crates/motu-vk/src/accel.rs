//! Acceleration-structure types: build flags and modes, the geometry a build reads, and the
//! motu types builds and copies are recorded with ([`AsBuild`], [`AsGeometry`]; `conv.rs`
//! turns them into Vulkan structs, `build_sizes.rs` asks the device for their sizes).

use ash::vk;
/// Acceleration structures must start at multiples of 256 bytes in their buffer (spec:
/// `VkAccelerationStructureCreateInfoKHR::offset`).
pub const ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT: u64 = 256;

/// Bytes per `VkAccelerationStructureInstanceKHR` in a TLAS instance buffer.
pub const INSTANCE_RECORD_SIZE_BYTES: u64 = 64;

/// One geometry of a bottom-level acceleration structure, described by its counts only.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlasGeometry {
    /// Triangles with `f32 x3` positions (12-byte stride) and optional `u32` indices.
    Triangles {
        vertex_count: u32,
        triangle_count: u32,
        indexed: bool,
        opaque: bool,
    },
    /// Axis-aligned boxes (programmable instances, procedural primitives).
    Aabbs { aabb_count: u32, opaque: bool },
}

impl BlasGeometry {
    pub(crate) fn primitive_count(&self) -> u32 {
        match *self {
            BlasGeometry::Triangles { triangle_count, .. } => triangle_count,
            BlasGeometry::Aabbs { aabb_count, .. } => aabb_count,
        }
    }
}

/// Build flags that change sizes. The default is what motu builds: fast trace + compaction.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AsBuildFlags {
    pub prefer_fast_trace: bool,
    pub prefer_fast_build: bool,
    pub allow_compaction: bool,
    pub allow_update: bool,
    pub low_memory: bool,
}

impl AsBuildFlags {
    /// A TLAS's flags: fast trace, compaction allowed when it will be compacted (the size
    /// query and the build must agree).
    pub fn tlas(compact: bool) -> Self {
        AsBuildFlags {
            allow_compaction: compact,
            ..AsBuildFlags::default()
        }
    }
}

impl Default for AsBuildFlags {
    fn default() -> Self {
        Self {
            prefer_fast_trace: true,
            prefer_fast_build: false,
            allow_compaction: true,
            allow_update: false,
            low_memory: false,
        }
    }
}

/// How triangle BLASes (and the streamer's proxy boxes) are built: what the driver is asked
/// to favour. TLASes are always built for fast trace.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BlasBuild {
    /// Fast trace, compacted: the full build's default, where everything is resident once and
    /// the frame is all tracing.
    #[default]
    FastTrace,
    /// Fast build and low memory, compacted: streaming's default. On the H200 these BLASes
    /// are a fifth smaller (island 0.3: 79 against 99 bytes a triangle) and build faster, so
    /// more of a frame fits its room and a frame builds less; streaming frames are mostly
    /// building, not tracing (BENCHMARKS.md, session 17).
    Small,
}

impl BlasBuild {
    /// The build flags (the same for the size query and the build).
    pub fn flags(self) -> AsBuildFlags {
        match self {
            BlasBuild::FastTrace => AsBuildFlags::default(),
            BlasBuild::Small => AsBuildFlags {
                prefer_fast_trace: false,
                prefer_fast_build: true,
                low_memory: true,
                ..AsBuildFlags::default()
            },
        }
    }

    /// The name `--blas-build` takes and `--stats` reports.
    pub fn name(self) -> &'static str {
        match self {
            BlasBuild::FastTrace => "fast-trace",
            BlasBuild::Small => "small",
        }
    }
}

/// Which level an acceleration structure is: a BLAS over geometry or a TLAS over instances.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AsLevel {
    Bottom,
    Top,
}

/// One geometry of a build, by the device addresses of its inputs (which the caller keeps
/// alive and written until the build's submission was waited on).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AsGeometry {
    /// Triangles: `vertex_count` `f32 x3` positions (12-byte stride) and `u32` indices.
    /// `opaque`: no any-hit; else each candidate reaches any-hit once.
    Triangles {
        positions_address: u64,
        vertex_count: u32,
        indices_address: u64,
        opaque: bool,
    },
    /// Axis-aligned boxes of 24 bytes (min xyz, max xyz) at `address`.
    Aabbs { address: u64, opaque: bool },
    /// A TLAS's instance records ([`INSTANCE_RECORD_SIZE_BYTES`] each) at `address`.
    Instances { address: u64 },
}

/// Whether a build makes a new structure or updates one in place.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AsBuildMode {
    Build,
    /// Refit the destination in place (it was built with `allow_update` over as many
    /// primitives; the spec allows source = destination).
    UpdateInPlace,
}

/// How an acceleration-structure copy treats its source.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AsCopyMode {
    /// Into a structure of the compacted size a query reported (source built with
    /// `allow_compaction`).
    Compact,
    /// A whole copy into a structure of the source's size (moving it to other memory).
    Clone,
}

/// Which hit group an instance's rays run and whether triangles are forced opaque.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum InstanceHit {
    /// Triangles (hit group 0); `any_hit`: alpha-tested, so not forced opaque.
    Triangles { any_hit: bool },
    /// Programmable instances' boxes (hit group 1), never opaque.
    Procedural,
}

/// One structure to build into `dst`: `geometries[i]` holds `primitive_counts[i]` primitives;
/// its scratch starts at `scratch_address` (aligned to the device's scratch alignment).
#[derive(Clone, Copy, Debug)]
pub struct AsBuild<'g> {
    pub level: AsLevel,
    /// The flags the sizes were queried with.
    pub flags: AsBuildFlags,
    pub mode: AsBuildMode,
    pub dst: AsTarget,
    pub geometries: &'g [AsGeometry],
    pub primitive_counts: &'g [u32],
    pub scratch_address: u64,
}

/// An acceleration structure named in a recorded command without borrowing it (see
/// [`crate::CommandRecorder`]: its owner keeps it alive until the submission was waited on).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AsTarget(pub(crate) vk::AccelerationStructureKHR);

/// Worst-case sizes from `vkGetAccelerationStructureBuildSizesKHR` (before compaction).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct AsBuildSizes {
    pub acceleration_structure_size_bytes: u64,
    pub build_scratch_size_bytes: u64,
    pub update_scratch_size_bytes: u64,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::conv::build_flags;
    use crate::error::VkError;
    use crate::testing::{assert_no_validation_errors, context_or_skip};
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
            large.acceleration_structure_size_bytes
                > 100 * small.acceleration_structure_size_bytes / 2,
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
            t4k.acceleration_structure_size_bytes
                > 1000 * t1.acceleration_structure_size_bytes.min(64)
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
}
