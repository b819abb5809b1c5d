//! A rebuilt TLAS built into the storage of the structure it replaces (issue 45.5, design B of
//! notes/tlasreuse.md). At a quarter of island 0.3 a piece's new TLAS (~110 MB) is the one
//! dedicated block of its rebuild: a `vkAllocateMemory` for the new structure and a
//! `vkFreeMemory` for the old one, 3.8 ms of each piece's host time on an H100 (session 48).
//! Building the new one into the old one's buffer (mode `Build`, the same handle and device
//! address) costs neither.
//!
//! Held only where the one-submission path can take the rebuild (nothing compacted, the host's
//! records, no persistent TLAS in it), and only when the new structure fits the old capacity
//! with at most an eighth of it to spare ([`reusable`]): the memory held is never more than
//! today's by more than that slack, and a shrunk piece gets a fresh, smaller block. The room
//! probe decides on the estimated sizes and releases what it will not reuse before asking;
//! the allocation checks the queried ones. Whatever is still held when a path gives up (a
//! refusal, the step-by-step path, an error) is released, so a failed build leaves the TLAS
//! absent with its storage freed, as before.

use motu_alloc::BuildSize;
use motu_vk::{AsLevel, Context, GpuHeap, VkError};

use super::{PhaseTimes, TlasBuild};
use crate::error::{GpuError, Result};
use crate::scene::AccelStruct;
use crate::stream::MAX_TLAS_HEADROOM;

/// Whether a structure of `capacity_bytes` takes a new one of `need_bytes`: it fits, with at
/// most an eighth of the capacity to spare (more would hold memory the rebuild no longer needs
/// until the piece grows back).
pub(super) fn reusable(capacity_bytes: u64, need_bytes: u64) -> bool {
    need_bytes <= capacity_bytes && capacity_bytes - need_bytes <= capacity_bytes / 8
}

/// The storage a fresh structure for `need_bytes` gets with `headroom` (a fraction of the
/// need, at most [`MAX_TLAS_HEADROOM`]), in 256-byte steps (the structures' offset
/// alignment). Pieces mostly outgrow their storage: at a quarter of island 0.3 on an H100,
/// 100 of 117 fresh allocations along 8 frames were pieces that had grown past theirs (session
/// 50), each a `vkAllocateMemory` + `vkFreeMemory` of ~110 MB.
pub(super) fn with_headroom(need_bytes: u64, headroom: f64) -> u64 {
    let extra = (need_bytes as f64 * headroom.clamp(0.0, MAX_TLAS_HEADROOM)).ceil() as u64;
    need_bytes
        .saturating_add(extra)
        .checked_next_multiple_of(256)
        .unwrap_or(!255u64)
}

/// The old structures of a rebuild's TLASes held for reuse: (TLAS, structure).
#[derive(Default)]
pub(super) struct OldStorage(Vec<(u32, AccelStruct)>);

impl OldStorage {
    pub(super) fn push(&mut self, t: u32, a: AccelStruct) {
        self.0.push((t, a));
    }

    pub(super) fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Whether TLAS `t`'s old structure is held.
    pub(super) fn holds(&self, t: u32) -> bool {
        self.0.iter().any(|(u, _)| *u == t)
    }

    /// TLAS `t`'s old structure, out of the holding.
    fn take(&mut self, t: u32) -> Option<AccelStruct> {
        let k = self.0.iter().position(|(u, _)| *u == t)?;
        Some(self.0.swap_remove(k).1)
    }

    /// Keeps the structures `keep(t, capacity)` accepts, releasing the others.
    pub(super) fn retain(&mut self, heap: &mut GpuHeap, mut keep: impl FnMut(u32, u64) -> bool) {
        let (kept, gone): (Vec<_>, Vec<_>) = std::mem::take(&mut self.0)
            .into_iter()
            .partition(|(t, a)| keep(*t, a.size_bytes));
        self.0 = kept;
        gone.into_iter().for_each(|(_, a)| a.release(heap));
    }

    /// Releases every structure held.
    pub(super) fn release(&mut self, heap: &mut GpuHeap) {
        self.retain(heap, |_, _| false);
    }
}

