//! Instance-level LOD on the GPU (motu_abi::lod_instance): each frame, before tracing, the
//! host picks every slot's level for the frame's camera with the CPU oracle's own rule
//! (`InstanceLod::levels`, so GPU and CPU levels agree exactly), and when any slot's level
//! differs from the ones the slot TLASes hold, a compute pass (`shaders/lod_instances.comp`)
//! writes the chosen levels' BLAS addresses into the TLAS instance buffer and the slots'
//! TLASes are rebuilt (`scene/lod_pass.rs`). Rays then reach LOD'd geometry in one trace,
//! without a traversal-shader hop.
//!
//! The pass is skipped when no slot's level changes: a static camera (progressive frames,
//! repeated renders), pans and turns, and the frames of a moving camera in which no slot
//! crosses a level threshold (the rebuild, not the level choice, is what costs GPU time).

use std::sync::Mutex;

use bytemuck::cast_slice;
use motu_abi::lod_instance::InstanceLod;
use motu_abi::{HierarchyView, BLAS_AABBS, FLAG_NEEDS_ANY_HIT};
use motu_alloc::{AllocKind, MemoryClass};
use motu_vk::{
    AsBuildFlags, BufferUsage, ComputePipeline, ComputePipelineDesc, GpuHeap, HeapBuffer,
};

use crate::error::{GpuError, Result};
use crate::scene::{
    box_list_instances, encode_instance, table_usage, AccelStruct, GpuScene, InstanceLodGpu,
    LodPush, LodTlas, Slot, Uploader,
};
use crate::shaders;

fn buffer(
    heap: &mut GpuHeap,
    label: &str,
    size_bytes: u64,
    usage: BufferUsage,
    kind: AllocKind,
    alignment: u64,
) -> Result<HeapBuffer> {
    heap.alloc_buffer(
        label,
        size_bytes.max(16),
        usage,
        kind,
        MemoryClass::DeviceLocal,
        alignment,
    )
    .map_err(Into::into)
}

