//! The ray-tracing pipeline of the `pipeline` backend and its shader binding table.
//!
//! Groups: raygen (motu-gpu's `pipeline/trace.rgen`), miss, hit group 0 = triangles (closest-hit, and
//! an any-hit alpha test that only non-opaque geometry runs; opaque instances `FORCE_OPAQUE`,
//! SBT offset 0), hit group 1 = programmable instances
//! (intersection + any-hit; instances `FORCE_NO_OPAQUE`, SBT offset 1), hit group 2 = a
//! streamed TLAS's proxy boxes (their own intersection + any-hit, SBT offset 2; the full
//! build's pipelines have no proxies and give the group the PI shaders). No descriptor sets:
//! everything is reached through 128 bytes of push-constant device addresses.

use ash::vk;
use motu_alloc::{AllocKind, MemoryClass};

use crate::context::Context;
use crate::error::{Result, VkError};
use crate::heap::{GpuHeap, HeapBuffer};
use crate::memory::BufferUsage;
use crate::pipeline_stats::PipelineExecutableStats;

/// The push-constant bytes every stage sees (the shaders' table addresses).
pub const PUSH_CONSTANT_BYTES: u32 = 128;

/// The SPIR-V of the pipeline's eight stages (entry point `main` each), which the crate above
/// embeds: it picks full-build or streamed variants.
#[derive(Clone, Copy, Debug)]
pub struct RtShaders<'s> {
    pub raygen: &'s [u32],
    pub miss: &'s [u32],
    pub triangle_closest_hit: &'s [u32],
    pub triangle_any_hit: &'s [u32],
    pub pi_intersection: &'s [u32],
    pub pi_any_hit: &'s [u32],
    pub proxy_intersection: &'s [u32],
    pub proxy_any_hit: &'s [u32],
}

pub(crate) fn rt_stages() -> vk::ShaderStageFlags {
    vk::ShaderStageFlags::RAYGEN_KHR
        | vk::ShaderStageFlags::MISS_KHR
        | vk::ShaderStageFlags::CLOSEST_HIT_KHR
        | vk::ShaderStageFlags::ANY_HIT_KHR
        | vk::ShaderStageFlags::INTERSECTION_KHR
}

/// A ray-tracing pipeline and its shader binding table (see the module docs for the groups).
pub struct RtPipeline {
    ctx: Context,
    pub(crate) rt: ash::khr::ray_tracing_pipeline::Device,
    pub(crate) pipeline: vk::Pipeline,
    pub(crate) layout: vk::PipelineLayout,
    /// raygen, miss, hit, callable (empty).
    pub(crate) regions: [vk::StridedDeviceAddressRegionKHR; 4],
    sbt: Option<HeapBuffer>,
    label: String,
    /// The driver's statistics, when the context captures them.
    stats: Option<PipelineExecutableStats>,
}

/// The hit groups' count: raygen, miss, triangle hit group, procedural hit group.
const GROUP_COUNT: u32 = 5;

/// Shader modules live for the pipeline's creation only: destroyed when this drops.
struct ShaderModules<'d> {
    device: &'d ash::Device,
    modules: Vec<vk::ShaderModule>,
}

impl<'d> ShaderModules<'d> {
    /// One module per SPIR-V blob, in order; on an error the ones made so far are destroyed.
    fn new(device: &'d ash::Device, sources: &[&[u32]]) -> Result<ShaderModules<'d>> {
        let mut made = ShaderModules {
            device,
            modules: Vec::with_capacity(sources.len()),
        };
        for words in sources {
            let info = vk::ShaderModuleCreateInfo::default().code(words);
            // SAFETY: SPIR-V validated by spirv-val when the embedding crate was built.
            let m = unsafe { device.create_shader_module(&info, None) }.map_err(|e| {
                VkError::Vulkan {
                    call: "vkCreateShaderModule",
                    result: e,
                }
            })?;
            made.modules.push(m);
        }
        Ok(made)
    }
}

impl Drop for ShaderModules<'_> {
    fn drop(&mut self) {
        for &m in &self.modules {
            // SAFETY: created from this device; only needed during the pipeline's creation.
            unsafe { self.device.destroy_shader_module(m, None) };
        }
    }
}

