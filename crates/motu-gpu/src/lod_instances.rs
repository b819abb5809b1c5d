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
    AsBuildFlags, BufferUsage, ComputePipeline, ComputePipelineDesc, Context, GpuHeap, HeapBuffer,
};

use crate::error::{GpuError, Result};
use crate::scene::{
    box_list_instances, encode_instance, table_usage, AccelStruct, GpuScene, InstanceLodGpu,
    LodPush, LodTlas, Slot, Uploader, SLOT_COUNT,
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
        let blas_addresses: Vec<u64> = self
            .blases
            .iter()
            .map(|b| b.as_ref().map_or(0, |a| a.address))
            .collect();
        let mut build = LodBuild {
            ctx: &ctx,
            heap: self.heap.get_mut().unwrap_or_else(|e| e.into_inner()),
            base,
            view: &view,
            lod,
            buffers: Vec::new(),
            accels: Vec::new(),
        };
        let gpu = match build.run(&blas_addresses, &self.addresses) {
            Ok(g) => g,
            Err(e) => {
                build.release();
                return Err(e);
            }
        };
        let accels = std::mem::take(&mut build.accels);
        self.install(gpu, accels)
    }

    /// Swaps the LOD pass's slot TLASes in (their first build is the first frame's LOD pass),
    /// points the shaders' TLAS address table at them and keeps the pass.
    fn install(&mut self, gpu: InstanceLodGpu, accels: Vec<SlotTlas>) -> Result<()> {
        let heap = self.heap.get_mut().unwrap_or_else(|e| e.into_inner());
        for SlotTlas { tlas, accel } in accels {
            self.report.as_bytes =
                self.report.as_bytes + accel.size_bytes - self.tlases[tlas as usize].size_bytes;
            let old = std::mem::replace(&mut self.tlases[tlas as usize], accel);
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
            .upload(&self.ctx, table, 0, cast_slice(&addrs))
            .and_then(|_| up.flush(&self.ctx));
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

/// A slot TLAS built for the LOD pass, to replace the scene's TLAS `tlas`.
struct SlotTlas {
    tlas: u32,
    accel: AccelStruct,
}

/// The slot TLASes and the one scratch buffer their builds and updates share.
struct SlotTlasLayout {
    tlases: Vec<LodTlas>,
    scratch_bytes: u64,
}

/// Device addresses of the LOD pass's uploaded tables.
struct LodTables {
    blas_addresses: u64,
    slots: u64,
    vk_instances: u64,
}

/// `enable_instance_lod`'s build, one method per phase. It owns what it allocates (`buffers`,
/// `accels`) until [`LodBuild::run`] hands the buffers to the pass; on failure
/// [`LodBuild::release`] frees them.
struct LodBuild<'a> {
    ctx: &'a Context,
    heap: &'a mut GpuHeap,
    base: &'a HierarchyView<'a>,
    view: &'a HierarchyView<'a>,
    lod: &'a InstanceLod,
    buffers: Vec<HeapBuffer>,
    accels: Vec<SlotTlas>,
}

impl LodBuild<'_> {
    /// The pass's resources: pipeline, slot TLASes, scratch, tables and the levels buffer.
    fn run(
        &mut self,
        blas_addresses: &[u64],
        scene_addresses: &[u64; SLOT_COUNT],
    ) -> Result<InstanceLodGpu> {
        let pipeline = ComputePipeline::new(
            self.ctx,
            &ComputePipelineDesc {
                label: "instance LOD",
                spirv: shaders::LOD_INSTANCES_COMP,
                storage_buffer_count: 0,
                push_constant_size_bytes: std::mem::size_of::<LodPush>() as u32,
                specialization: &[],
            },
        )?;
        let layout = self.slot_tlases()?;
        let scratch_address = self.scratch(layout.scratch_bytes)?;
        let vk_bytes = self.instance_bytes(blas_addresses);
        let tables = self.upload_tables(blas_addresses, &vk_bytes)?;
        let (levels, levels_address) = self.levels_buffer()?;
        let lod = self.lod;
        let push = LodPush {
            levels: levels_address,
            tlases: scene_addresses[Slot::Tlases as usize],
            instances: scene_addresses[Slot::Instances as usize],
            selectors: scene_addresses[Slot::Selectors as usize],
            lod_levels: scene_addresses[Slot::LodLevels as usize],
            slots: tables.slots,
            blas_addresses: tables.blas_addresses,
            vk_instances: tables.vk_instances,
            slot_count: lod.slots.len() as u32,
            lod_instance_base: lod.lod_instance_base,
            refit: 0,
            _pad: 0,
        };
        Ok(InstanceLodGpu {
            pipeline,
            _buffers: std::mem::take(&mut self.buffers),
            push,
            scratch_address,
            tlases: layout.tlases,
            group_count: (lod.slots.len() as u32).div_ceil(64),
            slot_count: lod.slots.len() as u32,
            slots: lod.slots.clone(),
            level_counts: lod
                .slots
                .iter()
                .map(|s| self.base.lod_selectors[s.selector as usize].level_count)
                .collect(),
            levels,
            state: InstanceLodGpu::new_state(),
            counts: Mutex::new([0; 4]),
            pass_ms: Mutex::new((0.0, 0)),
        })
    }

    /// Uncompacted slot TLASes sized for either kind of pass (scene/lod_pass.rs `PassKind`),
    /// and their scratch slices (for a build or an update).
    fn slot_tlases(&mut self) -> Result<SlotTlasLayout> {
        let flags = AsBuildFlags {
            allow_compaction: false,
            ..AsBuildFlags::default()
        };
        let refittable = AsBuildFlags {
            allow_update: true,
            ..flags
        };
        let scratch_align = self.ctx.limits().scratch_alignment_bytes();
        let mut tlases = Vec::new();
        let mut scratch_bytes = 0u64;
        for &t in &self.lod.lod_tlases {
            let rec = &self.view.tlases[t as usize];
            let hardware = rec.instance_count - box_list_instances(self.view, t as usize);
            let sz = self.ctx.tlas_build_sizes(hardware, flags)?;
            let sz_refit = self.ctx.tlas_build_sizes(hardware, refittable)?;
            let a = AccelStruct::new(
                self.ctx,
                self.heap,
                &format!("lod-tlas-{t}"),
                sz.acceleration_structure_size_bytes
                    .max(sz_refit.acceleration_structure_size_bytes),
                motu_vk::AsLevel::Top,
            )?;
            tlases.push(LodTlas {
                handle: a.target(),
                // A box list's instances are tested in raygen, as in the scene's build.
                count: hardware,
                offset_bytes: u64::from(rec.instance_base - self.lod.lod_instance_base) * 64,
                scratch_offset_bytes: scratch_bytes,
            });
            let scratch = sz
                .build_scratch_size_bytes
                .max(sz_refit.build_scratch_size_bytes)
                .max(sz_refit.update_scratch_size_bytes);
            scratch_bytes += scratch.div_ceil(scratch_align) * scratch_align;
            self.accels.push(SlotTlas { tlas: t, accel: a });
        }
        Ok(SlotTlasLayout {
            tlases,
            scratch_bytes,
        })
    }

    /// The slot TLASes' shared scratch buffer: its aligned device address.
    fn scratch(&mut self, scratch_bytes: u64) -> Result<u64> {
        let scratch_align = self.ctx.limits().scratch_alignment_bytes();
        let scratch = buffer(
            self.heap,
            "lod-scratch",
            scratch_bytes + scratch_align,
            BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
            AllocKind::Scratch,
            scratch_align,
        )?;
        let address = scratch.device_address()?.0.div_ceil(scratch_align) * scratch_align;
        self.buffers.push(scratch);
        Ok(address)
    }

    /// The TLAS instance buffer at the initial levels. Each instance's custom index is its
    /// index inside its own TLAS (the hit shaders find the record from the TLAS's base plus
    /// that index).
    fn instance_bytes(&self, blas_addresses: &[u64]) -> Vec<u8> {
        let (view, lod) = (self.view, self.lod);
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
        view.instances[lod_base..]
            .iter()
            .zip(&local_index)
            .flat_map(|(inst, &local)| {
                encode_instance(
                    &inst.tlas_from_blas,
                    view.blases[inst.blas as usize].kind == BLAS_AABBS,
                    inst.flags & FLAG_NEEDS_ANY_HIT != 0,
                    blas_addresses[inst.blas as usize],
                    local,
                )
            })
            .collect()
    }

    /// Uploads the BLAS address table, the slots and the instance buffer.
    fn upload_tables(&mut self, blas_addresses: &[u64], vk_bytes: &[u8]) -> Result<LodTables> {
        let ctx = self.ctx;
        let mut up = Uploader::new(self.heap, 4 << 20)?;
        let uploaded = (|| -> Result<[u64; 3]> {
            let mut addrs = [0u64; 3];
            for (k, (label, bytes, usage, kind)) in [
                (
                    "lod-blas-addresses",
                    cast_slice::<u64, u8>(blas_addresses),
                    table_usage(),
                    AllocKind::NodeTable,
                ),
                (
                    "lod-slots",
                    cast_slice(&self.lod.slots),
                    table_usage(),
                    AllocKind::NodeTable,
                ),
                (
                    "lod-instances",
                    vk_bytes,
                    table_usage().union(BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT),
                    AllocKind::InstanceBuffer,
                ),
            ]
            .into_iter()
            .enumerate()
            {
                let b = buffer(self.heap, label, bytes.len() as u64, usage, kind, 16)?;
                addrs[k] = b.device_address()?.0;
                if !bytes.is_empty() {
                    up.upload(ctx, &b, 0, bytes)?;
                }
                self.buffers.push(b);
            }
            up.flush(ctx)?;
            Ok(addrs)
        })();
        self.heap.free(up.staging);
        let [blas_addresses, slots, vk_instances] = uploaded?;
        Ok(LodTables {
            blas_addresses,
            slots,
            vk_instances,
        })
    }

    /// The host-visible buffer the host writes each pass's levels into, and its address.
    fn levels_buffer(&mut self) -> Result<(HeapBuffer, u64)> {
        let levels = self.heap.alloc_buffer(
            "lod-levels",
            (self.lod.slots.len() as u64 * 4).max(16),
            BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
            AllocKind::NodeTable,
            MemoryClass::HostVisible,
            16,
        )?;
        match levels.device_address() {
            Ok(a) => Ok((levels, a.0)),
            Err(e) => {
                self.heap.free(levels);
                Err(e.into())
            }
        }
    }

    /// Frees what the build allocated (after a failed phase).
    fn release(self) {
        self.buffers.into_iter().for_each(|b| self.heap.free(b));
        self.accels
            .into_iter()
            .for_each(|s| s.accel.release(self.heap));
    }
}
