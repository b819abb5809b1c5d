//! The device context: one logical device with one queue, shared by every RAII resource.

use std::ffi::CStr;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use ash::vk;

use crate::capabilities::{self, Caps, HeapReport, PhysicalInfo};
use crate::error::{Result, VkError};
use crate::instance::{version_string, InstanceShared, ValidationRequest};
use crate::limits::{LimitOverrides, Limits};
use crate::pipeline_stats::{CapturedPipeline, PipelineStatsState};
use crate::report::DeviceReport;

/// Environment variable selecting the device by index (as listed by `motu devices`).
pub const ENV_DEVICE: &str = "MOTU_DEVICE";

/// What the caller needs from the device; selection skips devices that lack it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Requirement {
    /// Any Vulkan 1.2 device with a compute queue.
    #[default]
    Compute,
    /// Acceleration structures plus the ray-tracing pipeline or ray queries.
    RayTracing,
    RayPipeline,
    RayQuery,
}

impl Requirement {
    fn met_by(self, caps: &Caps) -> bool {
        match self {
            Requirement::Compute => true,
            Requirement::RayTracing => {
                caps.acceleration_structure && (caps.ray_pipeline || caps.ray_query)
            }
            Requirement::RayPipeline => caps.ray_pipeline,
            Requirement::RayQuery => caps.ray_query,
        }
    }
    fn describe(self) -> &'static str {
        match self {
            Requirement::Compute => "Vulkan 1.2 compute",
            Requirement::RayTracing => "ray tracing",
            Requirement::RayPipeline => "the ray-tracing pipeline (VK_KHR_ray_tracing_pipeline)",
            Requirement::RayQuery => "ray queries (VK_KHR_ray_query)",
        }
    }
}

/// How to open a [`Context`].
#[derive(Clone, Debug, Default)]
pub struct ContextOptions {
    /// Device index; `None` reads `MOTU_DEVICE`, else picks the best device meeting `require`.
    pub device_index: Option<usize>,
    pub validation: ValidationRequest,
    /// Lowered limits (combined with the `MOTU_MAX_*` environment; the smaller wins).
    pub limit_overrides: LimitOverrides,
    pub require: Requirement,
    /// Open for presenting to windows of this display (`motu view`): enables the surface
    /// extensions on the instance and `VK_KHR_swapchain` on the device.
    pub presentation: Option<raw_window_handle::RawDisplayHandle>,
    /// Capture the driver's statistics of every pipeline made (`VK_KHR_pipeline_executable_properties`:
    /// registers, spills, instruction counts, …), logged at `info` and kept for
    /// [`Context::captured_pipelines`]. A device without the extension logs a warning and
    /// captures nothing (never an error). Off by default: capturing costs compile time.
    pub pipeline_stats: bool,
}

pub(crate) struct DeviceShared {
    pub(crate) device: ash::Device,
    queue: Mutex<vk::Queue>,
    pub(crate) queue_family_index: u32,
    pub(crate) accel: Option<ash::khr::acceleration_structure::Device>,
    debug_utils: Option<ash::ext::debug_utils::Device>,
    pub(crate) info: PhysicalInfo,
    pub(crate) limits: Limits,
    pub(crate) lowered: Vec<&'static str>,
    pub(crate) live_allocations: AtomicU32,
    pub(crate) peak_allocations: AtomicU32,
    pub(crate) allocated_bytes: AtomicU64,
    /// `vkQueueSubmit` calls and fence waits on them ([`Context::submit_count`]).
    pub(crate) submits: AtomicU64,
    pub(crate) fence_waits: AtomicU64,
    /// `ContextOptions::pipeline_stats`: the extension's functions and the pipelines' log.
    pub(crate) pipeline_stats: PipelineStatsState,
    /// Dropped after the device (field order), so the instance outlives it.
    pub(crate) instance: InstanceShared,
}