/// New TLAS structures for `ids` of queried `sizes`, in order: built into TLAS `ids[k]`'s held
/// old structure where it is [`reusable`], else fresh storage allocated after that old one is
/// released (the peak as without reuse), with `headroom` ([`with_headroom`]) where the budget
/// has room for it and at the exact size where it has not (the room probe asked for the exact
/// size: headroom never refuses a rebuild). Returns them with how many reuse old storage, or
/// `None` when the budget refuses one (those made are released, the rest stay held).
pub(super) fn tlas_structures(
    ctx: &Context,
    heap: &mut GpuHeap,
    old: &mut OldStorage,
    ids: &[u32],
    sizes: &[BuildSize],
    headroom: f64,
) -> Result<Option<(Vec<AccelStruct>, u32)>> {
    let mut made = Vec::with_capacity(ids.len());
    let mut reused = 0u32;
    for (k, (&t, size)) in ids.iter().zip(sizes).enumerate() {
        match old.take(t) {
            Some(a) if reusable(a.size_bytes, size.result_bytes) => {
                reused += 1;
                made.push(a);
                continue;
            }
            Some(a) => a.release(heap),
            None => {}
        }
        let label = format!("tlas-{k}");
        let roomy = with_headroom(size.result_bytes, headroom);
        let fresh = match AccelStruct::new(ctx, heap, &label, roomy, AsLevel::Top) {
            Err(VkError::Budget(_)) if roomy > size.result_bytes => None,
            other => Some(other),
        };
        let fresh = match fresh {
            Some(r) => r,
            None => AccelStruct::new(ctx, heap, &label, size.result_bytes, AsLevel::Top),
        };
        match fresh {
            Ok(a) => made.push(a),
            Err(e) => {
                made.into_iter().for_each(|a| a.release(heap));
                // A budget refusal: the caller falls back.
                return match e {
                    VkError::Budget(_) => Ok(None),
                    e => Err(e.into()),
                };
            }
        }
    }
    Ok(Some((made, reused)))
}

impl TlasBuild<'_, '_> {
    /// Whether rebuilding `ids` holds their old structures for reuse: only where the
    /// one-submission path can take it (`one_submit.rs`).
    pub(super) fn keeps_storage(&self, ids: &[u32]) -> bool {
        let r = &*self.r;
        !r.rebuild_opts().compact
            && r.opts.tlas_records != crate::stream::TlasRecordsMode::Gpu
            && !ids.iter().any(|&t| r.tlases.in_persistent_mode(t))
    }

    /// Releases every old structure still held (a path that will not reuse them, or the end
    /// of the build), timed as a free.
    pub(super) fn release_old_storage(&mut self) {
        if self.old_storage.is_empty() {
            return;
        }
        let (old, heap) = (&mut self.old_storage, &mut self.r.heap);
        PhaseTimes::timed(&mut self.times.free_ms, || old.release(heap));
    }

    /// The room probe of rebuilding `ids`
    /// ([`probe_tlas_room`](crate::stream::StreamingRenderer::probe_tlas_room); `tails`: the
    /// records after each one's own): the held old structures the estimated sizes would not
    /// reuse are released first, and those held are not asked for again (the shadow allocator
    /// keeps them, so asking would count them twice). Refused with storage held, it releases
    /// it and asks as without reuse: never refusing what it let through before.
    pub(super) fn probe_with_storage(&mut self, ids: &[u32], tails: &[u64]) -> Result<()> {
        let est = self.r.tlas_estimates(ids, tails)?;
        if !self.old_storage.is_empty() {
            let (old, heap) = (&mut self.old_storage, &mut self.r.heap);
            let (mut grew, mut shrank) = (0u32, 0u32);
            PhaseTimes::timed(&mut self.times.free_ms, || {
                old.retain(heap, |t, capacity_bytes| {
                    let Some(k) = ids.iter().position(|&u| u == t) else {
                        return false;
                    };
                    let need_bytes = est[k].1.result_bytes;
                    let keep = reusable(capacity_bytes, need_bytes);
                    grew += u32::from(!keep && need_bytes > capacity_bytes);
                    shrank += u32::from(!keep && need_bytes <= capacity_bytes);
                    keep
                })
            });
            // Why storage was not reused (the debug line): how often pieces outgrow theirs
            // decides whether headroom on fresh allocations would pay.
            self.times.storage_grew += grew;
            self.times.storage_shrank += shrank;
        }
        let held: Vec<bool> = ids.iter().map(|&t| self.old_storage.holds(t)).collect();
        match self.r.probe_tlas_room(&est, &held) {
            Err(GpuError::Budget(_)) if held.contains(&true) => {
                self.release_old_storage();
                self.r.probe_tlas_room(&est, &vec![false; ids.len()])
            }
            other => other,
        }
    }
}

#[cfg(test)]
mod tests;
