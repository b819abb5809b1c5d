//! What a physical device offers: extensions, features, limits, heaps. Shared by
//! `list_devices` and `Context::new`, so the report and the context never disagree.

use std::collections::BTreeSet;
use std::ffi::{CStr, CString};

use crate::error::{Result, VkError};
use crate::instance::version_string;
use crate::limits::Limits;
use ash::vk;

/// What the device (as opened) can do. Ray-tracing flags require both the extension and its
/// feature bit, plus acceleration structures and buffer device address.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Caps {
    pub acceleration_structure: bool,
    /// `VK_KHR_ray_tracing_pipeline` usable (the H200 path).
    pub ray_pipeline: bool,
    /// `VK_KHR_ray_query` usable (absent on the H200).
    pub ray_query: bool,
    pub ray_tracing_pipeline_trace_rays_indirect: bool,
    pub ray_tracing_maintenance1: bool,
    pub deferred_host_operations: bool,
    pub buffer_device_address: bool,
    /// `VK_EXT_memory_budget`: per-heap budget and usage.
    pub memory_budget: bool,
    pub spirv_1_4: bool,
    pub shader_float_controls: bool,
    pub maintenance4: bool,
    pub synchronization2: bool,
    pub timeline_semaphore: bool,
    pub scalar_block_layout: bool,
    pub descriptor_indexing: bool,
    pub shader_int64: bool,
    pub host_query_reset: bool,
    /// Timestamps on the queue motu uses (`timestampValidBits > 0`).
    pub timestamps: bool,
    /// `VK_KHR_pipeline_executable_properties` with `pipelineExecutableInfo`: the driver's
    /// statistics of compiled shaders (`ContextOptions::pipeline_stats`).
    pub pipeline_executable_info: bool,
}

/// One memory heap with its `VK_EXT_memory_budget` numbers (`None` without the extension).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct HeapReport {
    pub index: u32,
    pub size_bytes: u64,
    pub budget_bytes: Option<u64>,
    pub usage_bytes: Option<u64>,
    pub device_local: bool,
}

/// Everything probed from one physical device.
#[derive(Clone)]
pub(crate) struct PhysicalInfo {
    pub(crate) index: usize,
    pub(crate) handle: vk::PhysicalDevice,
    pub(crate) name: String,
    pub(crate) device_type: &'static str,
    pub(crate) vendor_id: u32,
    pub(crate) device_id: u32,
    pub(crate) device_api_version: u32,
    /// min(instance API, device API): what may be used.
    pub(crate) api_version: u32,
    pub(crate) driver_name: String,
    pub(crate) driver_info: String,
    pub(crate) driver_version: u32,
    pub(crate) extensions: BTreeSet<CString>,
    pub(crate) caps: Caps,
    pub(crate) limits: Limits,
    pub(crate) queue_family_index: Option<u32>,
    pub(crate) memory: vk::PhysicalDeviceMemoryProperties,
    /// Supported feature bits (p_next cleared), to enable a chosen subset at device creation.
    pub(crate) features: FeatureSet,
}

/// Copies of the queried feature structs with `p_next` nulled.
#[derive(Clone, Copy, Default)]
pub(crate) struct FeatureSet {
    pub(crate) f10: vk::PhysicalDeviceFeatures,
    pub(crate) f11: vk::PhysicalDeviceVulkan11Features<'static>,
    pub(crate) f12: vk::PhysicalDeviceVulkan12Features<'static>,
    pub(crate) f13: vk::PhysicalDeviceVulkan13Features<'static>,
    pub(crate) m4: vk::PhysicalDeviceMaintenance4Features<'static>,
    pub(crate) accel: vk::PhysicalDeviceAccelerationStructureFeaturesKHR<'static>,
    pub(crate) rt: vk::PhysicalDeviceRayTracingPipelineFeaturesKHR<'static>,
    pub(crate) rq: vk::PhysicalDeviceRayQueryFeaturesKHR<'static>,
    pub(crate) pe: vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR<'static>,
}

impl PhysicalInfo {
    pub(crate) fn driver_version_string(&self) -> String {
        let v = self.driver_version;
        if self.vendor_id == 0x10DE {
            // NVIDIA packs 10.8.8.6 bits.
            format!(
                "{}.{}.{}",
                (v >> 22) & 0x3ff,
                (v >> 14) & 0xff,
                (v >> 6) & 0xff
            )
        } else {
            version_string(v)
        }
    }

