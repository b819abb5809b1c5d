//! The TLAS part ([`Tlases`]): every TLAS with its proxy and marks BLASes, which TLASes are
//! persistent (updated in place, `persistent.rs`) and their placeholders, and which are dirty.
//!
//! Invariants: after the start every TLAS is resident (TLASes are never evicted; one is
//! absent only between a failed build and the caller's retry, never traced so); a TLAS is
//! `dirty` when its instance records no longer match the resident BLASes (a BLAS of it was
//! built, evicted or moved) and is rebuilt or updated before the next trace, except a
//! *stale* one (dirty only because BLASes of it were built: `stale ⊆ dirty`), which a frame
//! with a build budget may trace as it is (`piece_order.rs`): it references only resident
//! BLASes, and its proxy still holds the new BLASes' boxes, so their rays stay open; a TLAS marked
//! persistent in `persistent_mode` holds a [`Persistent`] once built, and leaves the mode for
//! good when it does not fit (then it is rebuilt like the others).

use std::collections::{BTreeMap, BTreeSet};

use motu_vk::GpuHeap;

use super::persistent::{Persistent, Placeholders};
use super::tlas_compact::KeptRecords;
use crate::scene::AccelStruct;

/// The TLASes of a [`StreamingRenderer`](super::StreamingRenderer) (see the module docs).
/// The fields are private: residency, the dirty set and the persistent mode change together
/// through the methods below, which keep the invariants.
pub(super) struct Tlases {
    /// Per TLAS: resident with its proxy and marks.
    tlas: Vec<Option<TlasGpu>>,
    /// The persistent TLASes' placeholder BLASes (empty unless some TLAS is persistent).
    placeholders: Placeholders,
    /// Per TLAS: persistent (built over every instance, then updated) rather than rebuilt.
    persistent_mode: Vec<bool>,
    /// Resident TLASes whose instance set changed since their build.
    dirty: BTreeSet<u32>,
    /// Of `dirty`: those whose instance set only grew (BLASes built, none evicted or moved)
    /// since their build, with the build step that first made them so (oldest first). Never
    /// a persistent TLAS (its update is not split this way).
    stale: BTreeMap<u32, u64>,
    /// The rebuilt TLASes' instance records kept on the GPU (`tlas_compact.rs`).
    records: KeptRecords,
    /// Per TLAS: the pass stamp of its last rebuild or update (a stamp is taken by every
    /// trace, so an equal stamp means no trace saw the one before).
    rebuilt_at: Vec<Option<u32>>,
}

impl Tlases {
    /// `count` TLASes, none resident yet, none persistent.
    pub fn new(count: usize) -> Tlases {
        Tlases {
            tlas: (0..count).map(|_| None).collect(),
            placeholders: Default::default(),
            persistent_mode: vec![false; count],
            dirty: BTreeSet::new(),
            stale: BTreeMap::new(),
            records: KeptRecords::new(count),
            rebuilt_at: vec![None; count],
        }
    }

    /// The instance records kept on the GPU for rebuilds (`tlas_compact.rs`).
    pub fn records(&self) -> &KeptRecords {
        &self.records
    }

    pub fn records_mut(&mut self) -> &mut KeptRecords {
        &mut self.records
    }

    /// TLAS `t`, where resident (`None` too for an id out of range).
    pub fn get(&self, t: u32) -> Option<&TlasGpu> {
        self.tlas.get(t as usize).and_then(Option::as_ref)
    }

    /// The resident TLASes.
    pub fn resident(&self) -> impl Iterator<Item = &TlasGpu> {
        self.tlas.iter().flatten()
    }

    /// Whether TLAS `t` is persistent and built.
    pub fn is_persistent(&self, t: u32) -> bool {
        self.get(t).is_some_and(|g| g.persistent.is_some())
    }

    /// How many TLASes are in persistent mode.
    pub fn persistent_count(&self) -> usize {
        self.persistent_mode.iter().filter(|&&p| p).count()
    }

    /// Whether TLAS `t` is in persistent mode (updated in place rather than rebuilt).
    pub fn in_persistent_mode(&self, t: u32) -> bool {
        self.persistent_mode[t as usize]
    }

