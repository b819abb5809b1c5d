//! Acceleration-structure basics: build-size queries within the device limits (for the VRAM
//! report and the budgeted builder). Builds themselves come with the AS-build issue.

use ash::vk;
use serde::Serialize;

use crate::context::Context;
use crate::error::{GpuError, Result};

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
    fn primitive_count(&self) -> u32 {
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

impl AsBuildFlags {
    pub(crate) fn to_vk(self) -> vk::BuildAccelerationStructureFlagsKHR {
        use vk::BuildAccelerationStructureFlagsKHR as F;
        let mut f = F::empty();
        for (on, flag) in [
            (self.prefer_fast_trace, F::PREFER_FAST_TRACE),
            (self.prefer_fast_build, F::PREFER_FAST_BUILD),
            (self.allow_compaction, F::ALLOW_COMPACTION),
            (self.allow_update, F::ALLOW_UPDATE),
            (self.low_memory, F::LOW_MEMORY),
        ] {
            if on {
                f |= flag;
            }
        }
        f
    }
}

/// Worst-case sizes from `vkGetAccelerationStructureBuildSizesKHR` (before compaction).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct AsBuildSizes {
    pub acceleration_structure_size_bytes: u64,
    pub build_scratch_size_bytes: u64,
    pub update_scratch_size_bytes: u64,
}

impl Context {
    pub(crate) fn accel_device(&self) -> Result<&ash::khr::acceleration_structure::Device> {
        self.shared
            .accel
            .as_ref()
            .ok_or_else(|| GpuError::MissingFeature {
                what: "VK_KHR_acceleration_structure".into(),
                details: format!("#{} {}", self.device_index(), self.device_name()),
            })
    }

    /// Sizes for a BLAS over `geometries`, checked against the geometry and primitive limits
    /// in force (so lowered test limits apply).
    pub fn blas_build_sizes(
        &self,
        geometries: &[BlasGeometry],
        flags: AsBuildFlags,
    ) -> Result<AsBuildSizes> {
        let accel = self.accel_device()?;
        let limits = self.limits();
        if geometries.is_empty() {
            return Err(GpuError::InvalidRequest(
                "a BLAS needs at least one geometry".into(),
            ));
        }
        let is_triangles = |g: &BlasGeometry| matches!(g, BlasGeometry::Triangles { .. });
        if geometries
            .iter()
            .any(|g| is_triangles(g) != is_triangles(&geometries[0]))
        {
            // VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03792.
            return Err(GpuError::InvalidRequest(
                "a BLAS holds either triangles or AABBs, not both".into(),
            ));
        }
        if geometries.len() as u64 > limits.max_geometry_count {
            return Err(GpuError::LimitExceeded {
                what: "geometries per BLAS (max_geometry_count)",
                requested: geometries.len() as u64,
                limit: limits.max_geometry_count,
            });
        }
        let primitives: u64 = geometries
            .iter()
            .map(|g| u64::from(g.primitive_count()))
            .sum();
        if primitives > limits.max_primitive_count {
            return Err(GpuError::LimitExceeded {
                what: "primitives per BLAS (max_primitive_count)",
                requested: primitives,
                limit: limits.max_primitive_count,
            });
        }
        let vk_geometries: Vec<vk::AccelerationStructureGeometryKHR<'_>> = geometries
            .iter()
            .map(|g| match *g {
                BlasGeometry::Triangles {
                    vertex_count,
                    indexed,
                    opaque,
                    ..
                } => {
                    let triangles = vk::AccelerationStructureGeometryTrianglesDataKHR::default()
                        .vertex_format(vk::Format::R32G32B32_SFLOAT)
                        .vertex_stride(12)
                        .max_vertex(vertex_count.saturating_sub(1))
                        .index_type(if indexed {
                            vk::IndexType::UINT32
                        } else {
                            vk::IndexType::NONE_KHR
                        });
                    vk::AccelerationStructureGeometryKHR::default()
                        .geometry_type(vk::GeometryTypeKHR::TRIANGLES)
                        .geometry(vk::AccelerationStructureGeometryDataKHR { triangles })
                        .flags(geometry_flags(opaque))
                }
                BlasGeometry::Aabbs { opaque, .. } => {
                    let aabbs = vk::AccelerationStructureGeometryAabbsDataKHR::default()
                        .stride(std::mem::size_of::<vk::AabbPositionsKHR>() as u64);
                    vk::AccelerationStructureGeometryKHR::default()
                        .geometry_type(vk::GeometryTypeKHR::AABBS)
                        .geometry(vk::AccelerationStructureGeometryDataKHR { aabbs })
                        .flags(geometry_flags(opaque))
                }
            })
            .collect();
        let counts: Vec<u32> = geometries
            .iter()
            .map(BlasGeometry::primitive_count)
            .collect();
        let info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL)
            .flags(flags.to_vk())
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&vk_geometries);
        Ok(query_sizes(accel, &info, &counts))
    }

    /// Sizes for a TLAS over `instance_count` instances, checked against `max_instance_count`.
    pub fn tlas_build_sizes(
        &self,
        instance_count: u32,
        flags: AsBuildFlags,
    ) -> Result<AsBuildSizes> {
        let accel = self.accel_device()?;
        let limit = self.limits().max_instance_count;
        if u64::from(instance_count) > limit {
            return Err(GpuError::LimitExceeded {
                what: "instances per TLAS (max_instance_count)",
                requested: u64::from(instance_count),
                limit,
            });
        }
        let instances =
            vk::AccelerationStructureGeometryInstancesDataKHR::default().array_of_pointers(false);
        let geometry = [vk::AccelerationStructureGeometryKHR::default()
            .geometry_type(vk::GeometryTypeKHR::INSTANCES)
            .geometry(vk::AccelerationStructureGeometryDataKHR { instances })];
        let info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::TOP_LEVEL)
            .flags(flags.to_vk())
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&geometry);
        Ok(query_sizes(accel, &info, &[instance_count]))
    }
}