/// The shader binding table's layout: a handle stride and the offsets of its three regions.
struct SbtLayout {
    handle_size: u64,
    stride: u64,
    /// The raygen region's stride and size (the miss and hit regions start aligned to it).
    raygen_stride: u64,
    miss_off: u64,
    hit_off: u64,
    total: u64,
}

impl SbtLayout {
    fn new(ctx: &Context) -> SbtLayout {
        let limits = ctx.limits();
        let handle_size = limits.shader_group_handle_size as u64;
        let handle_align = u64::from(limits.shader_group_handle_alignment.max(1));
        let base_align = u64::from(limits.shader_group_base_alignment.max(1));
        let stride = handle_size.div_ceil(handle_align) * handle_align;
        let align = |v: u64| v.div_ceil(base_align) * base_align;
        let miss_off = align(stride);
        let hit_off = miss_off + align(stride);
        SbtLayout {
            handle_size,
            stride,
            raygen_stride: align(stride),
            miss_off,
            hit_off,
            total: hit_off + 3 * stride,
        }
    }

    /// The table's bytes: each group's handle (`handles`, `GROUP_COUNT` of them) at its offset.
    fn bytes(&self, handles: &[u8]) -> Vec<u8> {
        let mut bytes = vec![0u8; self.total as usize];
        let size = self.handle_size as usize;
        let mut put = |off: u64, i: usize| {
            bytes[off as usize..off as usize + size]
                .copy_from_slice(&handles[i * size..(i + 1) * size]);
        };
        put(0, 0);
        put(self.miss_off, 1);
        put(self.hit_off, 2);
        put(self.hit_off + self.stride, 3);
        put(self.hit_off + 2 * self.stride, 4);
        bytes
    }

    /// The raygen, miss, hit and (empty) callable regions of a table at device address `base`.
    fn regions(&self, base: u64) -> [vk::StridedDeviceAddressRegionKHR; 4] {
        [
            vk::StridedDeviceAddressRegionKHR {
                device_address: base,
                stride: self.raygen_stride,
                size: self.raygen_stride,
            },
            vk::StridedDeviceAddressRegionKHR {
                device_address: base + self.miss_off,
                stride: self.stride,
                size: self.stride,
            },
            vk::StridedDeviceAddressRegionKHR {
                device_address: base + self.hit_off,
                stride: self.stride,
                size: 3 * self.stride,
            },
            vk::StridedDeviceAddressRegionKHR::default(),
        ]
    }
}

impl RtPipeline {
    /// `label` names it (validation messages, pipeline statistics); `specialization`:
    /// (constant id, value) pairs for every stage; `shaders`: the stages' SPIR-V (validated by
    /// the embedding crate's build).
    pub fn new(
        ctx: &Context,
        heap: &mut GpuHeap,
        label: &str,
        specialization: &[(u32, u32)],
        shaders: &RtShaders<'_>,
    ) -> Result<RtPipeline> {
        if !ctx.caps().ray_pipeline {
            return Err(VkError::MissingFeature {
                what: "the ray-tracing pipeline (VK_KHR_ray_tracing_pipeline)".into(),
                details: ctx.device_name().to_string(),
            });
        }
        let shared = &ctx.shared;
        let rt =
            ash::khr::ray_tracing_pipeline::Device::new(&shared.instance.instance, &shared.device);
        let mut p = RtPipeline {
            ctx: ctx.clone(),
            rt,
            pipeline: vk::Pipeline::null(),
            layout: vk::PipelineLayout::null(),
            regions: [vk::StridedDeviceAddressRegionKHR::default(); 4],
            sbt: None,
            label: label.to_string(),
            stats: None,
        };
        p.create_layout()?;
        p.create_pipeline(specialization, shaders)?;
        p.write_sbt(heap)?;
        Ok(p)
    }