    /// Chooses the persistent TLASes at the start (one flag per TLAS).
    pub fn set_persistent_mode(&mut self, mode: Vec<bool>) {
        assert_eq!(mode.len(), self.tlas.len(), "one flag per TLAS");
        self.persistent_mode = mode;
    }

    /// TLAS `t` leaves the persistent mode for good (built over every instance it does not
    /// fit): rebuilt from now on.
    pub fn leave_persistent_mode(&mut self, t: u32) {
        self.persistent_mode[t as usize] = false;
    }

    /// Every persistent TLAS becomes a rebuilt one: out of the mode, released and dirty (the
    /// next rebuild builds it over the resident instances). Returns whether any was persistent.
    pub fn end_persistent_mode(&mut self, heap: &mut GpuHeap) -> bool {
        let mut any = false;
        for t in 0..self.persistent_mode.len() {
            if !std::mem::take(&mut self.persistent_mode[t]) {
                continue;
            }
            any = true;
            if let Some(g) = self.tlas[t].take() {
                g.release(heap);
            }
            self.dirty.insert(t as u32);
            self.stale.remove(&(t as u32));
        }
        any
    }

    /// The persistent TLASes' placeholders.
    pub fn placeholders(&self) -> &Placeholders {
        &self.placeholders
    }

    /// The placeholders, to build or release them (`persistent.rs`).
    pub fn placeholders_mut(&mut self) -> &mut Placeholders {
        &mut self.placeholders
    }

    /// Whether some TLAS is dirty (to rebuild or update before the next trace).
    pub fn any_dirty(&self) -> bool {
        !self.dirty.is_empty()
    }

    /// The dirty TLASes, in order.
    pub fn dirty(&self) -> &BTreeSet<u32> {
        &self.dirty
    }

    /// A BLAS under resident TLAS `t` went or moved: its records name a structure no longer
    /// there, so it is rebuilt before any trace (a *must* rebuild, stale or not before). A
    /// TLAS not resident is built over the resident BLASes anyway.
    pub fn instances_changed(&mut self, t: u32) {
        if self.tlas[t as usize].is_some() {
            self.dirty.insert(t);
            self.stale.remove(&t);
        }
    }

    /// A BLAS under resident TLAS `t` was built (in build step `step`): a TLAS dirty by
    /// nothing else becomes stale (safe to trace as it is; see the module docs). A persistent
    /// TLAS becomes dirty as by [`Self::instances_changed`].
    pub fn instances_added(&mut self, t: u32, step: u64) {
        if self.tlas[t as usize].is_none() {
            return;
        }
        if self.is_persistent(t) || self.persistent_mode[t as usize] {
            self.instances_changed(t);
        } else if self.dirty.insert(t) {
            self.stale.insert(t, step);
        }
    }

    /// Whether some TLAS is dirty and not stale (rebuilt before any trace, whatever the
    /// frame's budget).
    pub fn any_must(&self) -> bool {
        self.dirty.len() > self.stale.len()
    }

    /// Whether dirty TLAS `t` is stale (may be traced as it is).
    pub fn is_stale(&self, t: u32) -> bool {
        self.stale.contains_key(&t)
    }

    /// The stale TLASes with the build step that made each stale, in TLAS order.
    pub fn stale(&self) -> &BTreeMap<u32, u64> {
        &self.stale
    }

