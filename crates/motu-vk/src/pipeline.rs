//! Compute pipelines from SPIR-V words, with storage-buffer descriptor sets and push constants.

use std::marker::PhantomData;
use std::sync::Arc;

use ash::vk;

use crate::context::{Context, DeviceShared};
use crate::error::{Result, VkError};
use crate::memory::{Buffer, BufferUsage};
use crate::pipeline_stats::PipelineExecutableStats;

/// What a compute pipeline looks like to the host.
#[derive(Clone, Debug)]
pub struct ComputePipelineDesc<'s> {
    pub label: &'s str,
    /// SPIR-V words (e.g. a constant of `motu_gpu::shaders`); entry point `main`.
    pub spirv: &'s [u32],
    /// Storage buffers at set 0, bindings `0..storage_buffer_count`.
    pub storage_buffer_count: u32,
    /// Size of the push-constant block (offset 0); 0 for none.
    pub push_constant_size_bytes: u32,
    /// Specialisation constants `(constant_id, value)`.
    pub specialization: &'s [(u32, u32)],
}

/// A compute pipeline with its layout and descriptor-set layout.
pub struct ComputePipeline {
    shared: Arc<DeviceShared>,
    pipeline: vk::Pipeline,
    layout: vk::PipelineLayout,
    set_layout: vk::DescriptorSetLayout,
    storage_buffer_count: u32,
    push_constant_size_bytes: u32,
    label: String,
    /// The driver's statistics, when the context captures them.
    stats: Option<PipelineExecutableStats>,
}

impl std::fmt::Debug for ComputePipeline {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ComputePipeline")
            .field("label", &self.label)
            .field("storage_buffer_count", &self.storage_buffer_count)
            .field("push_constant_size_bytes", &self.push_constant_size_bytes)
            .finish()
    }
}

impl ComputePipeline {
    pub fn new(ctx: &Context, desc: &ComputePipelineDesc<'_>) -> Result<ComputePipeline> {
        let shared = &ctx.shared;
        let device = &shared.device;
        if desc.spirv.first() != Some(&0x0723_0203) {
            return Err(VkError::InvalidRequest(format!(
                "pipeline {:?}: not SPIR-V (bad magic)",
                desc.label
            )));
        }
        let max_push = shared.limits.max_push_constants_size;
        if desc.push_constant_size_bytes % 4 != 0 || desc.push_constant_size_bytes > max_push {
            return Err(VkError::InvalidRequest(format!(
                "pipeline {:?}: push constants of {} bytes (must be a multiple of 4 and <= {max_push})",
                desc.label, desc.push_constant_size_bytes
            )));
        }
        // Build piece by piece into `pipe`, whose Drop cleans up whatever was created.
        let mut pipe = ComputePipeline {
            shared: Arc::clone(shared),
            pipeline: vk::Pipeline::null(),
            layout: vk::PipelineLayout::null(),
            set_layout: vk::DescriptorSetLayout::null(),
            storage_buffer_count: desc.storage_buffer_count,
            push_constant_size_bytes: desc.push_constant_size_bytes,
            label: desc.label.to_string(),
            stats: None,
        };
        let bindings: Vec<_> = (0..desc.storage_buffer_count)
            .map(|b| {
                vk::DescriptorSetLayoutBinding::default()
                    .binding(b)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .descriptor_count(1)
                    .stage_flags(vk::ShaderStageFlags::COMPUTE)
            })
            .collect();
        let set_info = vk::DescriptorSetLayoutCreateInfo::default().bindings(&bindings);
        // SAFETY: valid create info; the layout is owned by `pipe`.
        pipe.set_layout = unsafe { device.create_descriptor_set_layout(&set_info, None) }
            .map_err(VkError::vk("vkCreateDescriptorSetLayout"))?;
        let ranges = [vk::PushConstantRange::default()
            .stage_flags(vk::ShaderStageFlags::COMPUTE)
            .offset(0)
            .size(desc.push_constant_size_bytes)];
        let set_layouts = [pipe.set_layout];
        let mut layout_info = vk::PipelineLayoutCreateInfo::default().set_layouts(&set_layouts);
        if desc.push_constant_size_bytes > 0 {
            layout_info = layout_info.push_constant_ranges(&ranges);
        }
        // SAFETY: valid create info referencing the live set layout.
        pipe.layout = unsafe { device.create_pipeline_layout(&layout_info, None) }
            .map_err(VkError::vk("vkCreatePipelineLayout"))?;

        let module_info = vk::ShaderModuleCreateInfo::default().code(desc.spirv);
        // SAFETY: the words start with the SPIR-V magic; embedded shaders were validated by
        // spirv-val at build time (the driver validates the rest).
        let module = unsafe { device.create_shader_module(&module_info, None) }
            .map_err(VkError::vk("vkCreateShaderModule"))?;
        let entries: Vec<_> = desc
            .specialization
            .iter()
            .enumerate()
            .map(|(i, (id, _))| vk::SpecializationMapEntry {
                constant_id: *id,
                offset: (i * 4) as u32,
                size: 4,
            })
            .collect();
        let data: Vec<u8> = desc
            .specialization
            .iter()
            .flat_map(|(_, v)| v.to_ne_bytes())
            .collect();
        let spec = vk::SpecializationInfo::default()
            .map_entries(&entries)
            .data(&data);
        let mut stage = vk::PipelineShaderStageCreateInfo::default()
            .stage(vk::ShaderStageFlags::COMPUTE)
            .module(module)
            .name(c"main");
        if !desc.specialization.is_empty() {
            stage = stage.specialization_info(&spec);
        }
        let info = vk::ComputePipelineCreateInfo::default()
            .stage(stage)
            .layout(pipe.layout);
        let create = |flags: vk::PipelineCreateFlags| {
            // SAFETY: module and layout are live; the stage info points to data alive for the
            // call.
            unsafe {
                device.create_compute_pipelines(
                    vk::PipelineCache::null(),
                    &[info.flags(flags)],
                    None,
                )
            }
        };
        let (result, captured) = shared.pipeline_stats.create(desc.label, create);
        // SAFETY: the module is only needed during pipeline creation.
        unsafe { device.destroy_shader_module(module, None) };
        pipe.pipeline = result.map_err(|(_, e)| VkError::Vulkan {
            call: "vkCreateComputePipelines",
            result: e,
        })?[0];
        shared.set_name(pipe.pipeline, desc.label);
        pipe.stats = shared.pipeline_stats.capture(
            captured.then_some(pipe.pipeline),
            desc.label,
            "compute",
            None,
        );
        tracing::debug!(label = desc.label, "compute pipeline created");
        Ok(pipe)
    }

