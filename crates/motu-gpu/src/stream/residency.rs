//! Residency: the part that says what of the streamed state is resident ([`Resident`]); LRU
//! eviction under the budget, pins, mesh reference counts, and quarantine of TLASes left
//! inconsistent by a failed build step.
//!
//! Invariants: a streamed BLAS is resident (its structure set) exactly when the LRU order
//! holds it, with its structure's and meshes' bytes ([`Resident::admit_built`] sets both,
//! `evict` clears both; [`Resident::take_blas`] takes a structure out only until
//! [`Resident::put_back_blas`], with no eviction between); a mesh's reference count is the
//! number of resident (or loading) BLASes that use it, and the mesh is resident only while it
//! is above 0; pinned items are never evicted in the current build step, and what the step
//! built stays pinned until the step ends or gives it back; the eviction count never
//! decreases. The fields are private: other parts of `stream/` go through the methods here.

use motu_abi::BLAS_TRIANGLES;
use motu_alloc::{ItemId, MemoryClass, Residency};

use super::StreamingRenderer;
use crate::error::{GpuError, Result};
use crate::scene::{AccelStruct, MeshGpu};

/// Frames of history a BLAS's use count covers (the bits of `Resident::met_mask`).
const MET_FRAMES: u32 = 16;

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

/// The residency part: the streamed BLASes and meshes resident now, and what chooses what
/// goes (the LRU order by last sighting, the pins of a build step, the sizes and working set).
///
/// Its invariants are the module docs'.
pub(super) struct Resident {
    /// Per BLAS (streamed and skeleton alike): its structure when resident.
    blas: Vec<Option<AccelStruct>>,
    /// Per mesh: its geometry when resident, and how many resident BLASes use it.
    meshes: Vec<Option<MeshGpu>>,
    mesh_refs: Vec<u32>,
    /// The memory streamed meshes are allocated in ([`StreamOptions::mesh_memory`] resolved)
    /// and whether it counts against the budget.
    ///
    /// [`StreamOptions::mesh_memory`]: super::StreamOptions::mesh_memory
    mesh_class: MemoryClass,
    meshes_budgeted: bool,
    /// The streamed BLASes resident, with their bytes, in LRU order.
    residency: Residency,
    /// Per item (BLAS, then TLAS): the last pass stamp that saw it.
    last_seen: Vec<u32>,
    /// Per BLAS: bytes it held when last resident (structure plus meshes), and the last frame
    /// whose rays used it (walked while resident and seen, or built for them): the frame's
    /// working set.
    blas_bytes: Vec<u64>,
    used_in_frame: Vec<u64>,
    /// Per BLAS, the frames among the last [`MET_FRAMES`] it was used in: bit k for frame
    /// `used_in_frame - k`. Victims go least often used first ([`Resident::frames_met`]).
    met_mask: Vec<u16>,
    /// Per BLAS, the kinds of ray (`HIT_*` of `params.rs`) whose closest hit it held in the
    /// frame `used_in_frame` names (0: built for its rays, hit by none).
    hit_kinds: Vec<u8>,
    /// Pins of the current build step (items that must not be evicted): what the latest
    /// pass's incomplete pixels need (or, when prefetching, everything this frame saw), plus
    /// what the step built.
    pinned: Vec<bool>,
    /// Items the current build step made resident, in build (priority) order.
    built_now: Vec<u32>,
    /// BLASes per build group to try first (see `build_blas_queue`).
    group_hint: usize,
    /// BLASes evicted since the renderer started (also those given back; never decremented):
    /// whether a prefetch removed anything since a probe.
    evictions: u64,
    /// Per BLAS: the frame that last evicted it (0: never) and whether that frame's prefetch
    /// did (`returned_in_frame`, `returned_after_prefetch`).
    evicted_in: Vec<u64>,
    evicted_by_prefetch: Vec<bool>,
    /// Set while the dirty TLASes are rebuilt (`rebuild_dirty`): evictions then spare clean
    /// TLASes ([`StreamingRenderer::victims_sparing_clean_tlases`]).
    rebuilding: bool,
}