impl DeviceShared {
    pub(crate) fn queue(&self) -> MutexGuard<'_, vk::Queue> {
        self.queue.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Names `handle` for validation messages (no-op without VK_EXT_debug_utils).
    pub(crate) fn set_name<H: vk::Handle>(&self, handle: H, name: &str) {
        let Some(du) = &self.debug_utils else { return };
        let Ok(name) = std::ffi::CString::new(name) else {
            return;
        };
        let info = vk::DebugUtilsObjectNameInfoEXT::default()
            .object_handle(handle)
            .object_name(&name);
        // SAFETY: the handle is a live object of this device; the name outlives the call.
        let _ = unsafe { du.set_debug_utils_object_name(&info) };
    }
}

impl Drop for DeviceShared {
    fn drop(&mut self) {
        let errors = self.instance.log.errors();
        if !errors.is_empty() {
            // Loud even if nobody called check_validation (e.g. a test that forgot to).
            tracing::error!(count = errors.len(), first = %errors[0], "Vulkan validation errors");
            eprintln!(
                "motu-gpu: {} Vulkan validation error(s) on {}; first: {}",
                errors.len(),
                self.info.name,
                errors[0]
            );
        }
        // SAFETY: every child object holds an Arc to this struct, so all of them are gone; waiting
        // idle first makes destruction safe even if a submission was abandoned by a panic.
        unsafe {
            let _ = self.device.device_wait_idle();
            self.device.destroy_device(None);
        }
    }
}

/// An opened device. Cheap to clone; resources keep it alive.
#[derive(Clone)]
pub struct Context {
    pub(crate) shared: Arc<DeviceShared>,
}

impl std::fmt::Debug for Context {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Context")
            .field("device", &self.shared.info.name)
            .field("index", &self.shared.info.index)
            .field("validation", &self.validation_enabled())
            .finish()
    }
}

impl Context {
    /// Opens the device chosen by `options` (see [`ContextOptions`]).
    pub fn new(options: &ContextOptions) -> Result<Self> {
        let overrides = options
            .limit_overrides
            .combine(&LimitOverrides::from_env()?);
        let index = match options.device_index {
            Some(i) => Some(i),
            None => match std::env::var(ENV_DEVICE).ok() {
                Some(v) if !v.trim().is_empty() => {
                    Some(v.trim().parse().map_err(|_| VkError::InvalidEnv {
                        name: ENV_DEVICE,
                        value: v.clone(),
                        reason: "expected a device index (see `motu devices`)".into(),
                    })?)
                }
                _ => None,
            },
        };
        let instance = match options.presentation {
            None => InstanceShared::new(options.validation)?,
            Some(display) => {
                let surface_exts = ash_window::enumerate_required_extensions(display)
                    .map_err(|source| VkError::NoSurface { source })?;
                InstanceShared::with_extensions(options.validation, surface_exts)?
            }
        };
        let infos = capabilities::enumerate(&instance.instance, instance.api_version)?;
        if infos.is_empty() {
            return Err(VkError::NoDevice);
        }
        let info = select(&infos, index, options.require)?;
        Self::open(
            instance,
            info,
            &overrides,
            options.presentation.is_some(),
            options.pipeline_stats,
        )
    }

    /// Opens the default device with validation as the environment says (`MOTU_VALIDATION`).
    pub fn new_default() -> Result<Self> {
        Self::new(&ContextOptions::default())
    }

