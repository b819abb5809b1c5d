//! Residency: LRU eviction under the budget, pins, mesh reference counts, and quarantine of
//! TLASes left inconsistent by a failed build step.

use motu_abi::BLAS_TRIANGLES;
use motu_alloc::ItemId;

use super::StreamingRenderer;
use crate::error::{GpuError, Result};
use crate::scene::MeshGpu;

/// Why structures are evicted (`FrameStreamStats` counts each).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum EvictWhy {
    /// Room a BLAS build group needs by estimate, made before its meshes stream.
    BuildRoom,
    /// Room a TLAS rebuild needs outside blocks, made up front.
    TlasRoom,
    /// The budget refused an allocation.
    Refused,
}

impl<'a> StreamingRenderer<'a> {
    /// Bytes mesh `g` takes from the budget: 0 where streamed meshes live outside it (host
    /// memory of a discrete GPU, [`super::MeshMemory`]).
    pub(super) fn mesh_budget_bytes(&self, g: &MeshGpu) -> u64 {
        if self.meshes_budgeted {
            g.size_bytes()
        } else {
            0
        }
    }

    /// Evicts least-recently-visible unpinned structures (at least `bytes` of them, or all that
    /// are left). Returns false when nothing could be evicted.
    pub(super) fn evict_some(&mut self, bytes: u64, why: EvictWhy) -> Result<bool> {
        let t0 = std::time::Instant::now();
        let before = self.frame_stats.evicted;
        let r = self.evict_some_untimed(bytes);
        let n = self.frame_stats.evicted - before;
        match why {
            EvictWhy::BuildRoom => {}
            EvictWhy::TlasRoom => self.frame_stats.evicted_for_tlas += n,
            EvictWhy::Refused => self.frame_stats.evicted_on_refusal += n,
        }
        self.frame_stats.evict_ms += t0.elapsed().as_secs_f64() * 1e3;
        r
    }

    fn evict_some_untimed(&mut self, bytes: u64) -> Result<bool> {
        let pins = &self.pinned;
        let pinned = |id: ItemId| pins.get(id.0 as usize).copied().unwrap_or(true);
        let victims = match self
            .residency
            .choose_victims_excluding(bytes.max(1), pinned)
        {
            Ok(v) => v,
            Err(e) if e.evictable_bytes > 0 => self
                .residency
                .choose_victims_excluding(e.evictable_bytes, pinned)
                .unwrap_or_default(),
            Err(_) => Vec::new(),
        };
        if victims.is_empty() {
            return Ok(false);
        }
        tracing::trace!(
            victims = ?victims.iter().map(|v| (v.0, self.last_seen.get(v.0 as usize).copied().unwrap_or(0))).collect::<Vec<_>>(),
            stamp = self.stamp,
            first = self.frame_first_stamp,
            "evicting (BLAS, last seen)"
        );
        for id in victims {
            self.evict(id.0 as usize);
        }
        tracing::debug!(resident = self.residency.len(), "evicted");
        Ok(true)
    }

    /// Releases BLAS `b` with the meshes only it used; its resident parents become dirty.
    pub(super) fn evict(&mut self, b: usize) {
        let bytes = self.residency.remove(ItemId(b as u32)).unwrap_or(0);
        self.frame_stats.evicted += 1;
        self.evictions += 1;
        self.frame_stats.evicted_bytes += bytes;
        if let Some(a) = self.blas.get_mut(b).and_then(Option::take) {
            a.release(&mut self.heap);
        }
        self.release_blas_meshes(b);
        self.dirty_parents(b);
    }

    /// Marks BLAS `b`'s resident parent TLASes dirty: their instance records no longer match
    /// it (built, evicted or moved), so they are rebuilt before the next trace.
    pub(super) fn dirty_parents(&mut self, b: usize) {
        for &p in &self.parents[b] {
            if self.tlas[p as usize].is_some() {
                self.dirty.insert(p);
            }
        }
    }

