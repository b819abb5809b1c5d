//! The per-frame instance-LOD pass's resources, owned by [`GpuScene`](super::GpuScene) (set up
//! by `lod_instances.rs`): the compute pipeline, the slot TLASes it rebuilds, and when a frame
//! needs the pass.

use std::sync::Mutex;

use ash::vk;
use bytemuck::{Pod, Zeroable};

use crate::command::CommandRecorder;
use crate::context::Context;
use crate::error::Result;
use crate::heap::HeapBuffer;
use crate::pipeline::ComputePipeline;

/// `lod_instances.comp`'s push constants.
#[derive(Clone, Copy, Pod, Zeroable)]
#[repr(C)]
pub(crate) struct Push {
    pub frame: u64,
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
    /// The camera and LOD parameters (bytes, see [`InstanceLodGpu::needs_pass`]) the slot
    /// TLASes hold the levels of; None before the first pass and while a submission that
    /// rebuilds them has not completed (a failed one leaves them unknown).
    pub built_for: Mutex<Option<Vec<u8>>>,
    /// Frames that ran the pass and frames that skipped it (levels already current).
    pub counts: Mutex<[u64; 2]>,
}

impl InstanceLodGpu {
    /// Whether a frame with the levels' inputs `key` (the frame's camera and LOD parameters)
    /// needs the pass: false when the slot TLASes already hold that key's levels. When it
    /// returns true the built state is marked unknown until [`Self::built`] confirms the
    /// submission that rebuilds them completed.
    /// `frames` frames of this camera follow; all but the first skip the pass.
    pub(crate) fn needs_pass(&self, key: &[u8], frames: u32) -> bool {
        let mut built = self.built_for.lock().unwrap_or_else(|e| e.into_inner());
        let mut counts = self.counts.lock().unwrap_or_else(|e| e.into_inner());
        let needed = built.as_deref() != Some(key);
        if needed {
            *built = None;
            counts[0] += 1;
        }
        counts[1] += u64::from(frames) - u64::from(needed);
        needed
    }

    /// The submission with the pass for `key` completed: the slot TLASes hold its levels.
    pub(crate) fn built(&self, key: Vec<u8>) {
        *self.built_for.lock().unwrap_or_else(|e| e.into_inner()) = Some(key);
    }

    /// Records the LOD pass for the frame whose parameters are at `frame_address`: pick
    /// levels, write instances, rebuild the slots' TLASes. The caller orders it after the
    /// previous frame's trace (a full barrier); a barrier follows each step.
    pub(crate) fn record<'a>(
        &'a self,
        ctx: &Context,
        rec: &mut CommandRecorder<'a>,
        frame_address: u64,
    ) -> Result<()> {
        let push = Push {
            frame: frame_address,
            ..self.push
        };
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