    fn open(
        instance: InstanceShared,
        info: PhysicalInfo,
        overrides: &LimitOverrides,
        present: bool,
        pipeline_stats: bool,
    ) -> Result<Self> {
        let span = tracing::info_span!("open_device", device = %info.name, index = info.index);
        let _guard = span.enter();
        let queue_family_index =
            info.queue_family_index
                .ok_or_else(|| VkError::DeviceUnsuitable {
                    index: info.index,
                    name: info.name.clone(),
                    reason: "no compute queue".into(),
                })?;
        let capture = pipeline_stats && info.caps.pipeline_executable_info;
        if pipeline_stats && !capture {
            tracing::warn!(
                device = %info.name,
                "pipeline statistics asked for, but the device lacks \
                 VK_KHR_pipeline_executable_properties (pipelineExecutableInfo): none captured"
            );
        }
        let ext_names = device_extensions(&info, present, capture)?;
        let device = create_device(&instance, &info, queue_family_index, &ext_names, capture)?;
        let caps = &info.caps;
        // SAFETY: queue 0 of the family we requested exists.
        let queue = unsafe { device.get_device_queue(queue_family_index, 0) };
        let accel = caps
            .acceleration_structure
            .then(|| ash::khr::acceleration_structure::Device::new(&instance.instance, &device));

        let pipeline_stats = PipelineStatsState {
            requested: pipeline_stats,
            loader: capture.then(|| {
                ash::khr::pipeline_executable_properties::Device::new(&instance.instance, &device)
            }),
            ..PipelineStatsState::off()
        };
        let debug_utils = instance
            .has_debug_utils()
            .then(|| ash::ext::debug_utils::Device::new(&instance.instance, &device));
        let mut limits = info.limits.clone();
        let lowered = overrides.apply(&mut limits);
        tracing::info!(
            device = %info.name,
            api = %version_string(info.api_version),
            ray_pipeline = caps.ray_pipeline,
            ray_query = caps.ray_query,
            validation = instance.validation_enabled,
            lowered = ?lowered,
            "device opened"
        );
        Ok(Self {
            shared: Arc::new(DeviceShared {
                device,
                queue: Mutex::new(queue),
                queue_family_index,
                accel,
                debug_utils,
                info,
                limits,
                lowered,
                live_allocations: AtomicU32::new(0),
                peak_allocations: AtomicU32::new(0),
                submits: AtomicU64::new(0),
                fence_waits: AtomicU64::new(0),
                pipeline_stats,
                allocated_bytes: AtomicU64::new(0),
                instance,
            }),
        })
    }

    pub fn caps(&self) -> &Caps {
        &self.shared.info.caps
    }

    /// Limits in force (device limits, possibly lowered by overrides).
    pub fn limits(&self) -> &Limits {
        &self.shared.limits
    }

    /// The device's own limits, before overrides.
    pub fn device_limits(&self) -> &Limits {
        &self.shared.info.limits
    }

    /// Names of the limits lowered by overrides.
    pub fn lowered_limits(&self) -> &[&'static str] {
        &self.shared.lowered
    }

    /// Whether the device exposes the extension `name` (e.g. `"VK_NV_ray_tracing_invocation_reorder"`).
    pub fn has_extension(&self, name: &str) -> bool {
        self.shared
            .info
            .extensions
            .iter()
            .any(|e| e.to_bytes() == name.as_bytes())
    }

    pub fn device_name(&self) -> &str {
        &self.shared.info.name
    }

    pub fn device_index(&self) -> usize {
        self.shared.info.index
    }

    /// The full report for this device (limits as in force).
    pub fn report(&self) -> DeviceReport {
        let mut r =
            DeviceReport::from_info(&self.shared.info, self.heaps(), &LimitOverrides::default());
        r.limits = self.shared.limits.clone();
        r.limit_overrides = self.shared.lowered.clone();
        r
    }

    /// Heaps with current budget and usage (queried now).
    pub fn heaps(&self) -> Vec<HeapReport> {
        capabilities::heaps(
            &self.shared.instance.instance,
            self.shared.info.handle,
            self.shared.info.caps.memory_budget,
        )
    }

    pub fn validation_enabled(&self) -> bool {
        self.shared.instance.validation_enabled
    }

    /// Validation errors (and validation-type warnings) reported so far.
    pub fn validation_errors(&self) -> Vec<String> {
        self.shared.instance.log.errors()
    }

    /// Other warnings (e.g. performance) reported so far; informational only.
    pub fn validation_warnings(&self) -> Vec<String> {
        self.shared.instance.log.warnings()
    }

