//! The per-frame instance-LOD pass's resources, owned by [`GpuScene`](super::GpuScene) (set up
//! by `lod_instances.rs`): the compute pipeline, the slot TLASes it rebuilds, and when a frame
//! needs the pass.

use std::sync::Mutex;

use bytemuck::{Pod, Zeroable};

use motu_abi::camera::CameraParams;
use motu_abi::lod::LodParams;
use motu_abi::lod_instance::{camera_level, LodSlotRecord};
use motu_vk::{
    AsBuild, AsBuildFlags, AsBuildMode, AsGeometry, AsLevel, AsTarget, CommandRecorder,
    ComputePipeline, HeapBuffer,
};

use crate::error::{GpuError, Result};

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
    /// 1: a refittable pass (every level's instance stays active: the unchosen shrink to a
    /// point and are masked out), 0: the unchosen levels are made inactive.
    pub refit: u32,
    pub _pad: u32,
}

/// One TLAS rebuilt every frame: its instances at `offset_bytes` in the instance buffer; the
/// structure itself is `GpuScene::tlases[tlas]` (built without compaction, so a rebuild fits).
pub(crate) struct LodTlas {
    pub handle: AsTarget,
    pub count: u32,
    pub offset_bytes: u64,
    pub scratch_offset_bytes: u64,
}

/// What one LOD pass does to the slot TLASes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum PassKind {
    /// Rebuild. `refittable`: over every level's instances (the unchosen ones shrunk to a
    /// point and masked out, since an update may not change which instances are active),
    /// allowing updates, for a camera that keeps moving; otherwise the unchosen levels are
    /// inactive and the tree is the best the driver builds.
    Build { refittable: bool },
    /// New levels into a refittable tree: masks and transforms switched, updated in place
    /// (on the H200 0.05 ms against 0.20 ms for the rebuild, lod-grid at 1080p).
    Update,
    /// The camera held after moving: the refittable tree (2% slower to trace) is rebuilt to
    /// full quality once, for the frames that follow.
    Settle,
}

impl PassKind {
    /// The pass leaves a refittable tree (every level active, built to allow updates).
    fn refittable(self) -> bool {
        matches!(
            self,
            PassKind::Update | PassKind::Build { refittable: true }
        )
    }
}

/// The slot TLASes' state between passes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Tree {
    /// Not built, or a pass's submission has not completed (a failed one leaves it unknown).
    Unknown,
    Refittable,
    Quality,
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
    /// The levels (one per slot) the slot TLASes hold and the kind of tree holding them;
    /// `(None, Unknown)` before the first pass and while a submission with a pass has not
    /// completed.
    pub state: Mutex<(Option<Vec<u32>>, Tree)>,
    /// Frames that ran a level pass, frames that skipped it (levels already current), level
    /// passes that were updates, settle rebuilds.
    pub counts: Mutex<[u64; 4]>,
    /// GPU time of the passes that ran (ms, summed) and how many were timed.
    pub pass_ms: Mutex<(f64, u64)>,
}

impl InstanceLodGpu {
    pub(crate) fn new_state() -> Mutex<(Option<Vec<u32>>, Tree)> {
        Mutex::new((None, Tree::Unknown))
    }

    /// Each slot's level for a camera: the rule of `InstanceLod::levels` (the CPU oracle's).
    pub(crate) fn levels(&self, camera: &CameraParams, lod: &LodParams) -> Vec<u32> {
        self.slots
            .iter()
            .zip(&self.level_counts)
            .map(|(s, &n)| camera_level(lod, camera.pixels_per_unit_at_1, camera.world_eye, s, n))
            .collect()
    }

