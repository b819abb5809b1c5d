//! Acceleration-structure builds: triangle and PI BLAS sets, and rebuilding the TLASes whose
//! instance set changed, in groups that fit (the build itself: `tlas_build.rs`).

use motu_alloc::{AllocKind, BuildSize, MemoryClass};
use motu_vk::{AsLevel, BufferUsage, FitRequest, ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT};

use super::residency::EvictWhy;
use super::tlas_records::RECORD_BYTES;
use super::StreamingRenderer;
use crate::error::{GpuError, Result};
use crate::scene::{blas_geometry, build_batched, AccelStruct, ResourceReport};

impl<'a> StreamingRenderer<'a> {
    /// Builds the BLASes `ids` of the original hierarchy (meshes must be resident; `aabb_base`
    /// for PI BLASes) in batches. On failure nothing is left allocated.
    pub(super) fn build_blas_set(
        &mut self,
        ids: &[usize],
        aabb_base: u64,
    ) -> Result<Vec<(usize, AccelStruct)>> {
        let mut descs = Vec::with_capacity(ids.len());
        let mut sizes = Vec::with_capacity(ids.len());
        let mut order = Vec::with_capacity(ids.len());
        for &b in ids {
            let meshes = self.res.meshes();
            let Some((g, c, shape)) =
                blas_geometry(&self.view, b, |m| meshes[m].as_ref(), aabb_base)?
            else {
                continue;
            };
            let sz = self
                .ctx
                .blas_build_sizes(&shape, self.build_opts.blas_build.flags())?;
            sizes.push(BuildSize {
                result_bytes: sz.acceleration_structure_size_bytes,
                scratch_bytes: sz.build_scratch_size_bytes,
            });
            descs.push((g, c));
            order.push(b);
        }
        let mut report = ResourceReport::default();
        let built = build_batched(
            &self.ctx,
            &mut self.heap,
            &mut report,
            &sizes,
            AsLevel::Bottom,
            &self.build_opts,
            |k| (descs[k].0.clone(), descs[k].1.clone()),
            |_, _| Ok(()),
            &mut |_| {},
        )?;
        Ok(built.into_iter().map(|(k, a)| (order[k], a)).collect())
    }

    /// Per TLAS `ids[k]` of a rebuild: its records (the resident BLASes' instance records plus
    /// `tails[k]`, the records after its own: its proxy and marks, each present when it has a
    /// box) and its build sizes, estimated from what is resident now.
    pub(super) fn tlas_estimates(
        &self,
        ids: &[u32],
        tails: &[u64],
    ) -> Result<Vec<(u64, BuildSize)>> {
        let counts = self.resident_instance_counts();
        let mut est = Vec::with_capacity(ids.len());
        for (&t, &tail) in ids.iter().zip(tails) {
            let n = (counts[t as usize] + tail).max(1);
            let s = self.ctx.tlas_build_sizes(
                u32::try_from(n).unwrap_or(u32::MAX),
                self.rebuild_opts().tlas_flags(),
            )?;
            est.push((
                n,
                BuildSize {
                    result_bytes: s.acceleration_structure_size_bytes,
                    scratch_bytes: s.build_scratch_size_bytes,
                },
            ));
        }
        Ok(est)
    }