    /// `Err` if any validation error was reported: call before exiting so that, with
    /// `MOTU_VALIDATION=1`, a validation error fails the process.
    pub fn check_validation(&self) -> Result<()> {
        let errors = self.validation_errors();
        match errors.first() {
            None => Ok(()),
            Some(first) => Err(VkError::Validation {
                count: errors.len(),
                first: first.clone(),
            }),
        }
    }

    /// Live `vkAllocateMemory` allocations made through this context.
    pub fn allocation_count(&self) -> u32 {
        self.shared.live_allocations.load(Ordering::Relaxed)
    }

    /// Highest `allocation_count` seen.
    pub fn peak_allocation_count(&self) -> u32 {
        self.shared.peak_allocations.load(Ordering::Relaxed)
    }

    /// `vkQueueSubmit` calls made through this context so far (every one-shot submission and
    /// every presented frame): callers diff it around a phase to count its submissions.
    pub fn submit_count(&self) -> u64 {
        self.shared.submits.load(Ordering::Relaxed)
    }

    /// Fence waits on those submissions so far (each blocks the CPU until the GPU is done).
    pub fn fence_wait_count(&self) -> u64 {
        self.shared.fence_waits.load(Ordering::Relaxed)
    }

    /// Bytes currently held in `vkAllocateMemory` allocations made through this context.
    pub fn allocated_bytes(&self) -> u64 {
        self.shared.allocated_bytes.load(Ordering::Relaxed)
    }

    /// Whether pipeline statistics were asked for ([`ContextOptions::pipeline_stats`]).
    pub fn pipeline_stats_requested(&self) -> bool {
        self.shared.pipeline_stats.requested
    }

    /// Whether pipelines are created capturing the driver's statistics: asked for, and the
    /// device has `VK_KHR_pipeline_executable_properties`.
    pub fn pipeline_stats_enabled(&self) -> bool {
        self.shared.pipeline_stats.loader.is_some()
    }

    /// Every pipeline made through this context while statistics were asked for, in creation
    /// order, with its statistics (`None` on a device without the extension). Empty when
    /// they were not asked for.
    pub fn captured_pipelines(&self) -> Vec<CapturedPipeline> {
        self.shared
            .pipeline_stats
            .log
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Waits until the device is idle. For teardown and tests; normal paths wait on fences.
    pub fn wait_idle(&self) -> Result<()> {
        let _queue = self.shared.queue();
        // SAFETY: the queue lock is held, so no submission races with the wait.
        unsafe { self.shared.device.device_wait_idle() }.map_err(VkError::vk("vkDeviceWaitIdle"))
    }
}

/// The device extensions to enable: the ray-tracing ones the device has, the memory budget,
/// maintenance4 before Vulkan 1.3, and the swapchain when it presents (or why it cannot).
fn device_extensions(
    info: &PhysicalInfo,
    present: bool,
    pipeline_stats: bool,
) -> Result<Vec<&'static CStr>> {
    let caps = &info.caps;
    let v13 = info.api_version >= vk::API_VERSION_1_3;
    let mut ext_names: Vec<&CStr> = Vec::new();
    if caps.acceleration_structure {
        ext_names.push(ash::khr::acceleration_structure::NAME);
        ext_names.push(ash::khr::deferred_host_operations::NAME);
    }
    if caps.ray_pipeline {
        ext_names.push(ash::khr::ray_tracing_pipeline::NAME);
    }
    if caps.ray_query {
        ext_names.push(ash::khr::ray_query::NAME);
    }
    if caps.ray_tracing_maintenance1 && (caps.ray_pipeline || caps.ray_query) {
        ext_names.push(ash::khr::ray_tracing_maintenance1::NAME);
    }
    if caps.memory_budget {
        ext_names.push(ash::ext::memory_budget::NAME);
    }
    if !v13 && caps.maintenance4 {
        ext_names.push(ash::khr::maintenance4::NAME);
    }
    if pipeline_stats {
        ext_names.push(ash::khr::pipeline_executable_properties::NAME);
    }
    if present {
        let name = ash::khr::swapchain::NAME;
        if !info.extensions.contains(name) {
            return Err(VkError::DeviceUnsuitable {
                index: info.index,
                name: info.name.clone(),
                reason: "no VK_KHR_swapchain: it cannot present to a window".into(),
            });
        }
        ext_names.push(name);
    }
    Ok(ext_names)
}