impl GpuScene {
    /// Turns on instance-level LOD for a scene built from `lod.view(base)`: the slots' TLASes
    /// are rebuilt uncompacted (they are rebuilt every frame) and the LOD pass runs before
    /// each frame's trace of every renderer on this scene.
    pub fn enable_instance_lod(
        &mut self,
        base: &HierarchyView<'_>,
        lod: &InstanceLod,
    ) -> Result<()> {
        if self.instance_lod.is_some() {
            return Err(GpuError::InvalidRequest(
                "instance LOD is already enabled on this scene".into(),
            ));
        }
        let view = lod.view(base);
        if view.tlases.len() != self.tlases.len() || view.blases.len() != self.blases.len() {
            return Err(GpuError::InvalidRequest(
                "instance LOD: the scene was not built from this rewrite".into(),
            ));
        }
        let ctx = self.ctx.clone();
        let mut buffers: Vec<HeapBuffer> = Vec::new();
        let mut accels: Vec<(u32, AccelStruct)> = Vec::new();
        let heap = self.heap.get_mut().unwrap_or_else(|e| e.into_inner());
        let r = (|| -> Result<InstanceLodGpu> {
            let pipeline = ComputePipeline::new(
                &ctx,
                &ComputePipelineDesc {
                    label: "instance LOD",
                    spirv: shaders::LOD_INSTANCES_COMP,
                    storage_buffer_count: 0,
                    push_constant_size_bytes: std::mem::size_of::<LodPush>() as u32,
                    specialization: &[],
                },
            )?;
            // Uncompacted TLASes sized for either kind of pass (scene/lod_pass.rs `PassKind`),
            // and their scratch slices (for a build or an update).
            let flags = AsBuildFlags {
                allow_compaction: false,
                ..AsBuildFlags::default()
            };
            let refittable = AsBuildFlags {
                allow_update: true,
                ..flags
            };
            let scratch_align = ctx.limits().scratch_alignment_bytes();
            let mut tlases = Vec::new();
            let mut scratch_bytes = 0u64;
            for &t in &lod.lod_tlases {
                let rec = &view.tlases[t as usize];
                let hardware = rec.instance_count - box_list_instances(&view, t as usize);
                let sz = ctx.tlas_build_sizes(hardware, flags)?;
                let sz_refit = ctx.tlas_build_sizes(hardware, refittable)?;
                let a = AccelStruct::new(
                    &ctx,
                    heap,
                    &format!("lod-tlas-{t}"),
                    sz.acceleration_structure_size_bytes
                        .max(sz_refit.acceleration_structure_size_bytes),
                    motu_vk::AsLevel::Top,
                )?;
                tlases.push(LodTlas {
                    handle: a.target(),
                    // A box list's instances are tested in raygen, as in the scene's build.
                    count: hardware,
                    offset_bytes: u64::from(rec.instance_base - lod.lod_instance_base) * 64,
                    scratch_offset_bytes: scratch_bytes,
                });
                let scratch = sz
                    .build_scratch_size_bytes
                    .max(sz_refit.build_scratch_size_bytes)
                    .max(sz_refit.update_scratch_size_bytes);
                scratch_bytes += scratch.div_ceil(scratch_align) * scratch_align;
                accels.push((t, a));
            }
            let scratch = buffer(
                heap,
                "lod-scratch",
                scratch_bytes + scratch_align,
                BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
                AllocKind::Scratch,
                scratch_align,
            )?;
            let scratch_address =
                scratch.device_address()?.0.div_ceil(scratch_align) * scratch_align;
            buffers.push(scratch);
            // The BLAS address table, the slots and the instance buffer (initial levels).
            let blas_addr: Vec<u64> = self
                .blases
                .iter()
                .map(|b| b.as_ref().map_or(0, |a| a.address))
                .collect();
            // Each instance's custom index is its index inside its own TLAS (the hit shaders
            // find the record from the TLAS's base plus that index).
            let lod_base = lod.lod_instance_base as usize;
            let mut local_index: Vec<u32> = (0..view.instances.len() - lod_base)
                .map(|i| i as u32)
                .collect();
            for &t in &lod.lod_tlases {
                let rec = &view.tlases[t as usize];
                for k in 0..rec.instance_count {
                    if let Some(slot) = (rec.instance_base + k)
                        .checked_sub(lod.lod_instance_base)
                        .and_then(|vi| local_index.get_mut(vi as usize))
                    {
                        *slot = k;
                    }
                }
            }
            let vk_bytes: Vec<u8> = view.instances[lod_base..]
                .iter()
                .zip(&local_index)
                .flat_map(|(inst, &local)| {
                    encode_instance(
                        &inst.tlas_from_blas,
                        view.blases[inst.blas as usize].kind == BLAS_AABBS,
                        inst.flags & FLAG_NEEDS_ANY_HIT != 0,
                        blas_addr[inst.blas as usize],
                        local,
                    )
                })
                .collect();
            let mut up = Uploader::new(heap, 4 << 20)?;
            let uploaded = (|| -> Result<[u64; 3]> {
                let mut addrs = [0u64; 3];
                for (k, (label, bytes, usage, kind)) in [
                    (
                        "lod-blas-addresses",
                        cast_slice::<u64, u8>(&blas_addr),
                        table_usage(),
                        AllocKind::NodeTable,
                    ),
                    (
                        "lod-slots",
                        cast_slice(&lod.slots),
                        table_usage(),
                        AllocKind::NodeTable,
                    ),
                    (
                        "lod-instances",
                        &vk_bytes[..],
                        table_usage().union(BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT),
                        AllocKind::InstanceBuffer,
                    ),
                ]
                .into_iter()
                .enumerate()
                {
                    let b = buffer(heap, label, bytes.len() as u64, usage, kind, 16)?;
                    addrs[k] = b.device_address()?.0;
                    if !bytes.is_empty() {
                        up.upload(&ctx, &b, 0, bytes)?;
                    }
                    buffers.push(b);
                }
                up.flush(&ctx)?;
                Ok(addrs)
            })();
            heap.free(up.staging);
            let [blas_addresses, slots, vk_instances] = uploaded?;
            let levels = heap.alloc_buffer(
                "lod-levels",
                (lod.slots.len() as u64 * 4).max(16),
                BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
                AllocKind::NodeTable,
                MemoryClass::HostVisible,
                16,
            )?;
            let levels_address = match levels.device_address() {
                Ok(a) => a.0,
                Err(e) => {
                    heap.free(levels);
                    return Err(e.into());
                }
            };
            let push = LodPush {
                levels: levels_address,
                tlases: self.addresses[Slot::Tlases as usize],
                instances: self.addresses[Slot::Instances as usize],
                selectors: self.addresses[Slot::Selectors as usize],
                lod_levels: self.addresses[Slot::LodLevels as usize],
                slots,
                blas_addresses,
                vk_instances,
                slot_count: lod.slots.len() as u32,
                lod_instance_base: lod.lod_instance_base,
                refit: 0,
                _pad: 0,
            };
            Ok(InstanceLodGpu {
                pipeline,
                _buffers: std::mem::take(&mut buffers),
                push,
                scratch_address,
                tlases,
                group_count: (lod.slots.len() as u32).div_ceil(64),
                slot_count: lod.slots.len() as u32,
                slots: lod.slots.clone(),
                level_counts: lod
                    .slots
                    .iter()
                    .map(|s| base.lod_selectors[s.selector as usize].level_count)
                    .collect(),
                levels,
                state: InstanceLodGpu::new_state(),
                counts: Mutex::new([0; 4]),
                pass_ms: Mutex::new((0.0, 0)),
            })
        })();
        let gpu = match r {
            Ok(g) => g,
            Err(e) => {
                buffers.into_iter().for_each(|b| heap.free(b));
                accels.into_iter().for_each(|(_, a)| a.release(heap));
                return Err(e);
            }
        };
        // Swap the new structures in (their first build is the first frame's LOD pass) and
        // point the shaders' address table at them.
        for (t, a) in accels {
            self.report.as_bytes =
                self.report.as_bytes + a.size_bytes - self.tlases[t as usize].size_bytes;
            let old = std::mem::replace(&mut self.tlases[t as usize], a);
            old.release(heap);
        }
        let addrs: Vec<u64> = self.tlases.iter().map(|t| t.address).collect();
        let table = self
            .tables
            .iter()
            .find(|b| {
                b.device_address()
                    .is_ok_and(|a| a.0 == self.addresses[Slot::TlasAddresses as usize])
            })
            .ok_or_else(|| GpuError::InvalidRequest("TLAS address table missing".into()))?;
        let mut up = Uploader::new(heap, 64 << 10)?;
        let r = up
            .upload(&ctx, table, 0, cast_slice(&addrs))
            .and_then(|_| up.flush(&ctx));
        heap.free(up.staging);
        self.instance_lod = Some(gpu);
        r
    }