    /// Drops BLAS `b`'s references to its meshes, freeing those no other BLAS holds.
    pub(super) fn release_blas_meshes(&mut self, b: usize) {
        for m in self.blas_meshes(b) {
            self.drop_mesh_ref(m);
        }
    }

    /// Drops one reference to mesh `m`; at zero the mesh and its texture references go.
    pub(super) fn drop_mesh_ref(&mut self, m: usize) {
        self.mesh_refs[m] = self.mesh_refs[m].saturating_sub(1);
        if self.mesh_refs[m] == 0 {
            if let Some(g) = self.meshes[m].take() {
                self.heap.free(g.buffer);
                self.release_mesh_textures(m);
            }
        }
    }

    pub(super) fn blas_meshes(&self, b: usize) -> Vec<usize> {
        let r = &self.view.blases[b];
        if r.kind != BLAS_TRIANGLES {
            return Vec::new();
        }
        self.view.geometries[r.item_base as usize..(r.item_base + r.item_count) as usize]
            .iter()
            .map(|g| g.mesh as usize)
            .collect()
    }

    /// Runs `f`, evicting unpinned structures and retrying while the budget refuses it;
    /// returns the budget error once nothing unpinned is left.
    pub(super) fn with_eviction<T>(
        &mut self,
        mut f: impl FnMut(&mut Self) -> Result<T>,
    ) -> Result<T> {
        loop {
            match f(self) {
                Err(GpuError::Budget(msg)) => {
                    // What refused (`MOTU_LOG`): the numbers behind `evicted_on_refusal`.
                    tracing::debug!(%msg, "refused; evicting");
                    let step = (self.build_opts.budget_bytes / 32).max(1);
                    // A refusal is for a new block: whole blocks drained first, if any.
                    if self.opts.defrag && self.defragment(step)?.freed_bytes > 0 {
                        continue;
                    }
                    if self.evict_some(step, EvictWhy::Refused)? {
                        continue;
                    }
                    return Err(GpuError::Budget(msg));
                }
                r => return r,
            }
        }
    }

    /// [`with_eviction`](Self::with_eviction) for what the floor counts as always resident
    /// (frame buffers, the trace pipeline): refused with everything evicted, persistent
    /// TLASes give way (the floor is sized for rebuilt ones) and `f` is tried once more.
    pub(super) fn with_eviction_or_rebuilt_tlases<T>(
        &mut self,
        mut f: impl FnMut(&mut Self) -> Result<T>,
    ) -> Result<T> {
        match self.with_eviction(&mut f) {
            Err(GpuError::Budget(_)) if self.drop_persistent() => self.with_eviction(f),
            r => r,
        }
    }

    /// [`with_eviction`](Self::with_eviction) when `evict`, else `f` once.
    pub(super) fn maybe_evicting<T>(
        &mut self,
        evict: bool,
        mut f: impl FnMut(&mut Self) -> Result<T>,
    ) -> Result<T> {
        if evict {
            self.with_eviction(f)
        } else {
            f(self)
        }
    }

    /// Drops the pins that are not this step's builds (the incomplete pixels' best hits: they
    /// are found again later). Returns false if there were none.
    pub(super) fn unpin_pass_pins(&mut self) -> bool {
        let mut keep = vec![false; self.pinned.len()];
        for &i in &self.built_now {
            if let Some(k) = keep.get_mut(i as usize) {
                *k = true;
            }
        }
        let changed = self.pinned.iter().zip(&keep).any(|(&p, &k)| p && !k);
        self.pinned = keep;
        changed
    }

    /// After a failed build step, a TLAS left dirty (absent, or referencing evicted BLASes)
    /// must never be traced: every TLAS is part of the skeleton, so the renderer is poisoned.
    pub(super) fn quarantine_after_failure(&mut self, e: &GpuError) {
        if !self.dirty.is_empty() {
            self.poisoned = Some(e.to_string());
        }
    }
}