impl Resident {
    /// Makes streamed BLAS `b`, just built (or restored) for frame `frame`, resident: its
    /// structure, and its bytes (structure and meshes) in the LRU order, seen at pass stamp
    /// `stamp`; it is pinned and counted as the step's build.
    pub fn admit_built(
        &mut self,
        b: usize,
        accel: AccelStruct,
        bytes: u64,
        stamp: u32,
        frame: u64,
    ) {
        self.blas_bytes[b] = bytes;
        self.used_in(b, frame, 0);
        self.blas[b] = Some(accel);
        let _ = self
            .residency
            .insert(ItemId(b as u32), bytes, u64::from(stamp));
        self.pinned[b] = true;
        self.built_now.push(b as u32);
    }

    /// Puts skeleton BLAS `b` (never evicted: not in the LRU order) in place.
    pub fn place_skeleton_blas(&mut self, b: usize, accel: AccelStruct) {
        self.blas[b] = Some(accel);
    }

    /// Takes BLAS `b`'s structure out to read it (serialising it into the cache); it must come
    /// back with [`put_back_blas`](Self::put_back_blas) before anything is evicted or built.
    pub fn take_blas(&mut self, b: usize) -> Option<AccelStruct> {
        self.blas.get_mut(b).and_then(Option::take)
    }

    /// Puts back a structure [`take_blas`](Self::take_blas) took out.
    pub fn put_back_blas(&mut self, b: usize, accel: AccelStruct) {
        self.blas[b] = Some(accel);
    }

    /// Puts `accel` (a copy of resident BLAS `b` in other memory: defragmentation) in the
    /// place of its structure and returns the old one, for the caller to release.
    pub fn moved_blas(&mut self, b: usize, accel: AccelStruct) -> Option<AccelStruct> {
        self.blas[b].replace(accel)
    }

    /// Mesh `m`'s geometry, just loaded for a BLAS that holds a reference to it.
    pub fn loaded_mesh(&mut self, m: usize, g: MeshGpu) {
        debug_assert!(self.mesh_refs[m] > 0, "mesh {m} loaded with no reference");
        self.meshes[m] = Some(g);
    }

    /// Mesh `m`'s geometry to move (defragmentation), when resident.
    pub fn mesh_to_move(&mut self, m: usize) -> Option<&mut MeshGpu> {
        self.meshes.get_mut(m).and_then(Option::as_mut)
    }

    /// Resident streamed BLAS `b` was seen at `stamp` (it moves up the LRU order).
    pub fn saw(&mut self, b: usize, stamp: u32) {
        self.residency
            .mark_visible(ItemId(b as u32), u64::from(stamp));
    }

    /// Item `i` (BLAS, then TLAS) was seen by the pass of stamp `stamp`.
    pub fn seen_at(&mut self, i: usize, stamp: u32) {
        self.last_seen[i] = stamp;
    }

    /// Item `i` was seen at `stamp` or later (a probe's stamps are older than the frame's).
    pub fn seen_by(&mut self, i: usize, stamp: u32) {
        self.last_seen[i] = self.last_seen[i].max(stamp);
    }

    /// Resident BLAS `b`'s structure was walked by the rays of frame `frame`, and held the
    /// closest hit of rays of the kinds `hit_kinds` (`HIT_*`).
    pub fn used_in(&mut self, b: usize, frame: u64, hit_kinds: u32) {
        if self.used_in_frame[b] != frame {
            self.hit_kinds[b] = 0;
            let shift = frame.saturating_sub(self.used_in_frame[b]);
            self.met_mask[b] = if shift >= u64::from(MET_FRAMES) {
                0
            } else {
                self.met_mask[b] << shift
            };
        }
        self.met_mask[b] |= 1;
        self.used_in_frame[b] = frame;
        self.hit_kinds[b] |= hit_kinds as u8;
    }

