//! The TLAS part ([`Tlases`]): every TLAS with its proxy and marks BLASes, which TLASes are
//! persistent (updated in place, `persistent.rs`) and their placeholders, and which are dirty.
//!
//! Invariants: after the start every TLAS is resident (TLASes are never evicted; one is
//! absent only between a failed build and the caller's retry, never traced so); a TLAS is
//! `dirty` when its instance records no longer match the resident BLASes (a BLAS of it was
//! built, evicted or moved) and is rebuilt or updated before the next trace; a TLAS marked
//! persistent in `persistent_mode` holds a [`Persistent`] once built, and leaves the mode for
//! good when it does not fit (then it is rebuilt like the others).

use std::collections::BTreeSet;

use motu_vk::GpuHeap;

use super::persistent::{Persistent, Placeholders};
use crate::scene::AccelStruct;

/// The TLASes of a [`StreamingRenderer`](super::StreamingRenderer) (see the module docs).
pub(super) struct Tlases {
    /// Per TLAS: resident with its proxy and marks.
    pub tlas: Vec<Option<TlasGpu>>,
    /// The persistent TLASes' placeholder BLASes (empty unless some TLAS is persistent).
    pub placeholders: Placeholders,
    /// Per TLAS: persistent (built over every instance, then updated) rather than rebuilt.
    pub persistent_mode: Vec<bool>,
    /// Resident TLASes whose instance set changed since their build.
    pub dirty: BTreeSet<u32>,
}

impl Tlases {
    /// `count` TLASes, none resident yet, none persistent.
    pub fn new(count: usize) -> Tlases {
        Tlases {
            tlas: (0..count).map(|_| None).collect(),
            placeholders: Default::default(),
            persistent_mode: vec![false; count],
            dirty: BTreeSet::new(),
        }
    }

    /// Whether TLAS `t` is persistent and built.
    pub fn is_persistent(&self, t: u32) -> bool {
        self.tlas[t as usize]
            .as_ref()
            .is_some_and(|g| g.persistent.is_some())
    }

    /// How many TLASes are in persistent mode.
    pub fn persistent_count(&self) -> usize {
        self.persistent_mode.iter().filter(|&&p| p).count()
    }

    /// Bytes the TLASes, their proxies, marks and persistent parts, and the placeholders
    /// hold (`host_counts`: whether host-visible memory counts against the budget).
    pub fn size_bytes(&self, host_counts: bool) -> u64 {
        self.tlas
            .iter()
            .flatten()
            .map(|t| t.size_bytes(host_counts))
            .sum::<u64>()
            + self.placeholders.bytes
    }
}

/// A resident TLAS with its proxy BLAS (present while it has non-resident triangle instances).
pub(super) struct TlasGpu {
    pub accel: AccelStruct,
    pub proxy: Option<AccelStruct>,
    /// The resident clusters' boxes (instance mask [`MARKS_MASK`](super::MARKS_MASK)): only probe passes' rays
    /// meet them, to mark what they pass through (present while some cluster is resident).
    pub marks: Option<AccelStruct>,
    /// Present when the TLAS is persistent (every instance, updated: `persistent.rs`).
    pub persistent: Option<Persistent>,
}

impl TlasGpu {
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
