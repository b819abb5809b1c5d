//! Build steps: what a pass demanded, streamed and built most requested first, in groups that
//! halve when the budget refuses them.

use std::collections::BTreeSet;
use std::time::Instant;

use motu_alloc::ItemId;

use super::StreamingRenderer;
use crate::error::{GpuError, Result};
use crate::scene::MeshGpu;

/// Work of one build step: (BLAS, requests) pairs, most requested first.
#[derive(Default)]
pub(super) struct Demand {
    /// Some pixel's nearest open structure: built first, at least one per step.
    pub(super) blases: Vec<(u32, u32)>,
    /// Open for some pixel but not its nearest: built when they fit, so later passes have
    /// less to do.
    pub(super) later: Vec<(u32, u32)>,
}

impl Demand {
    pub(super) fn is_empty(&self) -> bool {
        self.blases.is_empty() && self.later.is_empty()
    }

    pub(super) fn len(&self) -> usize {
        self.blases.len() + self.later.len()
    }

    /// Most requested first (ties: lower id first, so runs are deterministic).
    pub(super) fn sort(&mut self) {
        for v in [&mut self.blases, &mut self.later] {
            v.sort_unstable_by_key(|&(id, n)| (std::cmp::Reverse(n), id));
        }
    }
}

impl<'a> StreamingRenderer<'a> {
    /// Streams the meshes of BLASes `group` (each BLAS takes a reference on its meshes) and
    /// builds them, pinned, evicting for room when `evict`. On failure the group's references
    /// and the meshes only it held are released: nothing of it stays resident.
    pub(super) fn build_group(&mut self, group: &[u32], evict: bool) -> Result<()> {
        let mut taken: Vec<usize> = Vec::new();
        let loaded = (|| -> Result<()> {
            for &b in group {
                for m in self.blas_meshes(b as usize) {
                    // Referenced before loading: evicting a BLAS that shares it keeps it.
                    self.mesh_refs[m] += 1;
                    taken.push(m);
                    if self.meshes[m].is_some() {
                        continue;
                    }
                    let rec = self.view.meshes[m];
                    let mut g = self
                        .maybe_evicting(evict, |s| MeshGpu::alloc_streamed(&mut s.heap, m, &rec))?;
                    let ctx = self.ctx.clone();
                    let source = self.source;
                    let up = self.up_mut()?;
                    let bytes = match g.upload_streamed(&ctx, up, source, m) {
                        Ok(n) => n,
                        Err(e) => {
                            // Queued copies into it must land before it is destroyed.
                            let _ = up.flush(&ctx);
                            self.heap.free(g.buffer);
                            return Err(e);
                        }
                    };
                    // Its material's textures come with it (a mesh is resident exactly
                    // while it holds its texture references).
                    let texture_bytes = match self.acquire_mesh_textures(m, evict) {
                        Ok(n) => n,
                        Err(e) => {
                            let ctx = self.ctx.clone();
                            let _ = self.up_mut()?.flush(&ctx);
                            self.heap.free(g.buffer);
                            return Err(e);
                        }
                    };
                    self.frame_stats.bytes_streamed += bytes + texture_bytes;
                    self.frame_stats.built_bytes += bytes + texture_bytes;
                    self.meshes[m] = Some(g);
                }
            }
            let ctx = self.ctx.clone();
            self.up_mut()?.flush(&ctx)
        })();
        if loaded.is_err() {
            // Copies still queued for the group's meshes must land before any is freed.
            let ctx = self.ctx.clone();
            if let Some(up) = self.up.as_mut() {
                up.flush(&ctx)?;
            }
        }
        let built = loaded.and_then(|()| {
            let ids: Vec<usize> = group.iter().map(|&b| b as usize).collect();
            self.maybe_evicting(evict, |s| s.build_blas_set(&ids, 0))
        });
        let built = match built {
            Ok(b) => b,
            Err(e) => {
                for m in taken {
                    self.mesh_refs[m] = self.mesh_refs[m].saturating_sub(1);
                    if self.mesh_refs[m] == 0 {
                        if let Some(g) = self.meshes[m].take() {
                            self.heap.free(g.buffer);
                            self.release_mesh_textures(m);
                        }
                    }
                }
                return Err(e);
            }
        };
        let mut built_ids = BTreeSet::new();
        for (b, accel) in built {
            let mesh_bytes: u64 = self
                .blas_meshes(b)
                .into_iter()
                .map(|m| self.meshes[m].as_ref().map_or(0, |g| g.size_bytes()))
                .sum();
            let bytes = accel.size_bytes + mesh_bytes;
            self.frame_stats.blas_built += 1;
            self.frame_stats.built_bytes += accel.size_bytes;
            self.frame_stats.triangles_built += u64::from(self.view.blases[b].primitive_count);
            self.blas[b] = Some(accel);
            let _ = self
                .residency
                .insert(ItemId(b as u32), bytes, u64::from(self.stamp));
            self.pinned[b] = true;
            self.built_now.push(b as u32);
            built_ids.insert(b as u32);
            for &p in &self.parents[b] {
                if self.tlas[p as usize].is_some() {
                    self.dirty.insert(p);
                }
            }
        }
        // A BLAS with nothing to build keeps no references.
        for &b in group {
            if !built_ids.contains(&b) {
                self.release_blas_meshes(b as usize);
            }
        }
        Ok(())
    }