    /// TLAS `t` is about to be rebuilt or updated: dirty until it is. A persistent TLAS keeps
    /// its structure and hands over its proxy and marks; another releases its structure and
    /// hands them over. The caller reuses them where its clusters' residency is unchanged
    /// (same boxes, same order) and releases them otherwise. With `keep_storage` a rebuilt
    /// (not persistent, not compacted) TLAS's structure is handed over too, unreleased, for
    /// the new one to be built into its storage (`tlas_build/storage.rs`); it is out of the
    /// TLAS either way (absent until swapped in: nothing traces it).
    pub fn start_rebuild(
        &mut self,
        t: u32,
        keep_storage: bool,
        heap: &mut GpuHeap,
    ) -> Option<(ProxyPair, Option<AccelStruct>)> {
        let taken = if self.is_persistent(t) {
            let g = self.tlas[t as usize].as_mut()?;
            (ProxyPair::take_from(g), None)
        } else {
            let mut old = self.tlas[t as usize].take()?;
            let pair = ProxyPair::take_from(&mut old);
            let storage = if keep_storage && old.saved_bytes == 0 && old.persistent.is_none() {
                Some(old.accel)
            } else {
                old.release(heap);
                None
            };
            (pair, storage)
        };
        // Absent until swapped in: a must rebuild should this one fail.
        self.dirty.insert(t);
        self.stale.remove(&t);
        Some(taken)
    }

    /// Persistent TLAS `t` built over every instance (its first build; the update that follows
    /// makes it clean).
    pub fn put_persistent(&mut self, t: u32, g: TlasGpu) {
        self.tlas[t as usize] = Some(g);
    }

    /// Takes persistent TLAS `t` out to update it in place; [`Self::put_back`] returns it.
    pub fn take_for_update(&mut self, t: u32) -> Option<TlasGpu> {
        self.tlas[t as usize].take()
    }

    /// Returns a TLAS taken by [`Self::take_for_update`], as dirty as it was.
    pub fn put_back(&mut self, t: u32, g: TlasGpu) {
        self.tlas[t as usize] = Some(g);
    }

    /// TLAS `t` rebuilt over the resident BLASes: resident and clean (the structure it
    /// replaces, if any, released).
    pub fn rebuilt(&mut self, t: u32, g: TlasGpu, heap: &mut GpuHeap) {
        if let Some(old) = self.tlas[t as usize].replace(g) {
            old.release(heap);
        }
        self.dirty.remove(&t);
        self.stale.remove(&t);
    }

    /// TLAS `t` was rebuilt or updated at pass stamp `stamp`; returns whether it was already
    /// at that stamp (rebuilt twice with no trace between).
    pub fn note_rebuilt(&mut self, t: u32, stamp: u32) -> bool {
        self.rebuilt_at[t as usize].replace(stamp) == Some(stamp)
    }

    /// Persistent TLAS `t` updated in place, with its new proxy and marks: clean.
    pub fn updated(&mut self, t: u32, pair: ProxyPair, heap: &mut GpuHeap) {
        if let Some(g) = self.tlas[t as usize].as_mut() {
            g.proxy = pair.proxy;
            g.marks = pair.marks;
            g.proxy_key = pair.key;
            g.proxy_saved_bytes = pair.saved_bytes;
        } else {
            pair.release(heap);
        }
        self.dirty.remove(&t);
        self.stale.remove(&t);
    }

    /// Bytes the TLASes, their proxies, marks and persistent parts, the placeholders and the
    /// kept instance records hold (`host_counts`: whether host-visible memory counts against
    /// the budget).
    pub fn size_bytes(&self, host_counts: bool) -> u64 {
        self.resident()
            .map(|t| t.size_bytes(host_counts))
            .sum::<u64>()
            + self.placeholders.bytes
            + self.records.bytes()
    }

    /// Bytes the resident TLASes' proxy and marks BLASes hold.
    pub fn proxy_bytes(&self) -> u64 {
        self.resident()
            .flat_map(|t| [&t.proxy, &t.marks])
            .flatten()
            .map(|a| a.size_bytes)
            .sum()
    }

    /// Bytes compaction saved on the resident TLASes and their proxy and marks BLASes: the
    /// room they would take more built without it (`--stream-tlas-compact off`).
    pub fn compact_saved_bytes(&self) -> u64 {
        self.resident()
            .map(|g| g.saved_bytes + g.proxy_saved_bytes)
            .sum()
    }
}

/// A TLAS's proxy and marks BLASes with the key of the boxes they were built over: one bit a
/// cluster, set where its BLAS was resident (the bits give the boxes' order: the
/// non-resident clusters', then the resident ones', each in cluster order).
#[derive(Default)]
pub(super) struct ProxyPair {
    pub key: Vec<u64>,
    pub proxy: Option<AccelStruct>,
    pub marks: Option<AccelStruct>,
    /// Bytes compaction saved on the two (their built sizes less their compacted ones).
    pub saved_bytes: u64,
}

