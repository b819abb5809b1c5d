//! Build steps: what a pass demanded, streamed and built most requested first, in groups that
//! halve when the budget refuses them.

use std::collections::BTreeSet;
use std::time::Instant;

use super::clones::Restored;
use super::residency::EvictWhy;
use super::skeleton::ms_since;
use super::StreamingRenderer;
use crate::error::{GpuError, Result};
use crate::scene::{upload_streamed_group, AccelStruct, MeshGpu};
use motu_vk::BudgetRefusal;

/// A pass's build step also builds the structures open behind its pixels' nearest ones
/// (`Demand::later`, with `StreamOptions::build_open_early`) only while at most one pixel in
/// this many is open. With most of the image open (a cold frame's first passes) most of them
/// are never hit, since the nearest structure holds the hit: island 0.63 at 24 GiB on an H100,
/// 10.9 of the 30.3 GB its first frame built were never hit, and building none early took the
/// frame from 8.1 to 5.5 s (4 → 7 passes; BENCHMARKS.md, session 48). With few pixels open
/// the next pass's TLAS rebuilds cost more than those builds, so they are built then.
const OPEN_EARLY_PIXEL_SHARE: u64 = 16;

/// One structure a build step may build: BLAS `blas`, and how many pixels' rays requested it
/// as their nearest open structure (0: open or seen, no ray's nearest), with
/// `REQUEST_CAMERA` (`params.rs`) set where one of them was a camera ray.
/// Plain data (`pub(super)` fields): no invariant ties the two, [`Demand`] keeps the order.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Request {
    pub(super) blas: u32,
    pub(super) requests: u32,
}

/// Work of one build step, most requested first. Its lists are private: a structure enters
/// through [`Demand::need`] or [`Demand::open`], and [`Demand::merge_first`] keeps each
/// structure once.
#[derive(Default)]
pub(super) struct Demand {
    /// Some pixel's nearest open structure: built first, at least one per step.
    needed: Vec<Request>,
    /// Open for some pixel but not its nearest: built when they fit, so later passes have
    /// less to do.
    later: Vec<Request>,
    /// The step builds only `needed` ([`Demand::defer_later_when_open`]); `later` still counts
    /// as seen.
    later_deferred: bool,
}

impl Demand {
    /// BLAS `blas` is needed, `requests` rays asking for it first (0: a candidate the frame
    /// saw, kept in the needed list's order).
    pub(super) fn need(&mut self, blas: u32, requests: u32) {
        self.needed.push(Request { blas, requests });
    }

    /// BLAS `blas` is open for some pixel but no ray's nearest: built when it fits.
    pub(super) fn open(&mut self, blas: u32) {
        self.later.push(Request { blas, requests: 0 });
    }

    /// The needed structures, in order.
    pub(super) fn needed(&self) -> &[Request] {
        &self.needed
    }

    /// How many needed structures some camera ray waits for (`REQUEST_CAMERA`).
    pub(super) fn needed_camera(&self) -> u32 {
        let camera = |r: &&Request| r.requests & super::params::REQUEST_CAMERA != 0;
        self.needed().iter().filter(camera).count() as u32
    }

    /// The structures built when they fit, in order.
    pub(super) fn later(&self) -> &[Request] {
        &self.later
    }

    /// This step builds none of [`Demand::later`] when more than one pixel in
    /// [`OPEN_EARLY_PIXEL_SHARE`] of the image's `pixels` is `open` (they stay seen, so they
    /// are not evicted first).
    pub(super) fn defer_later_when_open(&mut self, open: u64, pixels: u64) {
        self.later_deferred = open * OPEN_EARLY_PIXEL_SHARE > pixels;
    }

    pub(super) fn later_deferred(&self) -> bool {
        self.later_deferred
    }

    /// Every structure of the demand: the needed ones, then the later ones.
    pub(super) fn all(&self) -> impl Iterator<Item = &Request> {
        self.needed.iter().chain(&self.later)
    }

    pub(super) fn is_empty(&self) -> bool {
        self.needed.is_empty() && self.later.is_empty()
    }

    pub(super) fn len(&self) -> usize {
        self.needed.len() + self.later.len()
    }

