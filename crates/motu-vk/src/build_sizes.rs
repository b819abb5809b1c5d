//! Build-size queries within the device limits (for the VRAM report and the budgeted
//! builder), and the acceleration-structure extension's device functions.

use ash::vk;

use crate::accel::{AsBuildFlags, AsBuildSizes, BlasGeometry};
use crate::context::Context;
use crate::conv;
use crate::error::{Result, VkError};

impl Context {
    pub(crate) fn accel_device(&self) -> Result<&ash::khr::acceleration_structure::Device> {
        self.shared
            .accel
            .as_ref()
            .ok_or_else(|| VkError::MissingFeature {
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
            return Err(VkError::InvalidRequest(
                "a BLAS needs at least one geometry".into(),
            ));
        }
        let is_triangles = |g: &BlasGeometry| matches!(g, BlasGeometry::Triangles { .. });
        if geometries
            .iter()
            .any(|g| is_triangles(g) != is_triangles(&geometries[0]))
        {
            // VUID-VkAccelerationStructureBuildGeometryInfoKHR-type-03792.
            return Err(VkError::InvalidRequest(
                "a BLAS holds either triangles or AABBs, not both".into(),
            ));
        }
        if geometries.len() as u64 > limits.max_geometry_count {
            return Err(VkError::LimitExceeded {
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
            return Err(VkError::LimitExceeded {
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
                        .flags(conv::geometry_flags(opaque))
                }
                BlasGeometry::Aabbs { opaque, .. } => {
                    let aabbs = vk::AccelerationStructureGeometryAabbsDataKHR::default()
                        .stride(std::mem::size_of::<vk::AabbPositionsKHR>() as u64);
                    vk::AccelerationStructureGeometryKHR::default()
                        .geometry_type(vk::GeometryTypeKHR::AABBS)
                        .geometry(vk::AccelerationStructureGeometryDataKHR { aabbs })
                        .flags(conv::geometry_flags(opaque))
                }
            })
            .collect();
        let counts: Vec<u32> = geometries
            .iter()
            .map(BlasGeometry::primitive_count)
            .collect();
        let info = vk::AccelerationStructureBuildGeometryInfoKHR::default()
            .ty(vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL)
            .flags(conv::build_flags(flags))
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
            return Err(VkError::LimitExceeded {
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
            .flags(conv::build_flags(flags))
            .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
            .geometries(&geometry);
        Ok(query_sizes(accel, &info, &[instance_count]))
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