    /// In how many of the [`MET_FRAMES`] frames up to `frame` BLAS `b` was used (walked while
    /// resident, or built for the frame's rays).
    pub fn frames_met(&self, b: usize, frame: u64) -> u32 {
        let age = frame.saturating_sub(self.used_in_frame[b]);
        if age >= u64::from(MET_FRAMES) {
            return 0;
        }
        ((u32::from(self.met_mask[b]) << age) & 0xffff).count_ones()
    }

    /// Per BLAS, the kinds of ray whose closest hit it held in its `used_in_frame`.
    pub fn hit_kinds(&self) -> &[u8] {
        &self.hit_kinds
    }

    /// Per BLAS, the last frame whose rays used it.
    pub fn used_in_frame(&self) -> &[u64] {
        &self.used_in_frame
    }

    /// Bytes BLAS `b` held when last resident (structure plus meshes).
    pub fn blas_bytes(&self, b: usize) -> u64 {
        self.blas_bytes[b]
    }

    /// Starts a build step over `items` items: pinned are those seen at `seen_since` or later
    /// (a prefetch keeps what the frame saw) or none; nothing is built yet.
    pub fn start_step(&mut self, items: usize, seen_since: Option<u32>) {
        self.pinned = match seen_since {
            Some(first) => (0..items).map(|i| self.last_seen[i] >= first).collect(),
            None => vec![false; items],
        };
        self.built_now.clear();
    }

    /// Drops every pin of `items` items (what the step built stays counted as built).
    pub fn unpin_all(&mut self, items: usize) {
        self.pinned = vec![false; items];
    }

    /// The dirty TLASes are being rebuilt (`on`) or are no longer.
    pub fn set_rebuilding(&mut self, on: bool) {
        self.rebuilding = on;
    }

    /// Forgets what the current step built (a rebuild outside any build step).
    pub fn forget_built_now(&mut self) {
        self.built_now.clear();
    }

