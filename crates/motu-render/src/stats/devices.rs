//! `motu devices --json`: every Vulkan device as the device layer reports it (`{"devices":
//! [...]}`); each key is the library field of the same name, the limits flattened into the
//! device's object.

use super::mirror::mirror;
use serde::Serialize;

/// `motu devices --json`.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DeviceList {
    pub devices: Vec<DeviceReport>,
}

impl DeviceList {
    pub fn new(devices: &[motu_gpu::DeviceReport]) -> Self {
        Self {
            devices: devices.iter().map(Into::into).collect(),
        }
    }
}

mirror! {
    /// `motu_gpu::DeviceReport` as JSON.
    DeviceReport from motu_gpu::DeviceReport {
        index: usize,
        name: String,
        driver: String,
        driver_name: String,
        driver_info: String,
        driver_version: String,
        vendor_id: u32,
        device_id: u32,
        device_type: &'static str,
        api_version: String,
        usable: bool,
        unusable_reason: Option<String>,
        acceleration_structure: bool,
        ray_pipeline: bool,
        ray_query: bool,
        buffer_device_address: bool,
        memory_budget_ext: bool,
        caps: Caps,
        #[serde(flatten)]
        limits: Limits,
        heaps: Vec<HeapReport>,
        limit_overrides: Vec<&'static str>,
    }
}

mirror! {
    /// `motu_gpu::Caps` as JSON.
    Caps from motu_gpu::Caps {
        acceleration_structure: bool,
        ray_pipeline: bool,
        ray_query: bool,
        ray_tracing_pipeline_trace_rays_indirect: bool,
        ray_tracing_maintenance1: bool,
        deferred_host_operations: bool,
        buffer_device_address: bool,
        memory_budget: bool,
        spirv_1_4: bool,
        shader_float_controls: bool,
        maintenance4: bool,
        synchronization2: bool,
        timeline_semaphore: bool,
        scalar_block_layout: bool,
        descriptor_indexing: bool,
        shader_int64: bool,
        host_query_reset: bool,
        timestamps: bool,
        pipeline_executable_info: bool,
    }
}

mirror! {
    /// `motu_gpu::Limits` as JSON.
    Limits from motu_gpu::Limits {
        max_instance_count: u64,
        max_primitive_count: u64,
        max_geometry_count: u64,
        max_memory_allocation_count: u32,
        max_memory_allocation_size: u64,
        max_storage_buffer_range: u32,
        max_buffer_size: Option<u64>,
        min_acceleration_structure_scratch_offset_alignment: u32,
        max_descriptor_set_acceleration_structures: u32,
        shader_group_handle_size: u32,
        shader_group_base_alignment: u32,
        shader_group_handle_alignment: u32,
        max_shader_group_stride: u32,
        max_ray_recursion_depth: u32,
        max_ray_hit_attribute_size: u32,
        max_ray_dispatch_invocation_count: u32,
        timestamp_period_ns: f32,
        timestamp_valid_bits: u32,
        max_push_constants_size: u32,
        max_compute_work_group_count: [u32; 3],
        max_compute_work_group_invocations: u32,
        min_storage_buffer_offset_alignment: u64,
        non_coherent_atom_size: u64,
    }
}

mirror! {
    /// `motu_gpu::HeapReport` as JSON.
    HeapReport from motu_gpu::HeapReport {
        index: u32,
        size_bytes: u64,
        budget_bytes: Option<u64>,
        usage_bytes: Option<u64>,
        device_local: bool,
    }
}
