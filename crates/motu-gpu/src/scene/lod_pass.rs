//! The per-frame instance-LOD pass's resources, owned by [`GpuScene`](super::GpuScene) (set up
//! by `lod_instances.rs`): the compute pipeline, the slot TLASes it rebuilds, and when a frame
//! needs the pass.

use std::sync::Mutex;

use ash::vk;
use bytemuck::{Pod, Zeroable};

use motu_abi::camera::CameraParams;
use motu_abi::lod::LodParams;
use motu_abi::lod_instance::{camera_level, LodSlotRecord};

use crate::command::CommandRecorder;
use crate::context::Context;
use crate::error::{GpuError, Result};
use crate::heap::HeapBuffer;
use crate::pipeline::ComputePipeline;

/// `lod_instances.comp`'s push constants.
#[derive(Clone, Copy, Pod, Zeroable)]
#[repr(C)]
pub(crate) struct Push {
    /// The frame's level per slot (host-visible, written before the pass is recorded).
    pub levels: u64,
    pub tlases: u64,
    pub instances: u64,
    pub selectors: u64,
    pub lod_levels: u64,
    pub slots: u64,
    pub blas_addresses: u64,
    pub vk_instances: u64,
    pub slot_count: u32,
    pub lod_instance_base: u32,
    pub _pad: [u32; 2],
}

/// One TLAS rebuilt every frame: its instances at `offset_bytes` in the instance buffer; the
/// structure itself is `GpuScene::tlases[tlas]` (built without compaction, so a rebuild fits).
pub(crate) struct LodTlas {
    pub handle: vk::AccelerationStructureKHR,
    pub count: u32,
    pub offset_bytes: u64,
    pub scratch_offset_bytes: u64,
}

/// The per-frame LOD pass's resources (owned by [`GpuScene`](super::GpuScene)).
pub(crate) struct InstanceLodGpu {
    pub pipeline: ComputePipeline,
    /// Scratch, BLAS addresses, slots, instance buffer: kept for the scene's life.
    pub _buffers: Vec<HeapBuffer>,
    pub push: Push,
    pub scratch_address: u64,
    pub tlases: Vec<LodTlas>,
    pub group_count: u32,
    /// Slots (LOD'd instances), for stats.
    pub slot_count: u32,
    /// The slots and each one's level count: the host picks the levels.
    pub slots: Vec<LodSlotRecord>,
    pub level_counts: Vec<u32>,
    /// The levels the next pass applies (one u32 per slot, host-visible; `Push::levels`).
    pub levels: HeapBuffer,
    /// The levels (one per slot) the slot TLASes hold; None before the first pass and while
    /// a submission that rebuilds them has not completed (a failed one leaves them unknown).
    pub built_for: Mutex<Option<Vec<u32>>>,
    /// Frames that ran the pass and frames that skipped it (levels already current).
    pub counts: Mutex<[u64; 2]>,
}

impl InstanceLodGpu {
    /// Each slot's level for a camera: the rule of `InstanceLod::levels` (the CPU oracle's).
    pub(crate) fn levels(&self, camera: &CameraParams, lod: &LodParams) -> Vec<u32> {
        self.slots
            .iter()
            .zip(&self.level_counts)
            .map(|(s, &n)| camera_level(lod, camera.pixels_per_unit_at_1, camera.world_eye, s, n))
            .collect()
    }

    /// Whether a frame showing `levels` (one per slot, [`Self::levels`]) needs the pass:
    /// false when the slot TLASes already hold exactly those levels. When it returns true the
    /// built state is marked unknown until [`Self::built`] confirms the submission that
    /// rebuilds them completed.
    /// `frames` frames of this camera follow; all but the first skip the pass.
    pub(crate) fn needs_pass(&self, levels: &[u32], frames: u32) -> bool {
        let mut built = self.built_for.lock().unwrap_or_else(|e| e.into_inner());
        let mut counts = self.counts.lock().unwrap_or_else(|e| e.into_inner());
        let needed = built.as_deref() != Some(levels);
        if needed {
            *built = None;
            counts[0] += 1;
        }
        counts[1] += u64::from(frames) - u64::from(needed);
        needed
    }