    /// Fails fast with the budget's refusal when rebuilding TLASes of estimates `est`
    /// ([`Self::tlas_estimates`]) cannot fit now:
    /// asks the allocator whether what every attempt holds at once fits (the instance buffer,
    /// the largest TLAS's build scratch and the largest structure not `held`: a subset of the
    /// real peak, so a refusal here is one the build would meet). `held[k]`: TLAS `k`'s new
    /// structure reuses its old one's storage, which the heap holds already
    /// (`tlas_build/storage.rs`). A refused attempt is retried after evicting
    /// (`with_eviction`, `rebuild_dirty`'s give-back rounds) and used to refuse only after
    /// encoding, uploading every resident instance record and building the proxies: at ⅛ of
    /// the 0.3 island (2.8M resident records per rebuild) 46 TLAS builds for 14 rebuilds,
    /// two thirds of the frame's 13.4 s of TLAS time. Asked, not allocated: allocating and
    /// freeing those buffers (dedicated blocks of up to a gigabyte) took 36–116 ms a rebuild
    /// on the H200, 6% of a frame at a quarter of island 0.3 (BENCHMARKS.md, session 18).
    pub(super) fn probe_tlas_room(
        &mut self,
        est: &[(u64, BuildSize)],
        held: &[bool],
    ) -> Result<()> {
        let records: u64 = est.iter().map(|e| e.0).sum();
        let largest = |skip_held: bool| {
            est.iter()
                .zip(held)
                .filter(|(_, &h)| !(skip_held && h))
                .map(|(e, _)| e.1)
                .max_by_key(|s| s.result_bytes)
        };
        let scratch_bytes = largest(false).map_or(0, |s| s.scratch_bytes);
        let scratch_align = self.ctx.limits().scratch_alignment_bytes();
        let mut asks = vec![
            FitRequest {
                label: "stream-tlas-probe-instances",
                size_bytes: (records * RECORD_BYTES as u64).max(64),
                usage: BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
                kind: AllocKind::InstanceBuffer,
                class: MemoryClass::DeviceLocal,
                alignment: 16,
            },
            FitRequest {
                label: "stream-tlas-probe-scratch",
                size_bytes: scratch_bytes.max(scratch_align),
                usage: BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
                kind: AllocKind::Scratch,
                class: MemoryClass::DeviceLocal,
                alignment: scratch_align,
            },
        ];
        if let Some(s) = largest(true) {
            asks.push(FitRequest {
                label: "stream-tlas-probe",
                size_bytes: s.result_bytes.max(256),
                usage: BufferUsage::ACCELERATION_STRUCTURE_STORAGE,
                kind: AllocKind::TlasStorage,
                class: MemoryClass::DeviceLocal,
                alignment: ACCELERATION_STRUCTURE_OFFSET_ALIGNMENT,
            });
        }
        Ok(self.heap.try_fit(&asks)?)
    }

    /// Rebuilds every dirty TLAS, in groups ([`Self::next_rebuild_group`]). When the budget
    /// refuses even with everything unpinned evicted, gives back structures this step built,
    /// least requested first (their pixels stay incomplete); fails only when none is left.
    /// Meanwhile evictions (for a group's room or on a refused build) spare clean TLASes
    /// (`victims_sparing_clean_tlases`): a group's room does not dirty a group rebuilt before.
    pub(super) fn rebuild_dirty(&mut self) -> Result<()> {
        self.rebuild_timed(|s| s.rebuild_while(|s| s.next_rebuild_group(|_| true)))
    }

    /// Runs TLAS rebuilds `f` timed (`tlas_ms`), as rebuilds (evictions spare clean TLASes).
    pub(super) fn rebuild_timed(&mut self, f: impl FnOnce(&mut Self) -> Result<()>) -> Result<()> {
        let t0 = std::time::Instant::now();
        self.res.set_rebuilding(true);
        let r = f(self);
        self.res.set_rebuilding(false);
        let saved = self.tlases.compact_saved_bytes();
        let st = self.frame.stats_mut();
        st.tlas_ms += t0.elapsed().as_secs_f64() * 1e3;
        st.tlas_compact_resident_saved_bytes = st.tlas_compact_resident_saved_bytes.max(saved);
        r
    }

    /// Per TLAS: instance records of resident BLASes now (what its rebuild holds).
    pub(super) fn resident_instance_counts(&self) -> Vec<u64> {
        let mut counts = vec![0u64; self.view.tlases.len()];
        for (b, a) in self.res.blases().iter().enumerate() {
            if a.is_some() {
                self.topo.add_instance_counts(b as u32, &mut counts);
            }
        }
        counts
    }

    /// Bytes rebuilding TLAS `t` with `count` resident instance records takes beyond what its
    /// current build holds (instance buffer, structure, scratch; the proxy, its boxes and the
    /// fragmentation of blocks by a quarter more); 0 for a persistent TLAS.
    pub(super) fn tlas_rebuild_bytes(&self, t: u32, count: u64) -> Result<u64> {
        if self.tlases.is_persistent(t) {
            // Updated in place with its kept scratch: only its proxy and marks are rebuilt.
            return Ok(0);
        }
        let count = count + 2;
        let s = self.ctx.tlas_build_sizes(
            u32::try_from(count).unwrap_or(u32::MAX),
            self.rebuild_opts().tlas_flags(),
        )?;
        let need = count * RECORD_BYTES as u64
            + s.acceleration_structure_size_bytes
            + s.build_scratch_size_bytes;
        let old = self.tlases.get(t).map_or(0, |g| g.accel().size_bytes);
        Ok((need + need / 4).saturating_sub(old))
    }