/// The logical device with one queue of `queue_family_index`, `ext_names` and a chosen subset
/// of the supported features.
fn create_device(
    instance: &InstanceShared,
    info: &PhysicalInfo,
    queue_family_index: u32,
    ext_names: &[&CStr],
    pipeline_stats: bool,
) -> Result<ash::Device> {
    let caps = &info.caps;
    let v13 = info.api_version >= vk::API_VERSION_1_3;
    let ext_ptrs: Vec<*const std::ffi::c_char> = ext_names.iter().map(|n| n.as_ptr()).collect();

    // Enable a chosen subset of what is supported: features with a cost (robustness,
    // capture/replay, host AS commands) stay off.
    let s = &info.features;
    let on = |supported: vk::Bool32| supported;
    let f10 = vk::PhysicalDeviceFeatures::default()
        .shader_int64(s.f10.shader_int64 == vk::TRUE)
        .shader_int16(s.f10.shader_int16 == vk::TRUE)
        .shader_float64(s.f10.shader_float64 == vk::TRUE);
    let mut f11 = vk::PhysicalDeviceVulkan11Features::default();
    f11.storage_buffer16_bit_access = on(s.f11.storage_buffer16_bit_access);
    f11.uniform_and_storage_buffer16_bit_access = on(s.f11.uniform_and_storage_buffer16_bit_access);
    let mut f12 = vk::PhysicalDeviceVulkan12Features::default();
    f12.buffer_device_address = on(s.f12.buffer_device_address);
    f12.descriptor_indexing = on(s.f12.descriptor_indexing);
    f12.runtime_descriptor_array = on(s.f12.runtime_descriptor_array);
    f12.shader_storage_buffer_array_non_uniform_indexing =
        on(s.f12.shader_storage_buffer_array_non_uniform_indexing);
    f12.descriptor_binding_partially_bound = on(s.f12.descriptor_binding_partially_bound);
    f12.descriptor_binding_variable_descriptor_count =
        on(s.f12.descriptor_binding_variable_descriptor_count);
    f12.scalar_block_layout = on(s.f12.scalar_block_layout);
    f12.timeline_semaphore = on(s.f12.timeline_semaphore);
    f12.host_query_reset = on(s.f12.host_query_reset);
    f12.shader_int8 = on(s.f12.shader_int8);
    f12.shader_float16 = on(s.f12.shader_float16);
    f12.storage_buffer8_bit_access = on(s.f12.storage_buffer8_bit_access);
    f12.uniform_and_storage_buffer8_bit_access = on(s.f12.uniform_and_storage_buffer8_bit_access);
    f12.uniform_buffer_standard_layout = on(s.f12.uniform_buffer_standard_layout);
    f12.vulkan_memory_model = on(s.f12.vulkan_memory_model);
    f12.vulkan_memory_model_device_scope = on(s.f12.vulkan_memory_model_device_scope);
    f12.shader_subgroup_extended_types = on(s.f12.shader_subgroup_extended_types);
    let mut f13 = vk::PhysicalDeviceVulkan13Features::default();
    f13.synchronization2 = on(s.f13.synchronization2);
    f13.maintenance4 = on(s.f13.maintenance4);
    let mut m4 = vk::PhysicalDeviceMaintenance4Features::default();
    m4.maintenance4 = on(s.m4.maintenance4);
    let yes = |b: vk::Bool32| b == vk::TRUE;
    let mut f_as = vk::PhysicalDeviceAccelerationStructureFeaturesKHR::default()
        .acceleration_structure(yes(s.accel.acceleration_structure));
    let mut f_rt = vk::PhysicalDeviceRayTracingPipelineFeaturesKHR::default()
        .ray_tracing_pipeline(yes(s.rt.ray_tracing_pipeline))
        .ray_tracing_pipeline_trace_rays_indirect(yes(s
            .rt
            .ray_tracing_pipeline_trace_rays_indirect))
        .ray_traversal_primitive_culling(yes(s.rt.ray_traversal_primitive_culling));
    let mut f_rq = vk::PhysicalDeviceRayQueryFeaturesKHR::default().ray_query(yes(s.rq.ray_query));
    let mut f_pe = vk::PhysicalDevicePipelineExecutablePropertiesFeaturesKHR::default()
        .pipeline_executable_info(true);
    let mut f2 = vk::PhysicalDeviceFeatures2::default()
        .features(f10)
        .push_next(&mut f11)
        .push_next(&mut f12);
    if v13 {
        f2 = f2.push_next(&mut f13);
    } else if caps.maintenance4 {
        f2 = f2.push_next(&mut m4);
    }
    if caps.acceleration_structure {
        f2 = f2.push_next(&mut f_as);
    }
    if caps.ray_pipeline {
        f2 = f2.push_next(&mut f_rt);
    }
    if caps.ray_query {
        f2 = f2.push_next(&mut f_rq);
    }
    if pipeline_stats {
        f2 = f2.push_next(&mut f_pe);
    }

    let priorities = [1.0f32];
    let queue_infos = [vk::DeviceQueueCreateInfo::default()
        .queue_family_index(queue_family_index)
        .queue_priorities(&priorities)];
    let create_info = vk::DeviceCreateInfo::default()
        .queue_create_infos(&queue_infos)
        .enabled_extension_names(&ext_ptrs)
        .push_next(&mut f2);
    // SAFETY: the physical device belongs to this instance; extensions and features were
    // checked as supported; all pointers in create_info live until the call returns.
    unsafe {
        instance
            .instance
            .create_device(info.handle, &create_info, None)
    }
    .map_err(VkError::vk("vkCreateDevice"))
}

