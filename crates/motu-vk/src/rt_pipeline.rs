//! The ray-tracing pipeline of the `pipeline` backend and its shader binding table.
//!
//! Groups: raygen (motu-gpu's `pipeline/trace.rgen`), miss, hit group 0 = triangles (closest-hit, and
//! an any-hit alpha test that only non-opaque geometry runs; opaque instances `FORCE_OPAQUE`,
//! SBT offset 0), hit group 1 = programmable instances
//! (intersection + any-hit; instances `FORCE_NO_OPAQUE`, SBT offset 1). No descriptor sets:
//! everything is reached through 128 bytes of push-constant device addresses.

use ash::vk;
use motu_alloc::{AllocKind, MemoryClass};

use crate::context::Context;
use crate::error::{Result, VkError};
use crate::heap::{GpuHeap, HeapBuffer};
use crate::memory::BufferUsage;

/// The push-constant bytes every stage sees (the shaders' table addresses).
pub const PUSH_CONSTANT_BYTES: u32 = 128;

/// The SPIR-V of the pipeline's six stages (entry point `main` each), which the crate above
/// embeds: it picks full-build or streamed variants.
#[derive(Clone, Copy, Debug)]
pub struct RtShaders<'s> {
    pub raygen: &'s [u32],
    pub miss: &'s [u32],
    pub triangle_closest_hit: &'s [u32],
    pub triangle_any_hit: &'s [u32],
    pub pi_intersection: &'s [u32],
    pub pi_any_hit: &'s [u32],
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
}

impl RtPipeline {
    /// `specialization`: (constant id, value) pairs for every stage; `shaders`: the stages'
    /// SPIR-V (validated by the embedding crate's build).
    pub fn new(
        ctx: &Context,
        heap: &mut GpuHeap,
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
        let device = &shared.device;
        let rt = ash::khr::ray_tracing_pipeline::Device::new(&shared.instance.instance, device);
        let mut p = RtPipeline {
            ctx: ctx.clone(),
            rt,
            pipeline: vk::Pipeline::null(),
            layout: vk::PipelineLayout::null(),
            regions: [vk::StridedDeviceAddressRegionKHR::default(); 4],
            sbt: None,
        };
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(rt_stages())
            .offset(0)
            .size(PUSH_CONSTANT_BYTES)];
        let layout_info = vk::PipelineLayoutCreateInfo::default().push_constant_ranges(&ranges);
        // SAFETY: valid create info; the layout is owned by `p`.
        p.layout = unsafe { device.create_pipeline_layout(&layout_info, None) }
            .map_err(VkError::vk("vkCreatePipelineLayout"))?;

        let sources: [(&[u32], vk::ShaderStageFlags); 6] = [
            (shaders.raygen, vk::ShaderStageFlags::RAYGEN_KHR),
            (shaders.miss, vk::ShaderStageFlags::MISS_KHR),
            (
                shaders.triangle_closest_hit,
                vk::ShaderStageFlags::CLOSEST_HIT_KHR,
            ),
            (
                shaders.pi_intersection,
                vk::ShaderStageFlags::INTERSECTION_KHR,
            ),
            (shaders.pi_any_hit, vk::ShaderStageFlags::ANY_HIT_KHR),
            (shaders.triangle_any_hit, vk::ShaderStageFlags::ANY_HIT_KHR),
        ];
        let mut modules = Vec::with_capacity(sources.len());
        for (words, _) in &sources {
            let info = vk::ShaderModuleCreateInfo::default().code(words);
            // SAFETY: SPIR-V validated by spirv-val when the embedding crate was built.
            match unsafe { device.create_shader_module(&info, None) } {
                Ok(m) => modules.push(m),
                Err(e) => {
                    for m in modules {
                        // SAFETY: created above, unused.
                        unsafe { device.destroy_shader_module(m, None) };
                    }
                    return Err(VkError::Vulkan {
                        call: "vkCreateShaderModule",
                        result: e,
                    });
                }
            }
        }
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
        let stages: Vec<_> = sources
            .iter()
            .zip(&modules)
            .map(|((_, stage), m)| {
                let s = vk::PipelineShaderStageCreateInfo::default()
                    .stage(*stage)
                    .module(*m)
                    .name(c"main");
                // Every stage: the payload's size (PI_CAPACITY) must agree between them.
                s.specialization_info(&spec)
            })
            .collect();
        let unused = vk::SHADER_UNUSED_KHR;
        let general = |i: u32| {
            vk::RayTracingShaderGroupCreateInfoKHR::default()
                .ty(vk::RayTracingShaderGroupTypeKHR::GENERAL)
                .general_shader(i)
                .closest_hit_shader(unused)
                .any_hit_shader(unused)
                .intersection_shader(unused)
        };
        let groups = [
            general(0),
            general(1),
            vk::RayTracingShaderGroupCreateInfoKHR::default()
                .ty(vk::RayTracingShaderGroupTypeKHR::TRIANGLES_HIT_GROUP)
                .general_shader(unused)
                .closest_hit_shader(2)
                .any_hit_shader(5)
                .intersection_shader(unused),
            vk::RayTracingShaderGroupCreateInfoKHR::default()
                .ty(vk::RayTracingShaderGroupTypeKHR::PROCEDURAL_HIT_GROUP)
                .general_shader(unused)
                .closest_hit_shader(unused)
                .any_hit_shader(4)
                .intersection_shader(3),
        ];
        let info = vk::RayTracingPipelineCreateInfoKHR::default()
            .stages(&stages)
            .groups(&groups)
            .max_pipeline_ray_recursion_depth(1)
            .layout(p.layout);
        // SAFETY: modules, layout and infos are live for the call; recursion depth 1 (raygen
        // traces, no hit shader does).
        let result = unsafe {
            p.rt.create_ray_tracing_pipelines(
                vk::DeferredOperationKHR::null(),
                vk::PipelineCache::null(),
                &[info],
                None,
            )
        };
        for m in modules {
            // SAFETY: only needed during creation.
            unsafe { device.destroy_shader_module(m, None) };
        }
        p.pipeline = result.map_err(|(_, e)| VkError::Vulkan {
            call: "vkCreateRayTracingPipelinesKHR",
            result: e,
        })?[0];
        shared.set_name(p.pipeline, "traversal pipeline");
        // The raygen's stack (what stays live across its traceRayEXT calls, the traversal
        // stack included): each TLAS hop saves and restores it, so it is what hop cost tracks.
        // SAFETY: the pipeline is live; group 0 is the raygen (general) group.
        let raygen_stack_bytes = unsafe {
            p.rt.get_ray_tracing_shader_group_stack_size(
                p.pipeline,
                0,
                vk::ShaderGroupShaderKHR::GENERAL,
            )
        };
        tracing::debug!(raygen_stack_bytes, "traversal pipeline created");