    /// Drops the pins that are not this step's builds (the incomplete pixels' best hits: they
    /// are found again later). Returns false if there were none.
    pub fn unpin_pass_pins(&mut self) -> bool {
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

    /// Bytes mesh `g` takes from the budget: 0 where streamed meshes live outside it (host
    /// memory of a discrete GPU, [`super::MeshMemory`]).
    pub fn mesh_budget_bytes(&self, g: &MeshGpu) -> u64 {
        if self.meshes_budgeted {
            g.size_bytes()
        } else {
            0
        }
    }

    /// Items the current build step made resident, in build (priority) order.
    pub fn built_now(&self) -> &[u32] {
        &self.built_now
    }

    /// The latest of the step's builds, no longer counted as the step's (it is given back).
    pub fn pop_built_now(&mut self) -> Option<u32> {
        self.built_now.pop()
    }

    /// BLASes per build group to try first; `set_group_hint` keeps the size that worked.
    pub fn group_hint(&self) -> usize {
        self.group_hint
    }

    pub fn set_group_hint(&mut self, blases: usize) {
        self.group_hint = blases;
    }

    /// BLAS `b`'s structure when resident (streamed or skeleton).
    pub fn blas(&self, b: usize) -> Option<&AccelStruct> {
        self.blas.get(b).and_then(Option::as_ref)
    }

    /// Whether BLAS `b` (streamed or skeleton) has its structure now.
    pub fn has_blas(&self, b: usize) -> bool {
        self.blas(b).is_some()
    }

    /// Per BLAS, its structure when resident.
    pub fn blases(&self) -> &[Option<AccelStruct>] {
        &self.blas
    }

    /// Mesh `m`'s geometry when resident.
    pub fn mesh(&self, m: usize) -> Option<&MeshGpu> {
        self.meshes.get(m).and_then(Option::as_ref)
    }

    /// Per mesh, its geometry when resident.
    pub fn meshes(&self) -> &[Option<MeshGpu>] {
        &self.meshes
    }

    /// Whether streamed meshes count against the budget.
    pub fn meshes_budgeted(&self) -> bool {
        self.meshes_budgeted
    }

    /// Whether streamed BLAS `b` is resident (and so evictable).
    pub fn holds(&self, b: u32) -> bool {
        self.residency.contains(ItemId(b))
    }

    /// The frame that last evicted BLAS `b` (0: never) and whether its prefetch did.
    pub fn last_eviction(&self, b: usize) -> (u64, bool) {
        (self.evicted_in[b], self.evicted_by_prefetch[b])
    }

    /// BLASes evicted since the renderer started (never decreases).
    pub fn evictions(&self) -> u64 {
        self.evictions
    }

    /// The memory streamed meshes are allocated in.
    pub fn mesh_class(&self) -> MemoryClass {
        self.mesh_class
    }

    /// Nothing resident of `blases` BLASes, `tlases` TLASes and `meshes` meshes; streamed
    /// meshes go to `mesh_class`.
    pub fn new(
        blases: usize,
        tlases: usize,
        meshes: usize,
        mesh_class: MemoryClass,
        meshes_budgeted: bool,
    ) -> Resident {
        Resident {
            blas: (0..blases).map(|_| None).collect(),
            meshes: (0..meshes).map(|_| None).collect(),
            mesh_refs: vec![0; meshes],
            mesh_class,
            meshes_budgeted,
            residency: Residency::new(),
            last_seen: vec![0; blases + tlases],
            blas_bytes: vec![0; blases],
            used_in_frame: vec![0; blases],
            met_mask: vec![0; blases],
            hit_kinds: vec![0; blases],
            pinned: vec![false; blases + tlases],
            built_now: Vec::new(),
            group_hint: 16,
            evictions: 0,
            evicted_in: vec![0; blases],
            evicted_by_prefetch: vec![false; blases],
            rebuilding: false,
        }
    }
}

impl<'a> StreamingRenderer<'a> {
    /// Evicts least-recently-visible unpinned structures (at least `bytes` of them, or all that
    /// are left). Returns false when nothing could be evicted.
    /// Kept TLAS records (`tlas_compact.rs`) go first: they yield to structures, so when
    /// they free `bytes` nothing is evicted.
    pub(super) fn evict_some(&mut self, bytes: u64, why: EvictWhy) -> Result<bool> {
        let released = self.release_kept_records_for_room(bytes.max(1));
        if released >= bytes.max(1) {
            return Ok(true);
        }
        let evicted = self.evict_structures(bytes - released, why)?;
        // The staging buffer of staged transfers yields last (`transfer.rs`).
        Ok(evicted || released > 0 || self.release_staging_for_room())
    }

    /// [`evict_some`](Self::evict_some) for structures alone.
    fn evict_structures(&mut self, bytes: u64, why: EvictWhy) -> Result<bool> {
        let t0 = std::time::Instant::now();
        let before = self.frame.stats().evicted;
        let r = self.evict_some_untimed(bytes, why);
        let n = self.frame.stats().evicted - before;
        match why {
            EvictWhy::BuildRoom => {}
            EvictWhy::TlasRoom => self.frame.stats_mut().evicted_for_tlas += n,
            EvictWhy::Refused => self.frame.stats_mut().evicted_on_refusal += n,
        }
        self.frame.stats_mut().evict_ms += t0.elapsed().as_secs_f64() * 1e3;
        r
    }

