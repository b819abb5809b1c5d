//! A frame's measures: its working set (split by the kinds of ray that hit it) and what is
//! resident against the room (`FrameStreamStats`).

use crate::stream::room_split::{RoomHolders, RoomSplit};
use crate::stream::StreamingRenderer;

impl<'a> StreamingRenderer<'a> {
    /// The working set of the frame's rays (before the prefetch builds for the next).
    pub(super) fn measure_working_set(&mut self) {
        use crate::stream::params::{HIT_BOUNCE, HIT_CAMERA, HIT_GUARD, HIT_OCCLUSION};
        let mut working_meshes = std::collections::BTreeSet::new();
        for (b, &f) in self.res.used_in_frame().iter().enumerate() {
            if f == self.frame.number() {
                let bytes = self.res.blas_bytes(b);
                let kinds = u32::from(self.res.hit_kinds()[b]);
                let st = &mut self.frame.stats;
                st.working_set_blases += 1;
                st.working_set_bytes += bytes;
                let of = |kind: u32| if kinds & kind != 0 { bytes } else { 0 };
                st.working_set_camera_bytes += of(HIT_CAMERA);
                st.working_set_occlusion_bytes += of(HIT_OCCLUSION);
                st.working_set_bounce_bytes += of(HIT_BOUNCE);
                if kinds != 0 && kinds & (HIT_CAMERA | HIT_GUARD) == 0 {
                    st.working_set_secondary_only_bytes += bytes;
                }
                if kinds == 0 {
                    st.working_set_unhit_bytes += bytes;
                }
                working_meshes.extend(self.blas_meshes(b));
            }
        }
        // Of working_set_bytes: what the meshes take from the budget (0 in host memory).
        self.frame.stats.working_set_mesh_bytes = working_meshes
            .into_iter()
            .filter_map(|m| self.res.mesh(m).map(|g| self.res.mesh_budget_bytes(g)))
            .sum();
    }

    /// BLASes this frame's rays saw that are no longer resident (evicted by a later pass).
    pub(super) fn seen_evicted_in_frame(&self) -> usize {
        let frame = self.frame.number();
        (self.res.used_in_frame().iter().zip(self.res.blases()))
            .filter(|(&f, a)| f == frame && a.is_none())
            .count()
    }

    /// The frame's residency statistics, from the allocator's `report` now. Resident bytes
    /// are split once: streamed BLASes and their meshes (what the room is for) beside the
    /// skeleton's BLASes and TLASes.
    pub(super) fn measure_residency(&mut self, report: &motu_alloc::AllocReport) {
        let resident_textures = self.shading.resident_textures();
        let room_bytes = self.room_bytes(report);
        let room_split = self.room_split();
        let st = &mut self.frame.stats;
        st.resident_textures = resident_textures;
        let (mut streamed_blases, mut streamed_bytes, mut skeleton_bytes) = (0u32, 0u64, 0u64);
        for (a, &buildable) in self.res.blases().iter().zip(self.topo.buildable_all()) {
            if let Some(a) = a {
                if buildable {
                    streamed_blases += 1;
                    streamed_bytes += a.size_bytes;
                } else {
                    skeleton_bytes += a.size_bytes;
                }
            }
        }
        for g in self.res.meshes().iter().flatten() {
            if self.res.meshes_budgeted() {
                streamed_bytes += g.size_bytes();
            } else {
                st.resident_host_mesh_bytes += g.size_bytes();
            }
        }
        let host_counts = self.heap.host_visible_counts_against_budget();
        skeleton_bytes += self.tlases.size_bytes(host_counts);
        st.resident_blases = streamed_blases;
        st.resident_tlases = self.tlases.resident().count() as u32;
        st.resident_bytes = streamed_bytes + skeleton_bytes;
        st.vram_peak_bytes = report.peak_block_bytes;
        st.vram_budget_bytes = report.budget_bytes;
        st.heap_block_bytes = report.budget_block_bytes;
        st.heap_in_use_bytes = report.budget_in_use_bytes;
        st.room_bytes = room_bytes;
        st.room_split = room_split;
    }

    /// `budget − room_bytes` by what holds it, from the heap's per-kind use now.
    fn room_split(&self) -> RoomSplit {
        let (streamed_blas_bytes, budgeted_mesh_bytes) = self.streamed_parts();
        let records = self.tlases.records();
        let holders = RoomHolders {
            streamed_blas_bytes,
            budgeted_mesh_bytes,
            kept_record_bytes: records.record_bytes(),
            kept_table_bytes: records.bytes() - records.record_bytes(),
            proxy_blas_bytes: self.tlases.proxy_bytes(),
            instance_table_bytes: (self.gpu)
                .instance_table_budget_bytes(self.heap.host_visible_counts_against_budget()),
        };
        RoomSplit::of(self.heap.budget_in_use_by_kind(), &holders)
    }

    /// Budget bytes resident streamed BLASes and their budgeted meshes hold now.
    fn streamed_bytes(&self) -> u64 {
        let (blases, meshes) = self.streamed_parts();
        blases + meshes
    }

    /// [`Self::streamed_bytes`]'s two parts: BLASes, meshes.
    fn streamed_parts(&self) -> (u64, u64) {
        let blases: u64 = (self.res.blases().iter().zip(self.topo.buildable_all()))
            .filter_map(|(a, &buildable)| a.as_ref().filter(|_| buildable))
            .map(|a| a.size_bytes)
            .sum();
        let meshes: u64 = if self.res.meshes_budgeted() {
            self.res
                .meshes()
                .iter()
                .flatten()
                .map(|g| g.size_bytes())
                .sum()
        } else {
            0
        };
        (blases, meshes)
    }

    /// The budget less what stays in use beside streamed BLASes and their meshes, by the
    /// allocator's `report` now (`FrameStreamStats::room_bytes`).
    pub(in crate::stream) fn room_bytes(&self, report: &motu_alloc::AllocReport) -> u64 {
        // Kept TLAS records are not fixed: they yield to structures (`tlas_compact.rs`).
        let fixed_bytes = report
            .budget_in_use_bytes
            .saturating_sub(self.streamed_bytes() + self.tlases.records().bytes());
        report.budget_bytes.saturating_sub(fixed_bytes)
    }
}