    /// Why a context cannot be created on this device, if it cannot.
    pub(crate) fn unusable_reason(&self) -> Option<String> {
        if self.api_version < vk::API_VERSION_1_2 {
            return Some(format!(
                "Vulkan {} (device {}); motu needs 1.2",
                version_string(self.api_version),
                version_string(self.device_api_version)
            ));
        }
        if self.queue_family_index.is_none() {
            return Some("no compute queue".into());
        }
        None
    }

    /// What is missing for ray tracing, for error messages.
    pub(crate) fn rt_missing(&self) -> Vec<&'static str> {
        let mut m = Vec::new();
        if !self.caps.acceleration_structure {
            m.push("VK_KHR_acceleration_structure");
        }
        if !self.caps.buffer_device_address {
            m.push("bufferDeviceAddress");
        }
        if !self.caps.ray_pipeline && !self.caps.ray_query {
            m.push("VK_KHR_ray_tracing_pipeline or VK_KHR_ray_query");
        }
        m
    }
}

pub(crate) fn enumerate(instance: &ash::Instance, instance_api: u32) -> Result<Vec<PhysicalInfo>> {
    // SAFETY: `instance` is a live instance.
    let handles = unsafe { instance.enumerate_physical_devices() }
        .map_err(VkError::vk("vkEnumeratePhysicalDevices"))?;
    handles
        .into_iter()
        .enumerate()
        .map(|(index, handle)| probe(instance, instance_api, index, handle))
        .collect()
}

fn probe(
    instance: &ash::Instance,
    instance_api: u32,
    index: usize,
    handle: vk::PhysicalDevice,
) -> Result<PhysicalInfo> {
    // SAFETY: `handle` was enumerated from this live instance.
    let props = unsafe { instance.get_physical_device_properties(handle) };
    let api_version = props.api_version.min(instance_api);
    // SAFETY: as above.
    let ext_props = unsafe { instance.enumerate_device_extension_properties(handle) }
        .map_err(VkError::vk("vkEnumerateDeviceExtensionProperties"))?;
    let extensions: BTreeSet<CString> = ext_props
        .iter()
        .filter_map(|e| e.extension_name_as_c_str().ok().map(CStr::to_owned))
        .collect();
    let support = Support::new(api_version, &extensions);
    let more = MoreProperties::query(instance, handle, &support);
    let features = FeatureSet::query(instance, handle, &support);
    let queue = QueuePick::new(instance, handle);
    // SAFETY: live physical device.
    let memory = unsafe { instance.get_physical_device_memory_properties(handle) };
    let caps = support.caps(&features, queue.timestamp_valid_bits);
    let limits = more.limits(&props.limits, &support, queue.timestamp_valid_bits);

    let c_string = |r: std::result::Result<&CStr, _>| {
        r.map(|s: &CStr| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    };
    Ok(PhysicalInfo {
        index,
        handle,
        name: c_string(props.device_name_as_c_str()),
        device_type: match props.device_type {
            vk::PhysicalDeviceType::DISCRETE_GPU => "discrete_gpu",
            vk::PhysicalDeviceType::INTEGRATED_GPU => "integrated_gpu",
            vk::PhysicalDeviceType::VIRTUAL_GPU => "virtual_gpu",
            vk::PhysicalDeviceType::CPU => "cpu",
            _ => "other",
        },
        vendor_id: props.vendor_id,
        device_id: props.device_id,
        device_api_version: props.api_version,
        api_version,
        driver_name: if support.v12 {
            c_string(more.driver.driver_name_as_c_str())
        } else {
            String::new()
        },
        driver_info: if support.v12 {
            c_string(more.driver.driver_info_as_c_str())
        } else {
            String::new()
        },
        driver_version: props.driver_version,
        extensions,
        caps,
        limits,
        queue_family_index: queue.family.and_then(|i| u32::try_from(i).ok()),
        memory,
        features,
    })
}

/// What the device's API version and extensions allow to be queried and used.
struct Support<'e> {
    extensions: &'e BTreeSet<CString>,
    v12: bool,
    v13: bool,
    has_as: bool,
    has_rt: bool,
    has_rq: bool,
    has_m4: bool,
    has_pe: bool,
}