    /// Builds the BLASes of `queue` (priority order) in groups that halve when the budget
    /// refuses them; groups use free memory only, single BLASes evict for room (so eviction
    /// frees about what one build needs). Stops at the first single BLAS that does not fit
    /// (left for a later pass) and returns how many were left. `must_progress`: when nothing
    /// was built yet, evict the current pass's pins too before giving up, then fail with the
    /// numbers.
    pub(super) fn build_blas_queue(&mut self, queue: &[u32], must_progress: bool) -> Result<usize> {
        let mut i = 0;
        // Group size carries over between steps: a full budget keeps failing large groups,
        // and each failure streams their meshes for nothing.
        let mut chunk = self.group_hint.clamp(1, 64);
        let mut relaxed = false;
        while i < queue.len() {
            // The frame's build budget: spent stops the step (a frame that has built nothing
            // yet and must progress still builds one).
            if self.frame_build_spent() && (self.frame_stats.blas_built > 0 || !must_progress) {
                self.frame_stats.build_budget_spent = true;
                return Ok(queue.len() - i);
            }
            let n = self.group_within_frame_budget(&queue[i..], chunk);
            let group = &queue[i..i + n];
            match self.build_group(group, group.len() == 1) {
                Ok(()) => {
                    i += group.len();
                    chunk = (chunk * 2).min(64);
                    self.group_hint = chunk;
                }
                Err(GpuError::Budget(_)) if group.len() > 1 => {
                    chunk = group.len() / 2;
                    self.group_hint = chunk;
                }
                Err(GpuError::Budget(msg)) => {
                    if !self.built_now.is_empty() || !must_progress {
                        return Ok(queue.len() - i);
                    }
                    if !relaxed {
                        // Nothing fits next to what the incomplete pixels hold: let those go
                        // (their pixels find them again later) rather than fail.
                        relaxed = true;
                        self.unpin_pass_pins();
                        continue;
                    }
                    return Err(self.does_not_fit(queue[i], &msg));
                }
                Err(e) => return Err(e),
            }
        }
        Ok(0)
    }

    /// The error for BLAS `b` not fitting next to the skeleton alone.
    pub(super) fn does_not_fit(&self, b: u32, msg: &str) -> GpuError {
        let rec = &self.view.blases[b as usize];
        let mesh_bytes: u64 = self
            .blas_meshes(b as usize)
            .into_iter()
            .map(|m| {
                let r = &self.view.meshes[m];
                u64::from(r.vertex_count) * 12 + u64::from(r.triangle_count) * 12
            })
            .sum();
        let report = self.heap.report();
        GpuError::Budget(format!(
            "streaming: BLAS {b} ({} triangles, {mesh_bytes} bytes of meshes plus its \
             acceleration structure and build scratch) does not fit under the budget of {} \
             bytes even with every other structure evicted: {} bytes stay in use (resident \
             skeleton {} bytes, frame buffers, trace pipeline, staging ring); raise \
             --vram-budget or split the scene's meshes finer ({msg})",
            rec.primitive_count,
            report.budget_bytes,
            report.budget_in_use_bytes,
            self.totals.skeleton_bytes,
        ))
    }

    /// Makes `demand` resident (streams meshes, builds BLASes), needed first and most requested
    /// first, evicting least-recently-visible structures under the budget; then rebuilds every
    /// dirty TLAS and uploads the tables. Pins: only what this step built (carried hits mean
    /// no pixel needs anything else kept). `prefetch`: only structures this frame did not see
    /// may be evicted, and what does not fit is skipped.
    pub(super) fn make_resident(&mut self, demand: &Demand, prefetch: bool) -> Result<()> {
        let t0 = Instant::now();
        self.kept.step_start = Some(t0);
        self.pinned = if prefetch {
            let first = self.frame_first_stamp();
            (0..self.item_count())
                .map(|i| self.last_seen[i] >= first)
                .collect()
        } else {
            vec![false; self.item_count()]
        };
        self.built_now.clear();
        for &(b, _) in demand.blases.iter().chain(&demand.later) {
            self.last_seen[b as usize] = self.stamp;
        }
        let queue = |v: &[(u32, u32)]| -> Vec<u32> {
            v.iter()
                .map(|&(b, _)| b)
                .filter(|&b| self.blas[b as usize].is_none() && self.buildable[b as usize])
                .collect()
        };
        let (needed, later) = (queue(&demand.blases), queue(&demand.later));
        let deferred = self.build_blas_queue(&needed, !prefetch)?;
        if deferred == 0 && !later.is_empty() && self.opts.build_open_early {
            // What fits of the rest, without giving up anything built above.
            self.build_blas_queue(&later, false)?;
        }
        // Parents whose instance set changed (builds or evictions).
        self.rebuild_dirty()?;
        self.upload_tlas_addresses()?;
        if prefetch {
            self.frame_stats.prefetched += self.built_now.len() as u32;
        } else {
            self.frame_stats.deferred += deferred as u32;
        }
        self.kept.step_start = None;
        self.frame_stats.build_ms += t0.elapsed().as_secs_f64() * 1e3;
        tracing::debug!(
            demanded = demand.len(),
            built = self.built_now.len(),
            deferred,
            prefetch,
            "build step"
        );
        Ok(())
    }
}