    /// Puts `first`'s structures ahead of this demand's (a structure in both keeps
    /// `first`'s place): `first` must be sorted.
    pub(super) fn merge_first(&mut self, first: Demand) {
        let mut seen = std::collections::HashSet::new();
        let mut keep = |list: Vec<Request>| -> Vec<Request> {
            list.into_iter().filter(|r| seen.insert(r.blas)).collect()
        };
        self.needed = keep([first.needed, std::mem::take(&mut self.needed)].concat());
        self.later = keep([first.later, std::mem::take(&mut self.later)].concat());
    }

    /// The structures some ray would open first (requested at least once), in order.
    pub(super) fn needed_ids(&self) -> Vec<u32> {
        self.needed
            .iter()
            .filter(|r| r.requests > 0)
            .map(|r| r.blas)
            .collect()
    }

    /// What camera rays wait for first, then most requested first (ties: lower id first, so
    /// runs are deterministic). A pixel whose camera ray is open has its whole path still to
    /// trace (its secondary rays start only once that hit is final, and their misses take
    /// passes of their own), so its structures come before those that only shadow, AO and
    /// bounce rays wait for: on island 0.002 at ⅛ of the need (96×54, 6 frames) 6.4 → 6.0
    /// passes a frame after the first, at 1/16 16.4 → 15.6 (BENCHMARKS.md, session 47).
    pub(super) fn sort(&mut self) {
        for v in [&mut self.needed, &mut self.later] {
            v.sort_unstable_by_key(|r| (std::cmp::Reverse(r.requests), r.blas));
        }
    }
}

/// A BLAS a build group made resident: built now, or `restored` from a cached copy.
struct Admitted {
    blas: usize,
    accel: AccelStruct,
    restored: bool,
}

impl<'a> StreamingRenderer<'a> {
    /// Streams the meshes of BLASes `group` (each BLAS takes a reference on its meshes) and
    /// builds them, pinned, evicting for room when `evict`. On failure the group's references
    /// and the meshes only it held are released: nothing of it stays resident.
    pub(super) fn build_group(&mut self, group: &[u32], evict: bool) -> Result<()> {
        let mut taken: Vec<usize> = Vec::new();
        self.frame.stats_mut().build_groups += 1;
        // Cached entries read from the directory while the meshes load (`cache/reads.rs`).
        let ahead = self.read_cached_ahead(group);
        let t_mesh = Instant::now();
        // Allocated for the group, not resident yet: uploaded together (`upload_streamed_group`,
        // in parallel), then made resident one by one with their textures.
        let mut fresh: Vec<(usize, MeshGpu)> = Vec::new();
        let loaded = (|| -> Result<()> {
            let mut in_fresh = std::collections::HashSet::new();
            let (t_alloc, blocks) = (
                Instant::now(),
                self.heap.created_blocks(self.res.mesh_class()),
            );
            for &b in group {
                for m in self.blas_meshes(b as usize) {
                    // Referenced before loading: evicting a BLAS that shares it keeps it.
                    self.take_mesh_ref(m);
                    taken.push(m);
                    if self.res.mesh(m).is_some() || !in_fresh.insert(m) {
                        continue;
                    }
                    let rec = self.view.meshes[m];
                    let g = self.maybe_evicting(evict, |s| {
                        MeshGpu::alloc_streamed(&mut s.heap, m, &rec, s.res.mesh_class())
                    })?;
                    fresh.push((m, g));
                }
            }
            let ctx = self.ctx.clone();
            let source = self.source;
            let alloc = (
                ms_since(t_alloc),
                blocks,
                self.heap.created_blocks(self.res.mesh_class()),
            );
            let (sizes, split) = upload_streamed_group(&ctx, self.up_mut()?, source, &mut fresh)?;
            self.frame.stats_mut().note_mesh_upload(alloc, &split);
            let mut rest = std::mem::take(&mut fresh).into_iter();
            for bytes in sizes {
                let Some((m, g)) = rest.next() else { break };
                // Its material's textures come with it (a mesh is resident exactly while it
                // holds its texture references).
                let texture_bytes = match self.acquire_mesh_textures(m, evict) {
                    Ok(n) => n,
                    Err(e) => {
                        // Queued copies into them must land before they are destroyed.
                        let _ = self.up_mut()?.flush(&ctx);
                        self.heap.free(g.buffer);
                        fresh.extend(rest);
                        return Err(e);
                    }
                };
                let st = self.frame.stats_mut();
                st.bytes_streamed += bytes + texture_bytes;
                st.built_bytes += bytes + texture_bytes;
                self.res.loaded_mesh(m, g);
            }
            self.up_mut()?.flush(&ctx)
        })();
        if loaded.is_err() {
            // Copies still queued for the group's meshes must land before any is freed.
            let ctx = self.ctx.clone();
            if let Some(up) = self.up.as_mut() {
                up.flush(&ctx)?;
            }
        }
        // Allocated but not resident (an error before they were loaded): nothing refers to
        // them once the queued copies landed.
        for (_, g) in fresh.drain(..) {
            self.heap.free(g.buffer);
        }
        self.frame.stats_mut().mesh_ms += t_mesh.elapsed().as_secs_f64() * 1e3;
        let t_blas = Instant::now();
        let built = loaded.and_then(|()| {
            let ids: Vec<usize> = group.iter().map(|&b| b as usize).collect();
            let Restored {
                built: restored,
                rest,
            } = self.restore_cached(&ids, evict, ahead)?;
            let built = match self.maybe_evicting(evict, |s| {
                // Each successful batch is a sample of the store rule's build cost.
                let t = Instant::now();
                let built = s.build_blas_set(&rest, 0)?;
                let bytes = built.iter().map(|(_, a)| a.size_bytes).sum();
                s.reuse.note_builds(built.len(), bytes, ms_since(t));
                Ok(built)
            }) {
                Ok(b) => b,
                Err(e) => {
                    for (_, a) in restored {
                        a.release(&mut self.heap);
                    }
                    return Err(e);
                }
            };
            if let Err(e) = self.store_built(&built) {
                for (_, a) in restored.into_iter().chain(built) {
                    a.release(&mut self.heap);
                }
                return Err(e);
            }
            let admitted = |restored: bool| {
                move |(blas, accel): (usize, AccelStruct)| Admitted {
                    blas,
                    accel,
                    restored,
                }
            };
            Ok(built
                .into_iter()
                .map(admitted(false))
                .chain(restored.into_iter().map(admitted(true)))
                .collect::<Vec<_>>())
        });
        self.frame.stats_mut().blas_ms += t_blas.elapsed().as_secs_f64() * 1e3;
        if matches!(built, Err(GpuError::Budget(_))) {
            self.frame.stats_mut().refused_groups += 1;
        }
        let built = match built {
            Ok(b) => b,
            Err(e) => {
                for m in taken {
                    self.drop_mesh_ref(m);
                }
                return Err(e);
            }
        };
        self.admit_group(group, built);
        Ok(())
    }