        // Shader binding table.
        let limits = ctx.limits();
        let handle_size = limits.shader_group_handle_size as u64;
        let handle_align = u64::from(limits.shader_group_handle_alignment.max(1));
        let base_align = u64::from(limits.shader_group_base_alignment.max(1));
        let stride = handle_size.div_ceil(handle_align) * handle_align;
        let group_count = groups.len() as u32;
        // SAFETY: the pipeline has `group_count` groups; the output holds their handles.
        let handles = unsafe {
            p.rt.get_ray_tracing_shader_group_handles(
                p.pipeline,
                0,
                group_count,
                (handle_size * u64::from(group_count)) as usize,
            )
        }
        .map_err(VkError::vk("vkGetRayTracingShaderGroupHandlesKHR"))?;
        let align = |v: u64| v.div_ceil(base_align) * base_align;
        let raygen_off = 0u64;
        let miss_off = align(stride);
        let hit_off = miss_off + align(stride);
        let total = hit_off + 2 * stride;
        let sbt = heap.alloc_buffer(
            "sbt",
            total,
            BufferUsage::SHADER_BINDING_TABLE | BufferUsage::DEVICE_ADDRESS,
            AllocKind::Other,
            MemoryClass::HostVisible,
            base_align,
        )?;
        let mut bytes = vec![0u8; total as usize];
        let h = |i: usize| &handles[i * handle_size as usize..(i + 1) * handle_size as usize];
        let put = |bytes: &mut Vec<u8>, off: u64, i: usize| {
            bytes[off as usize..(off + handle_size) as usize].copy_from_slice(h(i));
        };
        put(&mut bytes, raygen_off, 0);
        put(&mut bytes, miss_off, 1);
        put(&mut bytes, hit_off, 2);
        put(&mut bytes, hit_off + stride, 3);
        sbt.write_bytes(0, &bytes)?;
        let base = sbt.device_address()?.0;
        p.regions = [
            vk::StridedDeviceAddressRegionKHR {
                device_address: base + raygen_off,
                stride: align(stride),
                size: align(stride),
            },
            vk::StridedDeviceAddressRegionKHR {
                device_address: base + miss_off,
                stride,
                size: stride,
            },
            vk::StridedDeviceAddressRegionKHR {
                device_address: base + hit_off,
                stride,
                size: 2 * stride,
            },
            vk::StridedDeviceAddressRegionKHR::default(),
        ];
        p.sbt = Some(sbt);
        Ok(p)
    }

    /// Returns the SBT's memory to the heap (call before dropping when the heap lives on).
    pub fn release(mut self, heap: &mut GpuHeap) {
        if let Some(b) = self.sbt.take() {
            heap.free(b);
        }
    }
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