impl ProxyPair {
    fn take_from(g: &mut TlasGpu) -> ProxyPair {
        ProxyPair {
            key: std::mem::take(&mut g.proxy_key),
            proxy: g.proxy.take(),
            marks: g.marks.take(),
            saved_bytes: std::mem::take(&mut g.proxy_saved_bytes),
        }
    }

    /// How many of the two it holds.
    pub fn count(&self) -> u64 {
        u64::from(self.proxy.is_some()) + u64::from(self.marks.is_some())
    }

    pub fn release(self, heap: &mut GpuHeap) {
        for a in [self.proxy, self.marks].into_iter().flatten() {
            a.release(heap);
        }
    }
}

/// A resident TLAS with its proxy BLAS (present while it has non-resident triangle instances).
/// The fields are private: a TLAS is made rebuilt ([`Self::rebuilt_with`]) or persistent
/// ([`Self::persistent_over`]) and its proxy and marks change only through [`Tlases`].
pub(super) struct TlasGpu {
    accel: AccelStruct,
    proxy: Option<AccelStruct>,
    /// The resident clusters' boxes (instance mask [`MARKS_MASK`](super::MARKS_MASK)): only probe passes' rays
    /// meet them, to mark what they pass through (present while some cluster is resident).
    marks: Option<AccelStruct>,
    /// Present when the TLAS is persistent (every instance, updated: `persistent.rs`).
    persistent: Option<Persistent>,
    /// The key of the boxes `proxy` and `marks` were built over ([`ProxyPair::key`]).
    proxy_key: Vec<u64>,
    /// Bytes compaction saved on `accel`, and on `proxy` and `marks`.
    saved_bytes: u64,
    proxy_saved_bytes: u64,
}

impl TlasGpu {
    /// A TLAS rebuilt over the resident instances, with its proxy and marks; `saved_bytes`:
    /// what compaction saved on it.
    pub fn rebuilt_with(accel: AccelStruct, pair: ProxyPair, saved_bytes: u64) -> TlasGpu {
        TlasGpu {
            accel,
            proxy: pair.proxy,
            marks: pair.marks,
            persistent: None,
            proxy_key: pair.key,
            saved_bytes,
            proxy_saved_bytes: pair.saved_bytes,
        }
    }

    /// A persistent TLAS built over every instance (its proxy and marks come with its update).
    pub fn persistent_over(accel: AccelStruct, p: Persistent) -> TlasGpu {
        TlasGpu {
            accel,
            proxy: None,
            marks: None,
            persistent: Some(p),
            proxy_key: Vec::new(),
            saved_bytes: 0,
            proxy_saved_bytes: 0,
        }
    }

    /// The structure the shaders trace.
    pub fn accel(&self) -> &AccelStruct {
        &self.accel
    }

    /// Its persistent part, when persistent.
    pub fn persistent(&self) -> Option<&Persistent> {
        self.persistent.as_ref()
    }

    /// The structure and the persistent part, to update the one from the other.
    pub fn update_parts(&mut self) -> (&AccelStruct, Option<&mut Persistent>) {
        (&self.accel, self.persistent.as_mut())
    }

    pub fn release(self, heap: &mut GpuHeap) {
        self.accel.release(heap);
        for a in [self.proxy, self.marks].into_iter().flatten() {
            a.release(heap);
        }
        if let Some(p) = self.persistent {
            p.release(heap);
        }
    }

    /// VRAM it holds (`host_counts`: whether host-visible memory counts against the budget).
    pub fn size_bytes(&self, host_counts: bool) -> u64 {
        self.accel.size_bytes
            + self
                .persistent
                .as_ref()
                .map_or(0, |p| p.size_bytes(host_counts))
            + [&self.proxy, &self.marks]
                .into_iter()
                .flatten()
                .map(|a| a.size_bytes)
                .sum::<u64>()
    }
}
