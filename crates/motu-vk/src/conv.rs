//! The conversions from motu's types to the Vulkan structs and flags of recorded commands (as
//! wgpu-hal keeps its in `vulkan/conv.rs`): the crates above name geometry, build flags, copy
//! modes, barriers and instance records in motu terms; this module spells them in `vk::`.
//! (A resource's creation flags stay beside its type, e.g. `BufferUsage::to_vk`.)

use ash::vk;

use crate::accel::{AsBuildFlags, AsCopyMode, AsGeometry, AsLevel, InstanceHit};
use crate::barrier::MemoryScope;

pub(crate) fn as_level(level: AsLevel) -> vk::AccelerationStructureTypeKHR {
    match level {
        AsLevel::Bottom => vk::AccelerationStructureTypeKHR::BOTTOM_LEVEL,
        AsLevel::Top => vk::AccelerationStructureTypeKHR::TOP_LEVEL,
    }
}

pub(crate) fn build_flags(flags: AsBuildFlags) -> vk::BuildAccelerationStructureFlagsKHR {
    use vk::BuildAccelerationStructureFlagsKHR as F;
    let mut f = F::empty();
    for (on, flag) in [
        (flags.prefer_fast_trace, F::PREFER_FAST_TRACE),
        (flags.prefer_fast_build, F::PREFER_FAST_BUILD),
        (flags.allow_compaction, F::ALLOW_COMPACTION),
        (flags.allow_update, F::ALLOW_UPDATE),
        (flags.low_memory, F::LOW_MEMORY),
    ] {
        if on {
            f |= flag;
        }
    }
    f
}

pub(crate) fn copy_mode(mode: AsCopyMode) -> vk::CopyAccelerationStructureModeKHR {
    match mode {
        AsCopyMode::Compact => vk::CopyAccelerationStructureModeKHR::COMPACT,
        AsCopyMode::Clone => vk::CopyAccelerationStructureModeKHR::CLONE,
    }
}

/// Opaque geometry runs no any-hit; other geometry records each candidate once (programmable
/// instances and alpha-tested triangles count on it).
pub(crate) fn geometry_flags(opaque: bool) -> vk::GeometryFlagsKHR {
    if opaque {
        vk::GeometryFlagsKHR::OPAQUE
    } else {
        vk::GeometryFlagsKHR::NO_DUPLICATE_ANY_HIT_INVOCATION
    }
}

/// The Vulkan geometry of `g` (its device addresses as given).
pub(crate) fn geometry(g: &AsGeometry) -> vk::AccelerationStructureGeometryKHR<'static> {
    match *g {
        AsGeometry::Triangles {
            positions_address,
            vertex_count,
            indices_address,
            opaque,
        } => {
            let triangles = vk::AccelerationStructureGeometryTrianglesDataKHR::default()
                .vertex_format(vk::Format::R32G32B32_SFLOAT)
                .vertex_data(vk::DeviceOrHostAddressConstKHR {
                    device_address: positions_address,
                })
                .vertex_stride(12)
                .max_vertex(vertex_count.saturating_sub(1))
                .index_type(vk::IndexType::UINT32)
                .index_data(vk::DeviceOrHostAddressConstKHR {
                    device_address: indices_address,
                });
            vk::AccelerationStructureGeometryKHR::default()
                .geometry_type(vk::GeometryTypeKHR::TRIANGLES)
                .geometry(vk::AccelerationStructureGeometryDataKHR { triangles })
                .flags(geometry_flags(opaque))
        }
        AsGeometry::Aabbs { address, opaque } => {
            let aabbs = vk::AccelerationStructureGeometryAabbsDataKHR::default()
                .data(vk::DeviceOrHostAddressConstKHR {
                    device_address: address,
                })
                .stride(std::mem::size_of::<vk::AabbPositionsKHR>() as u64);
            vk::AccelerationStructureGeometryKHR::default()
                .geometry_type(vk::GeometryTypeKHR::AABBS)
                .geometry(vk::AccelerationStructureGeometryDataKHR { aabbs })
                .flags(geometry_flags(opaque))
        }
        AsGeometry::Instances { address } => {
            let instances = vk::AccelerationStructureGeometryInstancesDataKHR::default()
                .array_of_pointers(false)
                .data(vk::DeviceOrHostAddressConstKHR {
                    device_address: address,
                });
            vk::AccelerationStructureGeometryKHR::default()
                .geometry_type(vk::GeometryTypeKHR::INSTANCES)
                .geometry(vk::AccelerationStructureGeometryDataKHR { instances })
        }
    }
}

/// The pipeline stages and accesses of one side of a barrier.
pub(crate) fn memory_scope(scope: MemoryScope) -> (vk::PipelineStageFlags, vk::AccessFlags) {
    match scope {
        MemoryScope::All => (
            vk::PipelineStageFlags::ALL_COMMANDS,
            vk::AccessFlags::MEMORY_WRITE | vk::AccessFlags::MEMORY_READ,
        ),
        MemoryScope::TransferWrites => (
            vk::PipelineStageFlags::TRANSFER,
            vk::AccessFlags::TRANSFER_WRITE,
        ),
        MemoryScope::BuildReads => (
            vk::PipelineStageFlags::ACCELERATION_STRUCTURE_BUILD_KHR,
            vk::AccessFlags::ACCELERATION_STRUCTURE_READ_KHR | vk::AccessFlags::SHADER_READ,
        ),
    }
}

/// One `VkAccelerationStructureInstanceKHR` (64 bytes): triangles use hit group 0 (opaque unless
/// they need any-hit), programmable instances hit group 1, never opaque. A `blas_address` of 0
/// makes the instance inactive (mask 0 as well: some drivers only check the mask). The custom
/// index is `custom_index` (< 2^24, which `max_instance_count` bounds).
pub fn encode_instance(
    tlas_from_blas: &[f32; 12],
    hit: InstanceHit,
    blas_address: u64,
    custom_index: u32,
) -> [u8; 64] {
    let (sbt, flags) = match hit {
        InstanceHit::Procedural => (1u32, vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE),
        InstanceHit::Proxy => (2u32, vk::GeometryInstanceFlagsKHR::FORCE_NO_OPAQUE),
        InstanceHit::Triangles { any_hit: true } => (
            0,
            vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE,
        ),
        InstanceHit::Triangles { any_hit: false } => (
            0,
            vk::GeometryInstanceFlagsKHR::FORCE_OPAQUE
                | vk::GeometryInstanceFlagsKHR::TRIANGLE_FACING_CULL_DISABLE,
        ),
    };
    let mut out = [0u8; 64];
    for (i, v) in tlas_from_blas.iter().enumerate() {
        out[4 * i..4 * i + 4].copy_from_slice(&v.to_le_bytes());
    }
    debug_assert!(
        custom_index < 1 << 24,
        "instance index {custom_index} ≥ 2^24"
    );
    let mask = if blas_address == 0 { 0u32 } else { 0xFF };
    out[48..52].copy_from_slice(&((mask << 24) | (custom_index & 0xFF_FFFF)).to_le_bytes());
    out[52..56].copy_from_slice(&(sbt | (flags.as_raw() << 24)).to_le_bytes());
    out[56..64].copy_from_slice(&blas_address.to_le_bytes());
    out
}
