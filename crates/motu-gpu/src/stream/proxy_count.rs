//! Counting mode of the streamed trace ([`StreamOptions::count_proxy_calls`]): where a pass's
//! proxy work goes, per ray kind (camera, guard, shadow, AO, bounce) and outcome (open, closed,
//! miss), to say why a partly resident frame traces slower than a complete one.
//!
//! The shaders count under a specialisation constant (`COUNT_PROXY` of `common.glsl`), so a
//! pipeline made without it runs no counting code. With it they write a longer stats buffer
//! than the frame's: the `STAT_*` words, [`PROXY_COUNT_WORDS`] counters, then
//! [`PROXY_ITEM_WORDS`] words per launch item where the pipeline's proxy intersection and
//! any-hit shaders add up what the item's current ray costs (they cannot reach the payload);
//! raygen moves those into the counters after each ray. That buffer (device-local, with a
//! host-visible copy of the counters each pass) is allocated beside the frame's only in
//! counting mode, so its room shifts residency a little against a run without counts: compare
//! counted runs with counted runs.
//!
//! [`StreamOptions::count_proxy_calls`]: super::StreamOptions::count_proxy_calls

use motu_alloc::{AllocKind, MemoryClass};
use motu_vk::{BufferUsage, GpuHeap, HeapBuffer};

use super::PassStats;
use crate::error::Result;
use crate::render::STAT_WORDS;

/// Ray kinds, outcomes and fields of the counters (`PROXY_KINDS`, `PROXY_OUTCOMES`,
/// `PROXY_FIELDS` of `common.glsl`).
pub(super) const PROXY_KINDS: usize = 5;
pub(super) const PROXY_OUTCOMES: usize = 3;
pub(super) const PROXY_FIELDS: usize = 5;
/// Counters after the `STAT_*` words (`PROXY_COUNT_WORDS`).
pub(super) const PROXY_COUNT_WORDS: usize = PROXY_KINDS * PROXY_OUTCOMES * PROXY_FIELDS;
/// Words per launch item after the counters (`PROXY_ITEM_WORDS`).
pub(super) const PROXY_ITEM_WORDS: usize = 4;

/// What the rays of one kind and outcome cost a pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ProxyWork {
    /// Rays traced (each ray once, over all its walks and its mark walk).
    pub rays: u64,
    /// Proxy intersection-shader calls (query backend: proxy candidates met).
    pub calls: u64,
    /// Of `calls`: boxes reported to the any-hit (the query backend runs every candidate).
    pub reports: u64,
    /// Member boxes tested quantised, and the exact tests they let through.
    pub member_tests: u64,
    pub exact_tests: u64,
}

/// A ray kind's [`ProxyWork`] by outcome: open (a structure it has not walked lies in front
/// of its best hit), closed (a hit, or occluded), miss (clear).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ProxyCalls {
    pub open: ProxyWork,
    pub closed: ProxyWork,
    pub miss: ProxyWork,
}

impl ProxyCalls {
    /// The sum over the outcomes.
    pub fn total(&self) -> ProxyWork {
        let mut t = ProxyWork::default();
        for w in [self.open, self.closed, self.miss] {
            t.rays += w.rays;
            t.calls += w.calls;
            t.reports += w.reports;
            t.member_tests += w.member_tests;
            t.exact_tests += w.exact_tests;
        }
        t
    }
}