    /// The layout: 128 bytes of push constants for every stage, no descriptor sets.
    fn create_layout(&mut self) -> Result<()> {
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(rt_stages())
            .offset(0)
            .size(PUSH_CONSTANT_BYTES)];
        let layout_info = vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&ranges);
        // SAFETY: valid create info; the layout is owned by `self`.
        self.layout = unsafe {
            self.ctx
                .shared
                .device
                .create_pipeline_layout(&layout_info, None)
        }
        .map_err(VkError::vk("vkCreatePipelineLayout"))?;
        Ok(())
    }

    /// The pipeline: eight stages (specialised alike) in the five groups of the module docs.
    fn create_pipeline(
        &mut self,
        specialization: &[(u32, u32)],
        shaders: &RtShaders<'_>,
    ) -> Result<()> {
        let shared = &self.ctx.shared;
        let stage_flags = [
            vk::ShaderStageFlags::RAYGEN_KHR,
            vk::ShaderStageFlags::MISS_KHR,
            vk::ShaderStageFlags::CLOSEST_HIT_KHR,
            vk::ShaderStageFlags::INTERSECTION_KHR,
            vk::ShaderStageFlags::ANY_HIT_KHR,
            vk::ShaderStageFlags::ANY_HIT_KHR,
            vk::ShaderStageFlags::INTERSECTION_KHR,
            vk::ShaderStageFlags::ANY_HIT_KHR,
        ];
        let modules = ShaderModules::new(
            &shared.device,
            &[
                shaders.raygen,
                shaders.miss,
                shaders.triangle_closest_hit,
                shaders.pi_intersection,
                shaders.pi_any_hit,
                shaders.triangle_any_hit,
                shaders.proxy_intersection,
                shaders.proxy_any_hit,
            ],
        )?;
        let spec_entries: Vec<vk::SpecializationMapEntry> = specialization
            .iter()
            .enumerate()
            .map(|(i, &(id, _))| vk::SpecializationMapEntry {
                constant_id: id,
                offset: 4 * i as u32,
                size: 4,
            })
            .collect();
        let spec_data: Vec<u8> = specialization
            .iter()
            .flat_map(|&(_, v)| v.to_ne_bytes())
            .collect();
        let spec = vk::SpecializationInfo::default()
            .map_entries(&spec_entries)
            .data(&spec_data);
        let stages: Vec<_> = stage_flags
            .iter()
            .zip(&modules.modules)
            .map(|(stage, m)| {
                let s = vk::PipelineShaderStageCreateInfo::default()
                    .stage(*stage)
                    .module(*m)
                    .name(c"main");
                // Every stage: the payload's size (PI_CAPACITY) must agree between them.
                s.specialization_info(&spec)
            })
            .collect();
        let groups = shader_groups();
        let info = vk::RayTracingPipelineCreateInfoKHR::default()
            .stages(&stages)
            .groups(&groups)
            .max_pipeline_ray_recursion_depth(1)
            .layout(self.layout);
        let create = |flags: vk::PipelineCreateFlags| {
            // SAFETY: modules, layout and infos are live for the call; recursion depth 1
            // (raygen traces, no hit shader does).
            unsafe {
                self.rt.create_ray_tracing_pipelines(
                    vk::DeferredOperationKHR::null(),
                    vk::PipelineCache::null(),
                    &[info.flags(flags)],
                    None,
                )
            }
        };
        let (result, captured) = shared.pipeline_stats.create(&self.label, create);
        drop(modules);
        self.pipeline = result.map_err(|(_, e)| VkError::Vulkan {
            call: "vkCreateRayTracingPipelinesKHR",
            result: e,
        })?[0];
        shared.set_name(self.pipeline, &self.label);
        // The raygen's stack (what stays live across its traceRayEXT calls, the traversal
        // stack included): each TLAS hop saves and restores it, so it is what hop cost tracks.
        // SAFETY: the pipeline is live; group 0 is the raygen (general) group.
        let raygen_stack_bytes = unsafe {
            self.rt.get_ray_tracing_shader_group_stack_size(
                self.pipeline,
                0,
                vk::ShaderGroupShaderKHR::GENERAL,
            )
        };
        tracing::debug!(raygen_stack_bytes, "traversal pipeline created");
        self.stats = shared.pipeline_stats.capture(
            captured.then_some(self.pipeline),
            &self.label,
            "ray_tracing",
            Some(raygen_stack_bytes),
        );
        Ok(())
    }

    /// The shader binding table: the groups' handles in host-visible memory, and its regions.
    fn write_sbt(&mut self, heap: &mut GpuHeap) -> Result<()> {
        let layout = SbtLayout::new(&self.ctx);
        let base_align = u64::from(self.ctx.limits().shader_group_base_alignment.max(1));
        // SAFETY: the pipeline has `GROUP_COUNT` groups; the output holds their handles.
        let handles = unsafe {
            self.rt.get_ray_tracing_shader_group_handles(
                self.pipeline,
                0,
                GROUP_COUNT,
                (layout.handle_size * u64::from(GROUP_COUNT)) as usize,
            )
        }
        .map_err(VkError::vk("vkGetRayTracingShaderGroupHandlesKHR"))?;
        let sbt = heap.alloc_buffer(
            "sbt",
            layout.total,
            BufferUsage::SHADER_BINDING_TABLE | BufferUsage::DEVICE_ADDRESS,
            AllocKind::Other,
            MemoryClass::HostVisible,
            base_align,
        )?;
        sbt.write_bytes(0, &layout.bytes(&handles))?;
        self.regions = layout.regions(sbt.device_address()?.0);
        self.sbt = Some(sbt);
        Ok(())
    }

    pub fn label(&self) -> &str {
        &self.label
    }

    /// The driver's statistics of its executables (one a stage, or as the driver merged them):
    /// `Some` only when the context was opened with `pipeline_stats` on a device with
    /// `VK_KHR_pipeline_executable_properties`.
    pub fn executable_stats(&self) -> Option<&PipelineExecutableStats> {
        self.stats.as_ref()
    }

    /// Returns the SBT's memory to the heap (call before dropping when the heap lives on).
    pub fn release(mut self, heap: &mut GpuHeap) {
        if let Some(b) = self.sbt.take() {
            heap.free(b);
        }
    }
}