    /// Makes `built` (of BLASes `group`, their meshes referenced) resident and pinned, counted
    /// in the frame's statistics; the BLASes of `group` with nothing built let their meshes go.
    fn admit_group(&mut self, group: &[u32], built: Vec<Admitted>) {
        let mut built_ids = BTreeSet::new();
        for Admitted {
            blas: b,
            accel,
            restored,
        } in built
        {
            let mesh_bytes: u64 = self
                .blas_meshes(b)
                .into_iter()
                .map(|m| {
                    self.res
                        .mesh(m)
                        .map_or(0, |g| self.res.mesh_budget_bytes(g))
                })
                .sum();
            let bytes = accel.size_bytes + mesh_bytes;
            let rebuilt = self.reuse.mark_built(b);
            let triangles = u64::from(self.view.blases[b].primitive_count);
            let st = self.frame.stats_mut();
            if restored {
                st.restored_blases += 1;
                st.restored_bytes += accel.size_bytes;
            } else {
                if rebuilt {
                    st.rebuilt_blases += 1;
                    st.rebuilt_bytes += accel.size_bytes;
                }
                st.blas_built += 1;
                st.built_bytes += accel.size_bytes;
                st.blas_structure_bytes += accel.size_bytes;
                st.triangles_built += triangles;
            }
            let (stamp, frame) = (self.frame.stamp(), self.frame.number());
            let (evicted_in, by_prefetch) = self.res.last_eviction(b);
            let prefetching = self.frame.prefetching();
            let st = self.frame.stats_mut();
            if evicted_in == frame {
                tracing::trace!(
                    blas = b,
                    by_prefetch,
                    prefetching,
                    "returned within the frame"
                );
                st.returned_in_frame += 1;
                st.returned_in_frame_bytes += bytes;
            } else if evicted_in + 1 == frame && by_prefetch && !prefetching {
                st.returned_after_prefetch += 1;
            }
            self.res.admit_built(b, accel, bytes, stamp, frame);
            built_ids.insert(b as u32);
            // Added, not removed: its parents may stay stale (`piece_order.rs`).
            self.stale_parents(b);
        }
        // A BLAS with nothing to build keeps no references.
        for &b in group {
            if !built_ids.contains(&b) {
                self.release_blas_meshes(b as usize);
            }
        }
    }