impl<'e> Support<'e> {
    fn new(api_version: u32, extensions: &'e BTreeSet<CString>) -> Support<'e> {
        let has = |n: &CStr| extensions.contains(n);
        let v13 = api_version >= vk::API_VERSION_1_3;
        Support {
            extensions,
            v12: api_version >= vk::API_VERSION_1_2,
            v13,
            has_as: has(ash::khr::acceleration_structure::NAME),
            has_rt: has(ash::khr::ray_tracing_pipeline::NAME),
            has_rq: has(ash::khr::ray_query::NAME),
            has_m4: v13 || has(ash::khr::maintenance4::NAME),
            has_pe: has(ash::khr::pipeline_executable_properties::NAME),
        }
    }

    fn has(&self, name: &CStr) -> bool {
        self.extensions.contains(name)
    }

    /// The capabilities: an extension and its feature bit (and acceleration structures need
    /// buffer device address and deferred host operations too).
    fn caps(&self, f: &FeatureSet, timestamp_valid_bits: u32) -> Caps {
        let (v12, v13) = (self.v12, self.v13);
        let bda = v12 && f.f12.buffer_device_address == vk::TRUE;
        let accel = self.has_as
            && f.accel.acceleration_structure == vk::TRUE
            && bda
            && self.has(ash::khr::deferred_host_operations::NAME);
        Caps {
            acceleration_structure: accel,
            ray_pipeline: accel && self.has_rt && f.rt.ray_tracing_pipeline == vk::TRUE,
            ray_query: accel && self.has_rq && f.rq.ray_query == vk::TRUE,
            ray_tracing_pipeline_trace_rays_indirect: self.has_rt
                && f.rt.ray_tracing_pipeline_trace_rays_indirect == vk::TRUE,
            ray_tracing_maintenance1: self.has(ash::khr::ray_tracing_maintenance1::NAME),
            deferred_host_operations: self.has(ash::khr::deferred_host_operations::NAME),
            buffer_device_address: bda,
            memory_budget: self.has(ash::ext::memory_budget::NAME),
            spirv_1_4: v12 || self.has(ash::khr::spirv_1_4::NAME),
            shader_float_controls: v12 || self.has(ash::khr::shader_float_controls::NAME),
            maintenance4: if v13 {
                f.f13.maintenance4 == vk::TRUE
            } else {
                self.has_m4 && f.m4.maintenance4 == vk::TRUE
            },
            synchronization2: v13 && f.f13.synchronization2 == vk::TRUE,
            timeline_semaphore: v12 && f.f12.timeline_semaphore == vk::TRUE,
            scalar_block_layout: v12 && f.f12.scalar_block_layout == vk::TRUE,
            descriptor_indexing: v12 && f.f12.descriptor_indexing == vk::TRUE,
            shader_int64: f.f10.shader_int64 == vk::TRUE,
            host_query_reset: v12 && f.f12.host_query_reset == vk::TRUE,
            timestamps: timestamp_valid_bits > 0,
            pipeline_executable_info: self.has_pe && f.pe.pipeline_executable_info == vk::TRUE,
        }
    }
}

/// The extended properties (p_next cleared): those a device's version and extensions have.
struct MoreProperties {
    driver: vk::PhysicalDeviceDriverProperties<'static>,
    m3: vk::PhysicalDeviceMaintenance3Properties<'static>,
    m4: vk::PhysicalDeviceMaintenance4Properties<'static>,
    accel: vk::PhysicalDeviceAccelerationStructurePropertiesKHR<'static>,
    rt: vk::PhysicalDeviceRayTracingPipelinePropertiesKHR<'static>,
}

impl MoreProperties {
    fn query(instance: &ash::Instance, handle: vk::PhysicalDevice, support: &Support<'_>) -> Self {
        // Chain only structs whose version/extension the device supports.
        let mut driver = vk::PhysicalDeviceDriverProperties::default();
        let mut m3 = vk::PhysicalDeviceMaintenance3Properties::default();
        let mut m4 = vk::PhysicalDeviceMaintenance4Properties::default();
        let mut as_props = vk::PhysicalDeviceAccelerationStructurePropertiesKHR::default();
        let mut rt_props = vk::PhysicalDeviceRayTracingPipelinePropertiesKHR::default();
        {
            let mut p2 = vk::PhysicalDeviceProperties2::default().push_next(&mut m3);
            if support.v12 {
                p2 = p2.push_next(&mut driver);
            }
            if support.has_m4 {
                p2 = p2.push_next(&mut m4);
            }
            if support.has_as {
                p2 = p2.push_next(&mut as_props);
            }
            if support.has_rt {
                p2 = p2.push_next(&mut rt_props);
            }
            // SAFETY: every chained struct is valid for this device's version/extensions.
            unsafe { instance.get_physical_device_properties2(handle, &mut p2) };
        }
        let null = std::ptr::null_mut();
        MoreProperties {
            driver: vk::PhysicalDeviceDriverProperties {
                p_next: null,
                ..driver
            },
            m3: vk::PhysicalDeviceMaintenance3Properties { p_next: null, ..m3 },
            m4: vk::PhysicalDeviceMaintenance4Properties { p_next: null, ..m4 },
            accel: vk::PhysicalDeviceAccelerationStructurePropertiesKHR {
                p_next: null,
                ..as_props
            },
            rt: vk::PhysicalDeviceRayTracingPipelinePropertiesKHR {
                p_next: null,
                ..rt_props
            },
        }
    }