/// Raygen (stage 0), miss (1), the triangle hit group (closest-hit 2, any-hit 5) and the
/// procedural hit group (intersection 3, any-hit 4).
fn shader_groups() -> [vk::RayTracingShaderGroupCreateInfoKHR<'static>; GROUP_COUNT as usize] {
    let unused = vk::SHADER_UNUSED_KHR;
    let general = |i: u32| {
        vk::RayTracingShaderGroupCreateInfoKHR::default()
            .ty(vk::RayTracingShaderGroupTypeKHR::GENERAL)
            .general_shader(i)
            .closest_hit_shader(unused)
            .any_hit_shader(unused)
            .intersection_shader(unused)
    };
    // A box hit group: its intersection and any-hit stages (PIs, then proxies).
    let procedural = |intersection: u32, any_hit: u32| {
        vk::RayTracingShaderGroupCreateInfoKHR::default()
            .ty(vk::RayTracingShaderGroupTypeKHR::PROCEDURAL_HIT_GROUP)
            .general_shader(unused)
            .closest_hit_shader(unused)
            .any_hit_shader(any_hit)
            .intersection_shader(intersection)
    };
    [
        general(0),
        general(1),
        vk::RayTracingShaderGroupCreateInfoKHR::default()
            .ty(vk::RayTracingShaderGroupTypeKHR::TRIANGLES_HIT_GROUP)
            .general_shader(unused)
            .closest_hit_shader(2)
            .any_hit_shader(5)
            .intersection_shader(unused),
        procedural(3, 4),
        procedural(6, 7),
    ]
}

impl Drop for RtPipeline {
    fn drop(&mut self) {
        let device = &self.ctx.shared.device;
        // SAFETY: created from this device; every trace using it was fenced.
        unsafe {
            device.destroy_pipeline(self.pipeline, None);
            device.destroy_pipeline_layout(self.layout, None);
        }
    }
}