    /// Builds the BLASes of `queue` (priority order) in groups that halve when the budget
    /// refuses them. `evict_groups`: groups evict unpinned structures for room (the room a
    /// group needs by estimate is made once, up front, so a group is rarely refused after its
    /// meshes were streamed); otherwise groups are cut to the free budget by estimate and
    /// only single BLASes evict. Stops at the first single BLAS that does not fit (left for a
    /// later pass) and returns how many were left. `must_progress`: when nothing was built
    /// yet, evict the current pass's pins too before giving up, then fail with the numbers.
    /// A flying frame (`flying.rs`) evicts nothing: it stops where the free room ends.
    pub(super) fn build_blas_queue(
        &mut self,
        queue: &[u32],
        must_progress: bool,
        evict_groups: bool,
    ) -> Result<usize> {
        let flying = self.flying();
        let evict_groups = evict_groups && !flying;
        let mut i = 0;
        // Group size carries over between steps: a full budget keeps failing large groups,
        // and each failure streams their meshes for nothing.
        let mut chunk = self.res.group_hint().clamp(1, 64);
        let mut relaxed = false;
        // Room for the TLAS rebuilds of this step, kept free while building: a step that
        // fills the budget with BLASes would give them back one by one to fit the rebuild
        // (each attempt re-encodes every resident instance record).
        let mut counts = self.resident_instance_counts();
        while i < queue.len() {
            // The frame's build budget: spent stops the step (a frame that has built nothing
            // yet and must progress still builds one).
            if self.frame_build_spent() && (self.frame.stats().blas_built > 0 || !must_progress) {
                self.frame.stats_mut().build_budget_spent = true;
                return Ok(queue.len() - i);
            }
            let t_group = Instant::now();
            let mut n = self.group_within_frame_budget(&queue[i..], chunk, must_progress);
            if n == 0 {
                // The frame's clock has no time left for the next BLAS.
                self.frame.stats_mut().build_budget_spent = true;
                return Ok(queue.len() - i);
            }
            let reserve = self.tlas_reserve(&counts, &queue[i..i + n])?;
            // Kept TLAS records count as free: they yield to structures (`tlas_compact.rs`).
            let free =
                (self.free_budget_bytes() + self.tlases.records().bytes()).saturating_sub(reserve);
            if !evict_groups {
                // Free memory only: a group the budget cannot hold would stream its meshes for
                // nothing.
                let mut est = 0u64;
                let mut k = 0;
                for &b in &queue[i..i + n] {
                    est += self.blas_estimate_bytes(b);
                    if k > 0 && est > free {
                        break;
                    }
                    k += 1;
                }
                n = k.max(1);
            }
            let group = &queue[i..i + n];
            let evict = !flying && (evict_groups || group.len() == 1);
            let need: u64 = group.iter().map(|&b| self.blas_estimate_bytes(b)).sum();
            if flying && need > free {
                // One BLAS (a longer group was cut to fit), over the free room by estimate:
                // streaming its meshes would only be refused.
                return Ok(self.flying_no_room(group[0], queue.len() - i));
            }
            // The group's room next to the TLAS reserve: kept TLAS records yield first (where
            // nothing is evicted, only when that makes the room).
            let short = need.saturating_sub(self.free_budget_bytes().saturating_sub(reserve));
            if evict || short <= self.tlases.records().bytes() {
                self.release_kept_records_for_room(short);
            }
            if evict {
                // The room the whole group needs, made before its meshes stream (a BLAS's
                // bytes count meshes other BLASes may still hold, so an eviction may free
                // less than it counted: repeat while it helps).
                let mut short = need.saturating_sub(free);
                while short > 0 && self.evict_some(short, EvictWhy::BuildRoom)? {
                    short = need.saturating_sub(self.free_budget_bytes().saturating_sub(reserve));
                }
            }
            if !self.res.built_now().is_empty()
                && need > self.free_budget_bytes().saturating_sub(reserve)
            {
                // Built next to the step's builds, it would squeeze out the TLAS rebuild:
                // smaller, or in a later pass.
                if group.len() > 1 {
                    chunk = group.len() / 2;
                    self.res.set_group_hint(chunk);
                    continue;
                }
                tracing::debug!(
                    blas = group[0],
                    need,
                    free = self.free_budget_bytes(),
                    reserve,
                    left = queue.len() - i,
                    "build queue stops: no room next to the step's builds and the TLAS reserve"
                );
                if flying {
                    return Ok(self.flying_no_room(group[0], queue.len() - i));
                }
                return Ok(queue.len() - i);
            }
            match self.build_group(group, evict) {
                Ok(()) => {
                    self.note_build_time(group, t_group);
                    for &b in group {
                        if self.res.has_blas(b as usize) {
                            self.topo.add_instance_counts(b, &mut counts);
                        }
                    }
                    i += group.len();
                    chunk = (chunk * 2).min(64);
                    self.res.set_group_hint(chunk);
                }
                Err(GpuError::Budget(_)) if group.len() > 1 => {
                    chunk = group.len() / 2;
                    self.res.set_group_hint(chunk);
                }
                Err(GpuError::Budget(_)) if flying => {
                    return Ok(self.flying_no_room(group[0], queue.len() - i));
                }
                Err(GpuError::Budget(msg)) => {
                    if !self.res.built_now().is_empty() || !must_progress {
                        tracing::debug!(
                            blas = queue[i],
                            left = queue.len() - i,
                            %msg,
                            "build queue stops: refused"
                        );
                        return Ok(queue.len() - i);
                    }
                    if !relaxed {
                        // Nothing fits next to what the incomplete pixels hold: let those go
                        // (their pixels find them again later) rather than fail.
                        relaxed = true;
                        self.res.unpin_pass_pins();
                        continue;
                    }
                    if self.drop_persistent() {
                        // The floor is sized for rebuilt TLASes: without the persistent ones
                        // it fits (their rebuild comes at the end of this step).
                        continue;
                    }
                    return Err(self.does_not_fit(queue[i], msg));
                }
                Err(e) => return Err(e),
            }
        }
        Ok(0)
    }