    /// Rebuilds the groups `next` names (with the room each needs) until it names none.
    pub(super) fn rebuild_while(
        &mut self,
        mut next: impl FnMut(&mut Self) -> Result<Option<(Vec<u32>, u64)>>,
    ) -> Result<()> {
        // Each group's rebuild settles (or fails) on its own; evictions for one group may
        // dirty TLASes another group rebuilt, which the next round picks up.
        let mut rounds = 0usize;
        while let Some((group, need)) = next(self)? {
            rounds += 1;
            if rounds > 64 + 4 * (self.view.tlases.len() + self.item_count()) {
                return Err(GpuError::InvalidRequest(
                    "streaming: TLAS rebuilds do not settle".into(),
                ));
            }
            self.rebuild_group(&group, need)?;
            self.frame.stats_mut().tlas_rebuild_groups += 1;
        }
        Ok(())
    }

    /// The dirty TLASes to rebuild together next: the one whose rebuild needs the most room,
    /// then the next largest while the group's rebuilds together need no more than that one
    /// or a 64th of the budget. A TLAS split into pieces (when the streamer loads the
    /// package, `--stream-split-instances`, or at import, `--max-instances`) is thus rebuilt
    /// piece by piece, each piece's instance buffer, scratch and new structure released or
    /// kept before the next: the room a rebuild takes from resident BLASes is one piece's, not
    /// the whole root's (at a quarter of island 0.3 split into 1M-instance pieces: 0.25 GB
    /// against 1.9 GB rebuilt at once, 2.6 passes and 1.2 s a frame against 3.5 passes and
    /// 4.5 s; BENCHMARKS.md, session 21). Small TLASes still share one batch (one submission,
    /// one instance buffer).
    /// Of the dirty TLASes only those `which` takes; `None` when it takes none.
    /// Returns the group and the room its rebuilds need together.
    pub(super) fn next_rebuild_group(
        &self,
        which: impl Fn(u32) -> bool,
    ) -> Result<Option<(Vec<u32>, u64)>> {
        let counts = self.resident_instance_counts();
        let mut need: Vec<(u64, u32)> = Vec::with_capacity(self.tlases.dirty().len());
        for &t in self.tlases.dirty().iter().filter(|&&t| which(t)) {
            need.push((self.tlas_rebuild_bytes(t, counts[t as usize])?, t));
        }
        if need.is_empty() {
            return Ok(None);
        }
        Ok(Some(group_by_need(need, self.build_opts.budget_bytes)))
    }