    /// Mean GPU time (ms) of the instance-LOD passes timed so far; 0 when none ran.
    pub fn lod_instance_pass_ms(&self) -> f64 {
        self.instance_lod.as_ref().map_or(0.0, |l| {
            let (sum, n) = *l.pass_ms.lock().unwrap_or_else(|e| e.into_inner());
            if n == 0 {
                0.0
            } else {
                sum / n as f64
            }
        })
    }

    /// LOD instance slots (instance-level LOD), 0 when it is off.
    pub fn lod_instance_slots(&self) -> u32 {
        self.instance_lod.as_ref().map_or(0, |l| l.slot_count)
    }

    /// Instance-level LOD so far on this scene: `[frames that ran the pass, frames that
    /// skipped it]` (skipped: the frame's camera and LOD parameters equalled those the levels
    /// were built for). `[0, 0]` when off.
    pub fn lod_instance_passes(&self) -> [u64; 2] {
        self.instance_lod.as_ref().map_or([0; 2], |l| {
            let c = *l.counts.lock().unwrap_or_else(|e| e.into_inner());
            [c[0], c[1]]
        })
    }

    /// Of those: `[level passes that updated the slot TLASes in place, settle rebuilds]`
    /// (scene/lod_pass.rs `PassKind`). `[0, 0]` when off.
    pub fn lod_instance_refits(&self) -> [u64; 2] {
        self.instance_lod.as_ref().map_or([0; 2], |l| {
            let c = *l.counts.lock().unwrap_or_else(|e| e.into_inner());
            [c[2], c[3]]
        })
    }
}