    fn evict_some_untimed(&mut self, bytes: u64, why: EvictWhy) -> Result<bool> {
        // Evictions while TLASes are rebuilt (for their room, or on a refused build) spare
        // clean TLASes; others go least recently seen first.
        let victims = if why == EvictWhy::TlasRoom || self.res.rebuilding {
            self.victims_sparing_clean_tlases(bytes.max(1))
        } else {
            self.lru_victims(bytes.max(1))
        };
        if victims.is_empty() {
            return Ok(false);
        }
        tracing::trace!(
            victims = ?victims.iter().map(|v| (v.0, self.res.last_seen.get(v.0 as usize).copied().unwrap_or(0))).collect::<Vec<_>>(),
            stamp = self.frame.stamp(),
            first = self.frame.first_stamp(),
            ?why,
            prefetching = self.frame.prefetching(),
            "evicting (BLAS, last seen)"
        );
        let ids: Vec<usize> = victims.iter().map(|v| v.0 as usize).collect();
        // Kept first (a host clone, `clones.rs`, or serialised, `cache.rs`), so a return is a
        // copy, not a build.
        self.keep_evicted(&ids)?;
        for b in ids {
            self.evict(b);
        }
        tracing::debug!(resident = self.res.residency.len(), "evicted");
        Ok(true)
    }

    /// Unpinned streamed BLASes until they hold `bytes` (all of them when they hold less):
    /// least recently seen first, or, with [`StreamOptions::victims_by_frequency`], used in the
    /// fewest of the last [`MET_FRAMES`] frames first, least recently seen first among equals.
    /// One-sample bounce rays meet a different part of the scene's fringe each frame: least
    /// recently seen alone evicts a BLAS met every second or third frame before it returns,
    /// while the room could hold the often met part of the fringe. Lavapipe, island 0.002
    /// along the default path, frames after the first (rebuilt plus restored; 1–3 runs):
    /// a third of the full build 443–481 → 239–293, 1/2.75 212–270 → 175–179, a quarter
    /// 462–494 → 394–426; island 0.01 at 1/2.75 unchanged (125 → 132). Opt-in: at an eighth
    /// (working set over the room) passes after the first went 30 → 31 and the merged probe
    /// rounds' TLAS rebuilds 215 → 233 (`tests/tests/stream.rs`); on an H100 at a quarter of
    /// island 0.3 frames were slower (1,147 against 1,068 ms; BENCHMARKS.md, session 48).
    ///
    /// [`StreamOptions::victims_by_frequency`]: super::StreamOptions::victims_by_frequency
    pub(super) fn lru_victims(&self, bytes: u64) -> Vec<ItemId> {
        let pins = &self.res.pinned;
        let pinned = |id: ItemId| pins.get(id.0 as usize).copied().unwrap_or(true);
        // Least recently seen first until `want` bytes (all that is evictable when less).
        let least_recent =
            |want: u64| match self.res.residency.choose_victims_excluding(want, pinned) {
                Ok(v) => v,
                Err(e) if e.evictable_bytes > 0 => self
                    .res
                    .residency
                    .choose_victims_excluding(e.evictable_bytes, pinned)
                    .unwrap_or_default(),
                Err(_) => Vec::new(),
            };
        if !self.opts.victims_by_frequency {
            return least_recent(bytes);
        }
        let mut order = least_recent(u64::MAX);
        // Stable: least recently seen first among equal counts.
        let frame = self.frame.number();
        order.sort_by_key(|id| self.res.frames_met(id.0 as usize, frame));
        let mut freed = 0u64;
        let n = order
            .iter()
            .take_while(|id| {
                let more = freed < bytes;
                freed += self.res.blas_bytes(id.0 as usize);
                more
            })
            .count();
        order.truncate(n);
        order
    }