    pub fn label(&self) -> &str {
        &self.label
    }

    /// The driver's statistics of its executable: `Some` only when the context was opened
    /// with `pipeline_stats` on a device with `VK_KHR_pipeline_executable_properties`.
    pub fn executable_stats(&self) -> Option<&PipelineExecutableStats> {
        self.stats.as_ref()
    }

    pub(crate) fn handle(&self) -> vk::Pipeline {
        self.pipeline
    }
    pub(crate) fn layout(&self) -> vk::PipelineLayout {
        self.layout
    }

    /// Makes a descriptor set binding `buffers[i]` at binding `i` (one per storage binding).
    pub fn bind_storage_buffers<'b>(&self, buffers: &[&'b Buffer]) -> Result<BindingSet<'b>> {
        if buffers.len() != self.storage_buffer_count as usize {
            return Err(VkError::InvalidRequest(format!(
                "pipeline {:?} has {} storage bindings, got {} buffers",
                self.label,
                self.storage_buffer_count,
                buffers.len()
            )));
        }
        let max_range = u64::from(self.shared.limits.max_storage_buffer_range);
        for b in buffers {
            if !b.same_device(&self.shared) {
                return Err(VkError::InvalidRequest(format!(
                    "buffer {:?} belongs to another device",
                    b.label()
                )));
            }
            b.check_bound()?;
            if !b.usage().contains(BufferUsage::STORAGE) {
                return Err(VkError::InvalidRequest(format!(
                    "buffer {:?} lacks STORAGE usage",
                    b.label()
                )));
            }
            if b.size_bytes() > max_range {
                return Err(VkError::InvalidRequest(format!(
                    "buffer {:?} ({} bytes) exceeds max_storage_buffer_range {max_range}",
                    b.label(),
                    b.size_bytes()
                )));
            }
        }
        let device = &self.shared.device;
        let mut set = BindingSet {
            shared: Arc::clone(&self.shared),
            pool: vk::DescriptorPool::null(),
            set: vk::DescriptorSet::null(),
            set_layout: self.set_layout,
            _buffers: PhantomData,
        };
        let sizes = [vk::DescriptorPoolSize {
            ty: vk::DescriptorType::STORAGE_BUFFER,
            descriptor_count: self.storage_buffer_count.max(1),
        }];
        let pool_info = vk::DescriptorPoolCreateInfo::default()
            .max_sets(1)
            .pool_sizes(&sizes);
        // SAFETY: valid create info; the pool is owned by `set`.
        set.pool = unsafe { device.create_descriptor_pool(&pool_info, None) }
            .map_err(VkError::vk("vkCreateDescriptorPool"))?;
        let layouts = [self.set_layout];
        let alloc = vk::DescriptorSetAllocateInfo::default()
            .descriptor_pool(set.pool)
            .set_layouts(&layouts);
        // SAFETY: the pool has room for one set of this layout.
        set.set = unsafe { device.allocate_descriptor_sets(&alloc) }
            .map_err(VkError::vk("vkAllocateDescriptorSets"))?[0];
        let infos: Vec<[vk::DescriptorBufferInfo; 1]> = buffers
            .iter()
            .map(|b| {
                [vk::DescriptorBufferInfo {
                    buffer: b.handle(),
                    offset: 0,
                    range: vk::WHOLE_SIZE,
                }]
            })
            .collect();
        let writes: Vec<_> = infos
            .iter()
            .enumerate()
            .map(|(i, info)| {
                vk::WriteDescriptorSet::default()
                    .dst_set(set.set)
                    .dst_binding(i as u32)
                    .descriptor_type(vk::DescriptorType::STORAGE_BUFFER)
                    .buffer_info(info)
            })
            .collect();
        // SAFETY: the set is live and not in use; buffers are bound with STORAGE usage and
        // within the range limit (checked above).
        unsafe { device.update_descriptor_sets(&writes, &[]) };
        Ok(set)
    }

    pub(crate) fn check_dispatch(
        &self,
        shared: &Arc<DeviceShared>,
        bindings: Option<&BindingSet<'_>>,
        push_constants: &[u8],
        group_count: [u32; 3],
    ) -> Result<()> {
        let bad = |why: String| {
            Err(VkError::InvalidRequest(format!(
                "dispatch of {:?}: {why}",
                self.label
            )))
        };
        if !Arc::ptr_eq(&self.shared, shared) {
            return bad("pipeline belongs to another device".into());
        }
        match bindings {
            None if self.storage_buffer_count > 0 => return bad("missing its binding set".into()),
            Some(b) if b.set_layout != self.set_layout => {
                return bad("binding set was made for another pipeline".into())
            }
            _ => {}
        }
        if push_constants.len() != self.push_constant_size_bytes as usize {
            return bad(format!(
                "{} bytes of push constants, the pipeline declares {}",
                push_constants.len(),
                self.push_constant_size_bytes
            ));
        }
        let max = shared.limits.max_compute_work_group_count;
        if group_count.iter().zip(max).any(|(g, m)| *g > m) {
            return bad(format!("group count {group_count:?} exceeds {max:?}"));
        }
        Ok(())
    }
}