    /// The limits motu checks and sizes by (acceleration-structure counts 0 without the
    /// extension).
    fn limits(
        &self,
        l: &vk::PhysicalDeviceLimits,
        support: &Support<'_>,
        timestamp_valid_bits: u32,
    ) -> Limits {
        let (as_props, rt_props) = (&self.accel, &self.rt);
        let has_as = support.has_as;
        Limits {
            max_instance_count: if has_as {
                as_props.max_instance_count
            } else {
                0
            },
            max_primitive_count: if has_as {
                as_props.max_primitive_count
            } else {
                0
            },
            max_geometry_count: if has_as {
                as_props.max_geometry_count
            } else {
                0
            },
            max_memory_allocation_count: l.max_memory_allocation_count,
            max_memory_allocation_size: self.m3.max_memory_allocation_size,
            max_storage_buffer_range: l.max_storage_buffer_range,
            max_buffer_size: support.has_m4.then_some(self.m4.max_buffer_size),
            min_acceleration_structure_scratch_offset_alignment: as_props
                .min_acceleration_structure_scratch_offset_alignment,
            max_descriptor_set_acceleration_structures: as_props
                .max_descriptor_set_acceleration_structures,
            shader_group_handle_size: rt_props.shader_group_handle_size,
            shader_group_base_alignment: rt_props.shader_group_base_alignment,
            shader_group_handle_alignment: rt_props.shader_group_handle_alignment,
            max_shader_group_stride: rt_props.max_shader_group_stride,
            max_ray_recursion_depth: rt_props.max_ray_recursion_depth,
            max_ray_hit_attribute_size: rt_props.max_ray_hit_attribute_size,
            max_ray_dispatch_invocation_count: rt_props.max_ray_dispatch_invocation_count,
            timestamp_period_ns: l.timestamp_period,
            timestamp_valid_bits,
            max_push_constants_size: l.max_push_constants_size,
            max_compute_work_group_count: l.max_compute_work_group_count,
            max_compute_work_group_invocations: l.max_compute_work_group_invocations,
            min_storage_buffer_offset_alignment: l.min_storage_buffer_offset_alignment,
            non_coherent_atom_size: l.non_coherent_atom_size,
        }
    }
}

impl FeatureSet {
    /// The supported feature bits: only structs the device's version and extensions have.
    fn query(instance: &ash::Instance, handle: vk::PhysicalDevice, support: &Support<'_>) -> Self {
        let mut f11 = vk::PhysicalDeviceVulkan11Features::default();
        let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
        let mut f13 = vk::PhysicalDeviceVulkan13Features::default();
        let mut f_as = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default();
        let mut f_rt = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default();
        let mut f_rq = vk::PhysicalDeviceRayQueryFeaturesKHR::default();
        let mut f_m4 = vk::PhysicalDeviceMaintenance4Features::default();
        let mut f_pe = vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default();
        let f10;
        {
            let mut f2 = vk::PhysicalDeviceFeatures2::default();
            if support.v12 {
                f2 = f2.push_next(&mut f11).push_next(&mut f12);
            }
            if support.v13 {
                f2 = f2.push_next(&mut f13);
            } else if support.has_m4 {
                f2 = f2.push_next(&mut f_m4);
            }
            if support.has_as {
                f2 = f2.push_next(&mut f_as);
            }
            if support.has_rt {
                f2 = f2.push_next(&mut f_rt);
            }
            if support.has_rq {
                f2 = f2.push_next(&mut f_rq);
            }
            if support.has_pe {
                f2 = f2.push_next(&mut f_pe);
            }
            // SAFETY: as for the properties chain.
            unsafe { instance.get_physical_device_features2(handle, &mut f2) };
            f10 = f2.features;
        }
        FeatureSet {
            f10,
            f11: vk::PhysicalDeviceVulkan11Features {
                p_next: std::ptr::null_mut(),
                ..f11
            },
            f12: vk::PhysicalDeviceVulkan12Features {
                p_next: std::ptr::null_mut(),
                ..f12
            },
            f13: vk::PhysicalDeviceVulkan13Features {
                p_next: std::ptr::null_mut(),
                ..f13
            },
            m4: vk::PhysicalDeviceMaintenance4Features {
                p_next: std::ptr::null_mut(),
                ..f_m4
            },
            accel: vk::PhysicalDeviceAccelerationStructureFeaturesKHR {
                p_next: std::ptr::null_mut(),
                ..f_as
            },
            rt: vk::PhysicalDeviceRayTracingPipelineFeaturesKHR {
                p_next: std::ptr::null_mut(),
                ..f_rt
            },
            rq: vk::PhysicalDeviceRayQueryFeaturesKHR {
                p_next: std::ptr::null_mut(),
                ..f_rq
            },
            pe: vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR {
                p_next: std::ptr::null_mut(),
                ..f_pe
            },
        }
    }
}

/// The queue motu uses: a universal (graphics+compute) one if there is one (it is the one
/// guaranteed timestamps and the one drivers optimise AS builds on), else any compute queue.
struct QueuePick {
    family: Option<usize>,
    timestamp_valid_bits: u32,
}

impl QueuePick {
    fn new(instance: &ash::Instance, handle: vk::PhysicalDevice) -> QueuePick {
        // SAFETY: live physical device.
        let families = unsafe { instance.get_physical_device_queue_family_properties(handle) };
        let family = families
            .iter()
            .position(|f| {
                f.queue_flags
                    .contains(vk::QueueFlags::GRAPHICS | vk::QueueFlags::COMPUTE)
            })
            .or_else(|| {
                families
                    .iter()
                    .position(|f| f.queue_flags.contains(vk::QueueFlags::COMPUTE))
            });
        QueuePick {
            family,
            timestamp_valid_bits: family.map_or(0, |i| families[i].timestamp_valid_bits),
        }
    }
}

/// Current heap sizes and, with `VK_EXT_memory_budget`, budgets and usage.
pub(crate) fn heaps(
    instance: &ash::Instance,
    handle: vk::PhysicalDevice,
    has_budget: bool,
) -> Vec<HeapReport> {
    let mut budget = vk::PhysicalDeviceMemoryBudgetPropertiesEXT::default();
    let mut p2 = vk::PhysicalDeviceMemoryProperties2::default();
    if has_budget {
        p2 = p2.push_next(&mut budget);
    }
    // SAFETY: live physical device; the budget struct is chained only with the extension.
    unsafe { instance.get_physical_device_memory_properties2(handle, &mut p2) };
    let mp = p2.memory_properties;
    let count = (mp.memory_heap_count as usize).min(vk::MAX_MEMORY_HEAPS);
    (0..count)
        .map(|i| HeapReport {
            index: i as u32,
            size_bytes: mp.memory_heaps[i].size,
            budget_bytes: has_budget.then_some(budget.heap_budget[i]),
            usage_bytes: has_budget.then_some(budget.heap_usage[i]),
            device_local: mp.memory_heaps[i]
                .flags
                .contains(vk::MemoryHeapFlags::DEVICE_LOCAL),
        })
        .collect()
}