    /// [`lru_victims`](Self::lru_victims) that dirty as few clean TLASes as they can: first the
    /// BLASes whose parent TLASes are all dirty already (or not resident), which the step
    /// rebuilds anyway, least recently seen first; when they hold too little, the one of the
    /// rest with the fewest clean parents (least recently seen first among equals), whose
    /// parents then count as dirty (so the BLASes under them come next), and so on. Evicting
    /// for a later rebuild group's room thus takes BLASes of TLASes still to rebuild rather
    /// than of TLASes this step already rebuilt (each of those was rebuilt again:
    /// `tlas_rebuilt_again`) or left clean; pins hold as for every eviction. Only TLASes split
    /// into pieces (or several TLASes) see a difference: under one TLAS every victim is free.
    /// Lavapipe, island 0.01 split into ~10 pieces (`--stream-split-instances 30000`), 64×36,
    /// 6 frames, frames after the first, 3 alternated runs: at ⅛ `tlas_rebuilt_again`
    /// 10–15 → 1, TLAS builds 335–341 → 319–327, passes 32 → 31, `returned_in_frame`
    /// 322–330 → 310–313; at ¼ 1 → 0 for one more pass in 5 frames (15 → 16, returned
    /// 89–92 → 96–97); at 1/16 unchanged (TLAS-room evictions 0–3; BENCHMARKS.md, session 42).
    fn victims_sparing_clean_tlases(&self, bytes: u64) -> Vec<ItemId> {
        let order = self.lru_victims(u64::MAX);
        let mut dirty: Vec<bool> = (0..self.view.tlases.len() as u32)
            .map(|t| self.tlases.dirty().contains(&t) || self.tlases.get(t).is_none())
            .collect();
        let mut taken = vec![false; order.len()];
        let mut victims = Vec::new();
        let mut freed = 0u64;
        loop {
            for (k, id) in order.iter().enumerate() {
                if freed >= bytes {
                    return victims;
                }
                let parents = self.topo.parents(id.0 as usize);
                if !taken[k] && parents.iter().all(|&p| dirty[p as usize]) {
                    taken[k] = true;
                    freed += self.res.blas_bytes(id.0 as usize);
                    victims.push(*id);
                }
            }
            if freed >= bytes {
                return victims;
            }
            // The one that dirties the fewest clean TLASes, least recently seen first among
            // equals. Each round dirties at least one more: at most one round per TLAS.
            let clean = |id: &ItemId| {
                let parents = self.topo.parents(id.0 as usize);
                parents.iter().filter(|&&p| !dirty[p as usize]).count()
            };
            let Some(k) = (0..order.len())
                .filter(|&k| !taken[k])
                .min_by_key(|&k| (clean(&order[k]), k))
            else {
                return victims;
            };
            for &p in self.topo.parents(order[k].0 as usize) {
                dirty[p as usize] = true;
            }
        }
    }

    /// Releases BLAS `b` with the meshes only it used; its resident parents become dirty.
    pub(super) fn evict(&mut self, b: usize) {
        let bytes = self.res.residency.remove(ItemId(b as u32)).unwrap_or(0);
        self.frame.stats_mut().evicted += 1;
        self.res.evictions += 1;
        self.res.evicted_in[b] = self.frame.number();
        self.res.evicted_by_prefetch[b] = self.frame.prefetching();
        if self.frame.prefetching() && self.frame.probe_met_resident(b) {
            self.frame.stats_mut().evicted_probe_met_in_prefetch += 1;
        }
        self.frame.stats_mut().evicted_bytes += bytes;
        if let Some(a) = self.res.blas.get_mut(b).and_then(Option::take) {
            a.release(&mut self.heap);
        }
        self.release_blas_meshes(b);
        self.dirty_parents(b);
    }

    /// Marks BLAS `b`'s resident parent TLASes dirty: their instance records no longer match
    /// it (built, evicted or moved), so they are rebuilt before the next trace.
    pub(super) fn dirty_parents(&mut self, b: usize) {
        for &p in self.topo.parents(b) {
            self.tlases.instances_changed(p);
        }
    }

    /// Drops BLAS `b`'s references to its meshes, freeing those no other BLAS holds.
    pub(super) fn release_blas_meshes(&mut self, b: usize) {
        for m in self.blas_meshes(b) {
            self.drop_mesh_ref(m);
        }
    }

    /// Takes a reference to mesh `m` for a BLAS about to use it (before loading it: evicting a
    /// BLAS that shares it then keeps it).
    pub(super) fn take_mesh_ref(&mut self, m: usize) {
        self.res.mesh_refs[m] += 1;
    }