    /// Rebuilds the TLASes of `group` that are dirty (see [`Self::rebuild_dirty`]); `need`: the
    /// room their rebuilds take ([`Self::next_rebuild_group`], all of them dirty when chosen).
    pub(super) fn rebuild_group(&mut self, group: &[u32], need: u64) -> Result<()> {
        let target = |s: &Self| -> Vec<u32> {
            group
                .iter()
                .copied()
                .filter(|t| s.tlases.dirty().contains(t))
                .collect()
        };
        if !target(self).is_empty() {
            // Room made once up front: each refused attempt re-encodes and re-uploads every
            // resident instance record of the dirty TLASes.
            // TLASes, their scratch and instance buffers are large (dedicated blocks): count
            // only budget no block holds as free, and evict a quarter more for fragmentation.
            let free = |s: &Self| {
                let r = s.heap.report();
                r.budget_bytes.saturating_sub(r.budget_block_bytes)
            };
            // A few rounds at most: evicted items free whole blocks only when they empty
            // them, so this could otherwise evict everything unpinned.
            let mut short = need.saturating_sub(free(self));
            if short > 0 {
                // Kept TLAS records yield first (`tlas_compact.rs`).
                self.release_kept_records_for_room(short);
                short = need.saturating_sub(free(self));
            }
            if short > 0 && self.opts.defrag {
                // Whole blocks freed by moving what sparse ones hold, before evicting.
                self.defragment(short)?;
                short = need.saturating_sub(free(self));
            }
            // What the rebuild needs against what blocks leave free (`MOTU_LOG`), the numbers
            // behind `evicted_for_tlas`.
            tracing::debug!(
                need,
                free = free(self),
                dirty = self.tlases.dirty().len(),
                group = group.len(),
                records = self.resident_instance_counts().iter().sum::<u64>(),
                "TLAS rebuild room"
            );
            let mut rounds = 0;
            while short > 0 && rounds < 4 && self.evict_some(short, EvictWhy::TlasRoom)? {
                short = need.saturating_sub(free(self));
                rounds += 1;
            }
        }
        let mut rounds = 0;
        while !target(self).is_empty() {
            rounds += 1;
            if rounds > 64 + self.item_count() {
                return Err(GpuError::InvalidRequest(
                    "streaming: TLAS rebuilds do not settle".into(),
                ));
            }
            let ids: Vec<u32> = target(self);
            let rebuilt = ids.len() as u32;
            match self.with_eviction(|s| {
                // Eviction may have given some up (a child TLAS): rebuild what is still dirty.
                let now: Vec<u32> = target(s);
                s.build_tlases(&now)
            }) {
                Ok(()) => self.frame.stats_mut().tlas_rebuilt += rebuilt,
                Err(GpuError::Budget(_))
                    if self.unpins_before_giving_back() && self.res.unpin_pass_pins() => {}
                Err(GpuError::Budget(msg)) => {
                    // Give back about a 32nd of the budget of this step's builds per round
                    // (least requested first): one at a time would re-encode every instance
                    // record once per structure.
                    let step = (self.build_opts.budget_bytes / 32).max(1);
                    let mut given = 0u64;
                    while given < step && self.res.built_now().len() > 1 {
                        let b = self.res.pop_built_now().unwrap_or_default();
                        given += self.res.blas_bytes(b as usize);
                        self.frame.stats_mut().deferred += 1;
                        if self.res.holds(b) {
                            self.keep_evicted(&[b as usize])?;
                            self.evict(b as usize);
                            self.frame.stats_mut().evicted -= 1;
                        }
                    }
                    let Some(last) = self.res.pop_built_now() else {
                        let report = self.heap.report();
                        return Err(GpuError::Budget(msg.explained(format!(
                            "streaming: rebuilding {} TLAS(es) does not fit under the budget of \
                             {} bytes with every evictable structure evicted ({} bytes in use, \
                             skeleton {} bytes); raise --vram-budget",
                            ids.len(),
                            report.budget_bytes,
                            report.budget_in_use_bytes,
                            self.totals.skeleton_bytes
                        ))));
                    };
                    self.frame.stats_mut().deferred += 1;
                    if self.res.holds(last) {
                        self.keep_evicted(&[last as usize])?;
                        self.evict(last as usize);
                        // Given back, not evicted for room: count it as deferred only.
                        self.frame.stats_mut().evicted -= 1;
                    }
                }
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }
}

impl<'a> StreamingRenderer<'a> {
    /// Whether a refused TLAS rebuild drops the step's pins before it gives back what the step
    /// built. In a frame's passes the pins are the open pixels' best hits, found again later.
    /// In the prefetch after a frame they are what the probe of the next camera met, which
    /// that frame's first pass needs: dropped, the rebuild evicted them (least recently seen
    /// first among them) and kept the prefetch's own latest builds, the least requested. So
    /// the prefetch gives those back first and unpins only when it has none left. Lavapipe,
    /// island 0.002 at a quarter of its full build along the default path (64×36, 8 frames,
    /// the bounce, no host tier): the prefetches of frames 1–3 each evicted 4 structures the
    /// probe had met resident, camera-ray hits the next frame's first pass built again
    /// (`evicted_probe_met_in_prefetch` 12 → 0); frames after the first rebuilt 214 → 198,
    /// built 200 → 183 MB, 2.857 → 2.714 passes after the first; a third of it, and island
    /// 0.005 at a quarter and a third, unchanged within a structure or two a frame
    /// (`tests/tests/stream_prefetch_churn.rs`).
    fn unpins_before_giving_back(&self) -> bool {
        !self.frame.prefetching() || self.res.built_now().is_empty()
    }
}

/// Of dirty TLASes given as (room its rebuild needs, TLAS), those to rebuild together: the
/// largest, then the next largest while the sum stays within that one's need or a 64th of
/// `budget_bytes` (see `next_rebuild_group`); with the group's need summed.
pub(super) fn group_by_need(mut need: Vec<(u64, u32)>, budget_bytes: u64) -> (Vec<u32>, u64) {
    // Largest first, ties by index (a stable order across runs).
    need.sort_by_key(|&(n, t)| (std::cmp::Reverse(n), t));
    let cap = need.first().map_or(0, |&(n, _)| n.max(budget_bytes / 64));
    let mut sum = 0u64;
    let mut group = Vec::new();
    for (n, t) in need {
        if group.is_empty() || sum + n <= cap {
            sum += n;
            group.push(t);
        }
    }
    (group, sum)
}

#[cfg(test)]
mod tests;