impl Drop for ComputePipeline {
    fn drop(&mut self) {
        let device = &self.shared.device;
        // SAFETY: created from this device; no recorder can outlive its borrow of the pipeline,
        // so no pending work uses it. Null handles (partial construction) are ignored by Vulkan.
        unsafe {
            device.destroy_pipeline(self.pipeline, None);
            device.destroy_pipeline_layout(self.layout, None);
            device.destroy_descriptor_set_layout(self.set_layout, None);
        }
    }
}

/// A descriptor set of storage buffers for one [`ComputePipeline`], borrowing the buffers.
pub struct BindingSet<'b> {
    shared: Arc<DeviceShared>,
    pool: vk::DescriptorPool,
    set: vk::DescriptorSet,
    set_layout: vk::DescriptorSetLayout,
    _buffers: PhantomData<&'b Buffer>,
}

impl std::fmt::Debug for BindingSet<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BindingSet").finish_non_exhaustive()
    }
}

impl BindingSet<'_> {
    pub(crate) fn handle(&self) -> vk::DescriptorSet {
        self.set
    }
}

impl Drop for BindingSet<'_> {
    fn drop(&mut self) {
        // SAFETY: destroying the pool frees its set; no pending work uses it (recorder borrow).
        unsafe { self.shared.device.destroy_descriptor_pool(self.pool, None) };
    }
}