    /// The submission with the pass for `levels` completed: the slot TLASes hold them.
    pub(crate) fn built(&self, levels: Vec<u32>) {
        *self.built_for.lock().unwrap_or_else(|e| e.into_inner()) = Some(levels);
    }

    /// Records the LOD pass applying `levels` (one per slot): write instances, rebuild the
    /// slots' TLASes. The levels go to a host-visible buffer now, so the caller must not
    /// record another pass before this submission completed (one pass per submission, which
    /// is waited for). The caller orders it after the previous frame's trace (a full
    /// barrier); a barrier follows each step.
    pub(crate) fn record<'a>(
        &'a self,
        ctx: &Context,
        rec: &mut CommandRecorder<'a>,
        levels: &[u32],
    ) -> Result<()> {
        if levels.len() != self.slots.len() {
            return Err(GpuError::InvalidRequest(format!(
                "instance LOD: {} levels for {} slots",
                levels.len(),
                self.slots.len()
            )));
        }
        if !levels.is_empty() {
            self.levels.write(0, levels)?;
        }
        let push = self.push;
        rec.dispatch(
            &self.pipeline,
            None,
            bytemuck::bytes_of(&push),
            [self.group_count, 1, 1],
        )?;
        rec.barrier();
        let accel = ctx.accel_device()?;
        let geometries: Vec<[vk::AccelerationStructureGeometryKHR<'_>; 1]> = self
            .tlases
            .iter()
            .map(|t| {
                let instances = vk::AccelerationStructureGeometryInstancesDataKHR::default()
                    .array_of_pointers(false)
                    .data(vk::DeviceOrHostAddressConstKHR {
                        device_address: self.push.vk_instances + t.offset_bytes,
                    });
                [vk::AccelerationStructureGeometryKHR::default()
                    .geometry_type(vk::GeometryTypeKHR::INSTANCES)
                    .geometry(vk::AccelerationStructureGeometryDataKHR { instances })]
            })
            .collect();
        let ranges: Vec<[vk::AccelerationStructureBuildRangeInfoKHR; 1]> = self
            .tlases
            .iter()
            .map(|t| {
                [vk::AccelerationStructureBuildRangeInfoKHR::default().primitive_count(t.count)]
            })
            .collect();
        let infos: Vec<vk::AccelerationStructureBuildGeometryInfoKHR<'_>> = self
            .tlases
            .iter()
            .zip(&geometries)
            .map(|(t, g)| {
                vk::AccelerationStructureBuildGeometryInfoKHR::default()
                    .ty(vk::AccelerationStructureTypeKHR::TOP_LEVEL)
                    .flags(vk::BuildAccelerationStructureFlagsKHR::PREFER_FAST_TRACE)
                    .mode(vk::BuildAccelerationStructureModeKHR::BUILD)
                    .dst_acceleration_structure(t.handle)
                    .geometries(g)
                    .scratch_data(vk::DeviceOrHostAddressKHR {
                        device_address: self.scratch_address + t.scratch_offset_bytes,
                    })
            })
            .collect();
        let range_refs: Vec<&[vk::AccelerationStructureBuildRangeInfoKHR]> =
            ranges.iter().map(|r| r.as_slice()).collect();
        let (_, cmd) = rec.raw();
        // SAFETY: recording state; the destinations (the scene's TLASes), the instance buffer
        // and the disjoint, aligned scratch slices live as long as the scene, which outlives
        // every submission recording this pass (callers wait on it).
        unsafe { accel.cmd_build_acceleration_structures(cmd, &infos, &range_refs) };
        rec.barrier();
        Ok(())
    }
}