    /// Drops one reference to mesh `m`; at zero the mesh and its texture references go.
    pub(super) fn drop_mesh_ref(&mut self, m: usize) {
        self.res.mesh_refs[m] = self.res.mesh_refs[m].saturating_sub(1);
        if self.res.mesh_refs[m] == 0 {
            if let Some(g) = self.res.meshes[m].take() {
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
    pub(super) fn with_eviction<T>(&mut self, f: impl FnMut(&mut Self) -> Result<T>) -> Result<T> {
        self.retry_refused(true, f)
    }

    /// Runs `f`, retrying while the budget refuses it after making room: kept TLAS records
    /// first (they yield to structures, `tlas_compact.rs`: a structure never gives way to
    /// them, nor is a block drained for them), then, when `evict`, drained blocks and evicted
    /// unpinned structures. Returns the budget error once nothing more gives way.
    fn retry_refused<T>(
        &mut self,
        evict: bool,
        mut f: impl FnMut(&mut Self) -> Result<T>,
    ) -> Result<T> {
        loop {
            match f(self) {
                Err(GpuError::Budget(msg)) => {
                    // What refused (`MOTU_LOG`): the numbers behind `evicted_on_refusal`.
                    tracing::debug!(%msg, evict, "refused; making room");
                    let step = (self.build_opts.budget_bytes / 32).max(1);
                    if self.release_kept_records_for_room(step) > 0 {
                        continue;
                    }
                    if !evict {
                        return Err(GpuError::Budget(msg));
                    }
                    // A refusal is for a new block: whole blocks drained first, if any (in
                    // the prefetch always, see `drains_on_refusal`).
                    if self.drains_on_refusal() && self.defragment(step)?.freed_bytes > 0 {
                        continue;
                    }
                    if self.evict_structures(step, EvictWhy::Refused)? {
                        continue;
                    }
                    return Err(GpuError::Budget(msg));
                }
                r => return r,
            }
        }
    }

    /// Whether a refused allocation drains blocks before it evicts: with
    /// `StreamOptions::defrag`, and in the prefetch after a frame always. There, evicting
    /// frees space inside blocks, scattered over all of them least recently seen first, and
    /// rarely a whole block, so the retry loop went on a 32nd of the budget at a time through
    /// structures the probe's later rounds then met and built again (`returned_in_frame`).
    /// Lavapipe, island 0.002 at a quarter of its full build along the default path (64×36, 8
    /// frames, the bounce, `--no-as-cache`), frames after the first, alternated runs (they
    /// vary run to run): evicted 417–498 → 303–304, returned within the frame 218–289 →
    /// 126–144, built 190–334 → 141–181 MB, passes after the first 2.29–2.86 → 2.29–2.43;
    /// the same image (`tests/tests/stream_prefetch_churn.rs`).
    fn drains_on_refusal(&self) -> bool {
        self.opts.defrag || self.frame.prefetching()
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

    /// [`with_eviction`](Self::with_eviction) when `evict`, else `f` in free room: nothing is
    /// evicted, but kept TLAS records, which count as free room (`tlas_compact.rs`), are
    /// released while the budget refuses.
    pub(super) fn maybe_evicting<T>(
        &mut self,
        evict: bool,
        f: impl FnMut(&mut Self) -> Result<T>,
    ) -> Result<T> {
        self.retry_refused(evict, f)
    }

    /// After a failed build step, a TLAS left dirty (absent, or referencing evicted BLASes)
    /// must never be traced: every TLAS is part of the skeleton, so the renderer is poisoned.
    pub(super) fn quarantine_after_failure(&mut self, e: &GpuError) {
        // A stale TLAS (frames with a build budget in ms) is safe to trace (`piece_order.rs`).
        if self.dirty_before_trace() {
            self.poisoned = Some(e.to_string());
        }
    }
}