    /// Bytes the TLAS rebuilds of the running step take by estimate (see
    /// `tlas_rebuild_bytes`) with `counts` resident instance records per TLAS plus those of
    /// `group`: every TLAS dirty now or parent of a BLAS of `group` or built this step.
    pub(super) fn tlas_reserve(&self, counts: &[u64], group: &[u32]) -> Result<u64> {
        let mut touched: BTreeSet<u32> = self.tlases.dirty().clone();
        for &b in group.iter().chain(self.res.built_now()) {
            touched.extend(self.topo.parents(b as usize).iter().copied());
        }
        let mut with_group = counts.to_vec();
        for &b in group {
            self.topo.add_instance_counts(b, &mut with_group);
        }
        let mut reserve = 0u64;
        for t in touched {
            reserve += self.tlas_rebuild_bytes(t, with_group[t as usize])?;
        }
        Ok(reserve)
    }

    /// Budget bytes not sub-allocated now (optimistic: a dedicated allocation needs them in
    /// one piece; a refusal is retried).
    pub(super) fn free_budget_bytes(&self) -> u64 {
        let r = self.heap.report();
        r.budget_bytes.saturating_sub(r.budget_in_use_bytes)
    }

    /// What building BLAS `b` takes from the budget by estimate: its meshes not resident yet
    /// where they count against it (geometry and shading attributes: 32 bytes a vertex, 16 a
    /// triangle) plus ~128 bytes a triangle for the structure and its scratch.
    pub(super) fn blas_estimate_bytes(&self, b: u32) -> u64 {
        let tris = u64::from(self.view.blases[b as usize].primitive_count);
        let meshes = if self.res.meshes_budgeted() {
            self.missing_mesh_bytes(b, 32, 16)
        } else {
            0
        };
        meshes + 128 * tris
    }