impl PassStats {
    /// The pass's counts by ray kind: camera, guard, shadow, AO, bounce.
    pub fn proxy_calls_by_kind(&self) -> [(&'static str, ProxyCalls); PROXY_KINDS] {
        [
            ("camera", self.proxy_calls_camera),
            ("guard", self.proxy_calls_guard),
            ("shadow", self.proxy_calls_shadow),
            ("ao", self.proxy_calls_ao),
            ("bounce", self.proxy_calls_bounce),
        ]
    }
}

/// Fills `pass`'s `proxy_calls_*` with what the counters `now` grew by since `before` (both
/// [`PROXY_COUNT_WORDS`] long, or empty without counting).
pub(super) fn fill_pass(now: &[u32], before: &[u32], pass: &mut PassStats) {
    if now.len() < PROXY_COUNT_WORDS {
        return;
    }
    let at = |i: usize| {
        let then = before.get(i).copied().unwrap_or(0);
        u64::from(now[i].wrapping_sub(then))
    };
    let work = |kind: usize, outcome: usize| {
        let w = PROXY_FIELDS * (PROXY_OUTCOMES * kind + outcome);
        ProxyWork {
            rays: at(w),
            calls: at(w + 1),
            reports: at(w + 2),
            member_tests: at(w + 3),
            exact_tests: at(w + 4),
        }
    };
    let calls = |kind: usize| ProxyCalls {
        open: work(kind, 0),
        closed: work(kind, 1),
        miss: work(kind, 2),
    };
    pass.proxy_calls_camera = calls(0);
    pass.proxy_calls_guard = calls(1);
    pass.proxy_calls_shadow = calls(2);
    pass.proxy_calls_ao = calls(3);
    pass.proxy_calls_bounce = calls(4);
    if pass.proxy_member_tests == 0 {
        // The pipeline backend counts member tests only here (the query backend's STAT words
        // hold the same sums).
        let all = pass.proxy_calls_by_kind().map(|(_, c)| c.total());
        pass.proxy_member_tests = all.iter().map(|w| w.member_tests).sum();
        pass.proxy_exact_tests = all.iter().map(|w| w.exact_tests).sum();
    }
}

/// Counting mode's buffers: the stats buffer its shaders write, and the counters' read-back.
pub(in crate::stream) struct CountBuffers {
    pub(super) counts: HeapBuffer,
    pub(super) readback: HeapBuffer,
}

impl CountBuffers {
    pub(super) fn release(self, heap: &mut GpuHeap) {
        heap.free(self.counts);
        heap.free(self.readback);
    }
}

/// Words of the counting stats buffer for passes of up to `items` launch items.
pub(super) fn count_buffer_words(items: u64) -> u64 {
    (STAT_WORDS + PROXY_COUNT_WORDS) as u64 + PROXY_ITEM_WORDS as u64 * items
}

/// The counting stats buffer, grown to hold passes of `items` launch items (`slot`: the one
/// kept so far, released when too small). Device-local: the shaders add to it per proxy call.
pub(super) fn ensure_count_buffer(
    heap: &mut GpuHeap,
    slot: &mut Option<CountBuffers>,
    items: u64,
) -> Result<()> {
    let bytes = 4 * count_buffer_words(items);
    if slot
        .as_ref()
        .is_some_and(|b| b.counts.size_bytes() >= bytes)
    {
        return Ok(());
    }
    if let Some(old) = slot.take() {
        old.release(heap);
    }
    // Some headroom, so a pass with a few more items does not reallocate.
    let bytes = 4 * count_buffer_words(items + items / 4 + 64);
    let usage = BufferUsage::STORAGE
        | BufferUsage::DEVICE_ADDRESS
        | BufferUsage::TRANSFER_SRC
        | BufferUsage::TRANSFER_DST;
    let counts = heap.alloc_buffer(
        "proxy-counts",
        bytes,
        usage,
        AllocKind::Other,
        MemoryClass::DeviceLocal,
        16,
    )?;
    let readback = heap.alloc_buffer(
        "proxy-counts-readback",
        (4 * PROXY_COUNT_WORDS) as u64,
        BufferUsage::TRANSFER_DST,
        AllocKind::Staging,
        MemoryClass::HostVisible,
        16,
    );
    match readback {
        Ok(readback) => {
            *slot = Some(CountBuffers { counts, readback });
            Ok(())
        }
        Err(e) => {
            heap.free(counts);
            Err(e.into())
        }
    }
}

#[cfg(test)]
mod tests;