    /// The pass a submission of `frames` frames showing `levels` (one per slot,
    /// [`Self::levels`]) runs before its first frame, if any: none when the slot TLASes hold
    /// exactly those levels in a full-quality tree. New levels update a refittable tree, or
    /// rebuild (refittable when one frame is asked for: a moving camera renders frame by
    /// frame; `frames > 1` of one camera get the full-quality tree at once); the same levels
    /// in a refittable tree settle it (the camera held). Until [`Self::built`] confirms the
    /// submission completed, the state is unknown.
    pub(crate) fn needs_pass(&self, levels: &[u32], frames: u32) -> Option<PassKind> {
        let mut state = self.state.lock().unwrap_or_else(|e| e.into_inner());
        let mut counts = self.counts.lock().unwrap_or_else(|e| e.into_inner());
        let current = state.0.as_deref() == Some(levels);
        let kind = match (current, state.1) {
            (true, Tree::Quality) => None,
            (true, _) => Some(PassKind::Settle),
            (false, Tree::Refittable) => Some(PassKind::Update),
            (false, _) => Some(PassKind::Build {
                refittable: frames == 1,
            }),
        };
        if !current {
            counts[0] += 1;
        }
        counts[1] += u64::from(frames) - u64::from(!current);
        match kind {
            Some(PassKind::Update) => counts[2] += 1,
            Some(PassKind::Settle) => counts[3] += 1,
            _ => {}
        }
        if kind.is_some() {
            *state = (None, Tree::Unknown);
        }
        kind
    }

    /// The submission with pass `kind` for `levels` completed: the slot TLASes hold them;
    /// the pass took `pass_ms` of GPU time.
    pub(crate) fn built(&self, levels: Vec<u32>, kind: PassKind, pass_ms: f64) {
        let tree = if kind.refittable() {
            Tree::Refittable
        } else {
            Tree::Quality
        };
        *self.state.lock().unwrap_or_else(|e| e.into_inner()) = (Some(levels), tree);
        let mut t = self.pass_ms.lock().unwrap_or_else(|e| e.into_inner());
        t.0 += pass_ms;
        t.1 += 1;
    }

    /// Records the LOD pass applying `levels` (one per slot): write instances, rebuild the
    /// slots' TLASes. The levels go to a host-visible buffer now, so the caller must not
    /// record another pass before this submission completed (one pass per submission, which
    /// is waited for). The caller orders it after the previous frame's trace (a full
    /// barrier); a barrier follows each step.
    pub(crate) fn record<'a>(
        &'a self,
        rec: &mut CommandRecorder<'a>,
        levels: &[u32],
        kind: PassKind,
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
        let refittable = kind.refittable();
        let mut push = self.push;
        push.refit = u32::from(refittable);
        rec.dispatch(
            &self.pipeline,
            None,
            bytemuck::bytes_of(&push),
            [self.group_count, 1, 1],
        )?;
        rec.barrier();
        let mode = if kind == PassKind::Update {
            AsBuildMode::UpdateInPlace
        } else {
            AsBuildMode::Build
        };
        let flags = AsBuildFlags {
            prefer_fast_trace: true,
            prefer_fast_build: false,
            allow_compaction: false,
            allow_update: refittable,
            low_memory: false,
        };
        let geometries: Vec<[AsGeometry; 1]> = self
            .tlases
            .iter()
            .map(|t| {
                [AsGeometry::Instances {
                    address: self.push.vk_instances + t.offset_bytes,
                }]
            })
            .collect();
        let counts: Vec<[u32; 1]> = self.tlases.iter().map(|t| [t.count]).collect();
        let builds: Vec<AsBuild<'_>> = self
            .tlases
            .iter()
            .zip(geometries.iter().zip(&counts))
            .map(|(t, (g, n))| AsBuild {
                level: AsLevel::Top,
                flags,
                mode,
                dst: t.handle,
                geometries: g,
                primitive_counts: n,
                scratch_address: self.scratch_address + t.scratch_offset_bytes,
            })
            .collect();
        // The destinations (the scene's TLASes), the instance buffer and the disjoint, aligned
        // scratch slices live as long as the scene, which outlives every submission recording
        // this pass (callers wait on it).
        rec.build_acceleration_structures(&builds)?;
        rec.barrier();
        Ok(())
    }
}