    /// Bytes of BLAS `b`'s meshes that are not resident yet, at `per_vertex` and
    /// `per_triangle` bytes (callers count geometry alone or geometry with attributes).
    pub(super) fn missing_mesh_bytes(&self, b: u32, per_vertex: u64, per_triangle: u64) -> u64 {
        self.blas_meshes(b as usize)
            .into_iter()
            .filter(|&m| self.res.mesh(m).is_none())
            .map(|m| {
                let r = &self.view.meshes[m];
                u64::from(r.vertex_count) * per_vertex + u64::from(r.triangle_count) * per_triangle
            })
            .sum()
    }

    /// The error for BLAS `b` not fitting next to the skeleton alone.
    pub(super) fn does_not_fit(&self, b: u32, refusal: BudgetRefusal) -> GpuError {
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
        let meshes = if self.res.meshes_budgeted() {
            format!("{mesh_bytes} bytes of meshes plus its")
        } else {
            format!("its {mesh_bytes} bytes of meshes in host memory aside,")
        };
        GpuError::Budget(refusal.explained(format!(
            "streaming: BLAS {b} ({} triangles, {meshes} \
             acceleration structure and build scratch) does not fit under the budget of {} \
             bytes even with every other structure evicted: {} bytes stay in use (resident \
             skeleton {} bytes, frame buffers, trace pipeline, staging ring); raise \
             --vram-budget or split the scene's meshes finer",
            rec.primitive_count,
            report.budget_bytes,
            report.budget_in_use_bytes,
            self.totals.skeleton_bytes,
        )))
    }

    /// Makes `demand` resident (streams meshes, builds BLASes), needed first and most requested
    /// first, evicting least-recently-visible structures under the budget; then rebuilds every
    /// dirty TLAS and uploads the tables. Pins: only what this step built (carried hits mean
    /// no pixel needs anything else kept). `prefetch`: only structures this frame did not see
    /// may be evicted, and what does not fit is skipped.
    pub(super) fn make_resident(&mut self, demand: &Demand, prefetch: bool) -> Result<()> {
        let t0 = Instant::now();
        self.frame.kept_mut().start_step(t0);
        let seen_since = prefetch.then(|| self.prefetch_pins_from());
        self.res.start_step(self.item_count(), seen_since);
        for r in demand.all() {
            self.res.seen_at(r.blas as usize, self.frame.stamp());
        }
        let queue = |v: &[Request]| -> Vec<u32> {
            v.iter()
                .map(|r| r.blas)
                .filter(|&b| !self.res.has_blas(b as usize) && self.topo.buildable(b as usize))
                .collect()
        };
        let (needed, later) = (queue(demand.needed()), queue(demand.later()));
        tracing::trace!(?needed, ?later, prefetch, "build step queues");
        let deferred = self.build_blas_queue(&needed, !prefetch, !prefetch)?;
        if deferred == 0
            && !later.is_empty()
            && self.opts.build_open_early
            && !demand.later_deferred()
        {
            // What fits of the rest, without giving up anything built above.
            self.build_blas_queue(&later, false, false)?;
        }
        // Parents whose instance set changed (builds or evictions); with a frame build budget
        // in milliseconds, stale ones only while it holds (`piece_order.rs`).
        self.rebuild_step()?;
        // A pass's step took the frame's last build decision so far; a prefetch's is no tail.
        self.frame
            .kept_mut()
            .clock_mut()
            .decided((!prefetch).then(Instant::now));
        let t_tables = Instant::now();
        self.upload_tlas_addresses()?;
        self.frame.stats_mut().tables_ms += t_tables.elapsed().as_secs_f64() * 1e3;
        self.frame.stats_mut().build_steps += 1;
        if prefetch {
            let built = self.res.built_now().len() as u32;
            self.frame.stats_mut().prefetched += built;
            let wanted = (needed.len() + later.len()) as u32;
            self.frame.stats_mut().prefetch_skipped += wanted.saturating_sub(built);
        } else {
            self.frame.stats_mut().deferred += deferred as u32;
        }
        self.frame.kept_mut().end_step();
        self.frame.stats_mut().build_ms += t0.elapsed().as_secs_f64() * 1e3;
        tracing::debug!(
            demanded = demand.len(),
            built = self.res.built_now().len(),
            deferred,
            prefetch,
            "build step"
        );
        Ok(())
    }
}

#[cfg(test)]
mod tests;
