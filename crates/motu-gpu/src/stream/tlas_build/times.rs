//! A TLAS rebuild's phase times ([`PhaseTimes`]): the frame's `tlas_*_ms` and the debug line
//! "TLAS rebuild phases" (`MOTU_LOG=motu_gpu=debug`), with the host parts inside the phases
//! (allocations, frees, record counting, proxy uploads) apart.

use crate::scene::AccelStruct;

/// Milliseconds of each phase, for `--stats` (`tlas_*_ms` per frame) and the debug line at the
/// end (`MOTU_LOG`).
pub(super) struct PhaseTimes {
    pub(super) clock: std::time::Instant,
    /// Old structures out, the PI slots' flush and the new structures in.
    pub(super) swap_ms: f64,
    pub(super) probe_ms: f64,
    pub(super) proxy_host_ms: f64,
    pub(super) proxy_build_ms: f64,
    pub(super) update_ms: f64,
    pub(super) encode_ms: f64,
    pub(super) upload_ms: f64,
    pub(super) build_ms: f64,
    pub(super) records: u64,
    pub(super) proxy_boxes: u32,
    pub(super) proxies_built: u32,
    pub(super) proxies_kept: u32,
    /// Structures copied to their compacted size, and the bytes that saved.
    pub(super) compactions: u32,
    pub(super) compact_saved_bytes: u64,
    /// Host parts inside the phases above (the debug line only): buffer and structure
    /// allocations, frees, counting the records, queueing the proxies' boxes and PI records.
    pub(super) alloc_ms: f64,
    pub(super) free_ms: f64,
    pub(super) count_ms: f64,
    pub(super) proxy_upload_ms: f64,
    /// Rebuilt TLASes built into the storage of the structure they replace, and those given
    /// fresh storage (`storage.rs`).
    pub(super) storage_reused: u32,
    pub(super) storage_allocated: u32,
    /// Old structures the room probe released instead of reusing: the piece outgrew its
    /// storage (also `tlas_storage_grew` in the frame stats), or shrank by more than the slack
    /// (the debug line only).
    pub(super) storage_grew: u32,
    pub(super) storage_shrank: u32,
}

impl PhaseTimes {
    pub(super) fn new() -> Self {
        PhaseTimes {
            clock: std::time::Instant::now(),
            swap_ms: 0.0,
            probe_ms: 0.0,
            proxy_host_ms: 0.0,
            proxy_build_ms: 0.0,
            update_ms: 0.0,
            encode_ms: 0.0,
            upload_ms: 0.0,
            build_ms: 0.0,
            records: 0,
            proxy_boxes: 0,
            proxies_built: 0,
            proxies_kept: 0,
            compactions: 0,
            compact_saved_bytes: 0,
            alloc_ms: 0.0,
            free_ms: 0.0,
            count_ms: 0.0,
            proxy_upload_ms: 0.0,
            storage_reused: 0,
            storage_allocated: 0,
            storage_grew: 0,
            storage_shrank: 0,
        }
    }

    /// Structures of `built` (with the bytes compaction saved on each) that were compacted.
    pub(super) fn count_compactions(&mut self, built: &[(usize, AccelStruct, u64)]) {
        for &(_, _, saved) in built {
            self.compactions += u32::from(saved > 0);
            self.compact_saved_bytes += saved;
        }
    }

    /// `f()`, its milliseconds added to `*part` (a host part inside a phase).
    pub(super) fn timed<T>(part: &mut f64, f: impl FnOnce() -> T) -> T {
        let t0 = std::time::Instant::now();
        let v = f();
        *part += t0.elapsed().as_secs_f64() * 1e3;
        v
    }

    /// Milliseconds since the last lap.
    pub(super) fn lap(&mut self) -> f64 {
        let d = self.clock.elapsed().as_secs_f64() * 1e3;
        self.clock = std::time::Instant::now();
        d
    }

    /// The phases into the frame's stats and the debug line (a failed build's too: its time
    /// is part of `tlas_ms`).
    pub(super) fn record(mut self, st: &mut crate::stream::FrameStreamStats) {
        self.swap_ms += self.lap();
        st.tlas_gpu_ms += self.build_ms + self.update_ms;
        st.tlas_upload_ms += self.upload_ms;
        st.tlas_proxy_ms += self.proxy_host_ms + self.proxy_build_ms;
        st.tlas_swap_ms += self.swap_ms;
        st.tlas_room_ms += self.probe_ms;
        st.tlas_encode_ms += self.encode_ms;
        st.tlas_proxies_built += self.proxies_built;
        st.tlas_proxies_kept += self.proxies_kept;
        st.tlas_compactions += self.compactions;
        st.tlas_compact_saved_bytes += self.compact_saved_bytes;
        st.tlas_storage_reused += self.storage_reused;
        st.tlas_storage_allocated += self.storage_allocated;
        st.tlas_storage_grew += self.storage_grew;
        tracing::debug!(
            records = self.records,
            probe_ms = self.probe_ms,
            update_ms = self.update_ms,
            proxy_boxes = self.proxy_boxes,
            proxies_built = self.proxies_built,
            proxies_kept = self.proxies_kept,
            compactions = self.compactions,
            compact_saved_bytes = self.compact_saved_bytes,
            proxy_host_ms = self.proxy_host_ms,
            proxy_build_ms = self.proxy_build_ms,
            encode_ms = self.encode_ms,
            upload_ms = self.upload_ms,
            build_ms = self.build_ms,
            swap_ms = self.swap_ms,
            alloc_ms = self.alloc_ms,
            free_ms = self.free_ms,
            count_ms = self.count_ms,
            proxy_upload_ms = self.proxy_upload_ms,
            storage_reused = self.storage_reused,
            storage_allocated = self.storage_allocated,
            storage_grew = self.storage_grew,
            storage_shrank = self.storage_shrank,
            "TLAS rebuild phases"
        );
    }
}