fn select(
    infos: &[PhysicalInfo],
    index: Option<usize>,
    require: Requirement,
) -> Result<PhysicalInfo> {
    if let Some(index) = index {
        let info = infos.get(index).ok_or(VkError::DeviceIndexOutOfRange {
            index,
            count: infos.len(),
        })?;
        if let Some(reason) = info.unusable_reason() {
            return Err(VkError::DeviceUnsuitable {
                index,
                name: info.name.clone(),
                reason,
            });
        }
        if !require.met_by(&info.caps) {
            return Err(VkError::DeviceUnsuitable {
                index,
                name: info.name.clone(),
                reason: format!(
                    "it lacks {}: missing {}",
                    require.describe(),
                    info.rt_missing().join(", ")
                ),
            });
        }
        return Ok(info.clone());
    }
    let rank = |i: &PhysicalInfo| {
        let kind = match i.device_type {
            "discrete_gpu" => 4,
            "integrated_gpu" => 3,
            "virtual_gpu" => 2,
            "cpu" => 1,
            _ => 0,
        };
        (i.caps.ray_pipeline || i.caps.ray_query, kind)
    };
    let best = infos
        .iter()
        .filter(|i| i.unusable_reason().is_none() && require.met_by(&i.caps))
        // max_by_key returns the last maximum; reverse so the lowest index wins ties.
        .rev()
        .max_by_key(|i| rank(i));
    match best {
        Some(info) => Ok(info.clone()),
        None => Err(VkError::MissingFeature {
            what: require.describe().to_string(),
            details: infos
                .iter()
                .map(|i| {
                    let why = i
                        .unusable_reason()
                        .unwrap_or_else(|| format!("missing {}", i.rt_missing().join(", ")));
                    format!("#{} {}: {}", i.index, i.name, why)
                })
                .collect::<Vec<_>>()
                .join("; "),
        }),
    }
}