fn geometry_flags(opaque: bool) -> vk::GeometryFlagsKHR {
    if opaque {
        vk::GeometryFlagsKHR::OPAQUE
    } else {
        // Programmable instances record every candidate once in any-hit.
        vk::GeometryFlagsKHR::NO_DUPLICATE_ANY_HIT_INVOCATION
    }
}

fn query_sizes(
    accel: &ash::khr::acceleration_structure::Device,
    info: &vk::AccelerationStructureBuildGeometryInfoKHR<'_>,
    counts: &[u32],
) -> AsBuildSizes {
    let mut sizes = vk::AccelerationStructureBuildSizesInfoKHR::default();
    // SAFETY: the extension and feature are enabled (accel exists only then); `counts` has one
    // entry per geometry; device addresses in `info` are ignored by this query.
    unsafe {
        accel.get_acceleration_structure_build_sizes(
            vk::AccelerationStructureBuildTypeKHR::DEVICE,
            info,
            counts,
            &mut sizes,
        )
    };
    AsBuildSizes {
        acceleration_structure_size_bytes: sizes.acceleration_structure_size,
        build_scratch_size_bytes: sizes.build_scratch_size,
        update_scratch_size_bytes: sizes.update_scratch_size,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::{assert_no_validation_errors, context_or_skip};
    use crate::{ContextOptions, LimitOverrides, Requirement, ValidationRequest};

    #[test]
    fn blas_build_modes_ask_for_what_they_name() {
        use vk::BuildAccelerationStructureFlagsKHR as F;
        // Fast trace is what every other build (TLASes, the size model) uses.
        assert_eq!(BlasBuild::FastTrace.flags(), AsBuildFlags::default());
        assert_eq!(
            BlasBuild::FastTrace.flags().to_vk(),
            F::PREFER_FAST_TRACE | F::ALLOW_COMPACTION
        );
        // Small: fast build and low memory, still compacted (streamed BLASes are compacted).
        assert_eq!(
            BlasBuild::Small.flags().to_vk(),
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
                GpuError::LimitExceeded {
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
