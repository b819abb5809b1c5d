//! Host-visible buffers the structure cache serialises into and deserialises from, kept
//! between batches where host-visible memory lies outside the VRAM budget (a discrete GPU).
//!
//! Each batch used to allocate a buffer the size of all its blobs (gigabytes at scale) and
//! free it after: the driver pins and zeroes every page of such an allocation, and on the H200
//! storing ran at ~1 GB/s and restoring at 1.3–1.8 GB/s. Batches are now cut at
//! [`TRANSFER_CAP_BYTES`] and, on a discrete GPU, one buffer per direction is kept and reused
//! (grown to the largest batch seen, at most the cap). On unified memory (lavapipe, integrated
//! GPUs) host-visible memory is the budget's own: buffers are freed after each batch as before.
//! A blob larger than the cap gets a buffer of its own, freed after use.
//!
//! Staged transfers (the default on discrete GPUs where the room allows): the GPU serialises
//! into, and deserialises from, a small device-local buffer ([`staging_bytes`], allocated after
//! the floor and kept; it yields to structures where nothing else can be evicted) and one buffer
//! copy a run moves the bytes across the bus, instead of the structure copies writing and
//! reading host memory themselves. On an H100 (island 0.63 at 8 GiB, alternated with direct)
//! serialising took 713–760 against 860 ms a frame and deserialising 382–387 / 797–800 against
//! 432 / 966 ms (cold / warm); cold 14.7 against 15.7 s to the PNG, warm 14.2 against 14.4 s
//! (BENCHMARKS.md, session 42). `MOTU_AS_TRANSFER=direct` turns staging off (A/B measurements),
//! `=staged` forces it (tests of small scenes).

use motu_alloc::{AllocKind, MemoryClass, MIB};
use motu_vk::{BufferUsage, HeapBuffer, SERIALIZED_ALIGNMENT};

use super::StreamingRenderer;

/// The most bytes one serialise or deserialise batch moves (and a kept buffer holds).
pub(super) const TRANSFER_CAP_BYTES: u64 = 256 * MIB;

/// The most bytes of the device-local staging buffer of staged transfers (module docs): a
/// 128th of an 8 GiB budget.
pub(super) const STAGING_MAX_BYTES: u64 = 64 * MIB;

/// The staging buffer's size under a budget of `budget_bytes` with `room_bytes` of it left for
/// streamed structures before the first frame: a 128th of the budget and at most a 32nd of the
/// room (at the floor it would cost passes: the default island at its floor took 17 passes against
/// 11 with a 1 MiB buffer), at most [`STAGING_MAX_BYTES`]; `None` below 1 MiB (direct).
pub(super) fn staging_bytes(budget_bytes: u64, room_bytes: u64) -> Option<u64> {
    let bytes = (budget_bytes / 128)
        .min(room_bytes / 32)
        .min(STAGING_MAX_BYTES);
    (bytes >= MIB).then_some(bytes)
}

/// The least a kept buffer is allocated with, so small batches do not grow it step by step.
const TRANSFER_MIN_BYTES: u64 = 16 * MIB;

/// Which way a transfer buffer carries structures.
#[derive(Clone, Copy, Debug)]
pub(super) enum Transfer {
    /// Serialised structures, written by the GPU and read by the host (storing).
    Readback,
    /// Serialised structures, written by the host and read by the GPU (restoring).
    Upload,
    /// Device-local staging between the structure copies and the host buffers (staged
    /// transfers, module docs).
    Staging,
}

impl Transfer {
    fn label(self) -> &'static str {
        match self {
            Transfer::Readback => "serialised blases",
            Transfer::Upload => "restore blobs",
            Transfer::Staging => "structure transfer staging",
        }
    }

    fn usage(self) -> BufferUsage {
        match self {
            Transfer::Readback => BufferUsage::DEVICE_ADDRESS.union(BufferUsage::TRANSFER_DST),
            Transfer::Upload => BufferUsage::DEVICE_ADDRESS
                .union(BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT)
                .union(BufferUsage::TRANSFER_SRC),
            Transfer::Staging => BufferUsage::DEVICE_ADDRESS
                .union(BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT)
                .union(BufferUsage::TRANSFER_SRC)
                .union(BufferUsage::TRANSFER_DST),
        }
    }

    fn class(self) -> MemoryClass {
        match self {
            Transfer::Readback | Transfer::Upload => MemoryClass::HostVisible,
            Transfer::Staging => MemoryClass::DeviceLocal,
        }
    }
}

/// `MOTU_AS_TRANSFER`: `direct` (no staging), `staged` (a staging buffer of a 128th of the
/// budget, at least 1 MiB, whatever the room: for tests of small scenes), else the default
/// ([`staging_bytes`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum StagingMode {
    Direct,
    Auto,
    Forced,
}

fn staging_mode() -> StagingMode {
    match std::env::var("MOTU_AS_TRANSFER").as_deref() {
        Ok("direct") => StagingMode::Direct,
        Ok("staged") => StagingMode::Forced,
        _ => StagingMode::Auto,
    }
}

/// The kept buffers (none on unified memory).
#[derive(Default)]
pub(super) struct TransferBuffers {
    readback: Option<HeapBuffer>,
    upload: Option<HeapBuffer>,
    staging: Option<HeapBuffer>,
}

impl TransferBuffers {
    pub(super) fn slot(&mut self, t: Transfer) -> &mut Option<HeapBuffer> {
        match t {
            Transfer::Readback => &mut self.readback,
            Transfer::Upload => &mut self.upload,
            Transfer::Staging => &mut self.staging,
        }
    }
}

/// One run of a staged transfer: blobs `blobs` (indices into the batch), staged together
/// through the staging buffer from the batch buffer's offset `start_bytes` on, `len_bytes`
/// long; or, `staged` false, one blob larger than the staging buffer, copied direct.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(super) struct StagedRun {
    pub(super) blobs: std::ops::Range<usize>,
    pub(super) start_bytes: u64,
    pub(super) len_bytes: u64,
    pub(super) staged: bool,
}

impl StagedRun {
    /// Where blob `i` (at `offset_bytes` in the batch buffer at `batch`) lies for the
    /// structure copy: in the staging buffer at `staging` when the run is staged, else in the
    /// batch buffer.
    pub(super) fn address(
        &self,
        offset_bytes: u64,
        staging: motu_vk::DeviceAddress,
        batch: motu_vk::DeviceAddress,
    ) -> motu_vk::DeviceAddress {
        if self.staged {
            staging.offset(offset_bytes - self.start_bytes)
        } else {
            batch.offset(offset_bytes)
        }
    }
}

/// Cuts a batch of blobs at `offsets` (ascending, in one buffer) of `sizes` bytes into runs
/// whose bytes fit `cap_bytes` from their first blob's offset ([`StagedRun`]).
pub(super) fn staged_runs(offsets: &[u64], sizes: &[u64], cap_bytes: u64) -> Vec<StagedRun> {
    let mut runs = Vec::new();
    let mut i = 0;
    while i < offsets.len() {
        let start_bytes = offsets[i];
        let mut j = i;
        while j < offsets.len() && offsets[j] + sizes[j] - start_bytes <= cap_bytes {
            j += 1;
        }
        let staged = j > i;
        let j = j.max(i + 1);
        runs.push(StagedRun {
            blobs: i..j,
            start_bytes,
            len_bytes: offsets[j - 1] + sizes[j - 1] - start_bytes,
            staged,
        });
        i = j;
    }
    runs
}

/// Bytes a kept buffer is allocated with for a batch of `size_bytes`: a power of two between
/// the minimum and the cap, so a few sizes serve every batch.
fn kept_size_bytes(size_bytes: u64) -> u64 {
    size_bytes
        .next_power_of_two()
        .clamp(TRANSFER_MIN_BYTES, TRANSFER_CAP_BYTES)
}

impl StreamingRenderer<'_> {
    /// Whether transfer buffers are kept between batches (host-visible memory outside the
    /// VRAM budget).
    fn keeps_transfer_buffers(&self) -> bool {
        !self.heap.host_visible_counts_against_budget()
    }

    /// A host-visible buffer of at least `size_bytes` for `t`: the kept one when it is large
    /// enough, else a new one. Give it back with [`Self::put_back_transfer`].
    pub(super) fn transfer_buffer(
        &mut self,
        t: Transfer,
        size_bytes: u64,
    ) -> motu_vk::Result<HeapBuffer> {
        self.frame.stats_mut().transfer_batches += 1;
        if let Some(b) = self.reuse.take_transfer(t) {
            if b.size_bytes() >= size_bytes {
                return Ok(b);
            }
            self.heap.free(b);
        }
        let alloc_bytes = if self.keeps_transfer_buffers() && size_bytes <= TRANSFER_CAP_BYTES {
            kept_size_bytes(size_bytes)
        } else {
            size_bytes
        };
        self.frame.stats_mut().transfer_allocations += 1;
        self.heap.alloc_buffer(
            t.label(),
            alloc_bytes,
            t.usage(),
            AllocKind::Staging,
            t.class(),
            SERIALIZED_ALIGNMENT,
        )
    }

    /// With a structure cache and staged transfers (on a discrete GPU): allocates the staging
    /// buffer now, after the floor and before frames fill the budget (a store at eviction finds
    /// the budget full), and keeps it, where the room left allows ([`staging_bytes`]). No
    /// room: transfers go direct.
    pub(super) fn reserve_transfer_staging(&mut self, room_bytes: u64) {
        if self.cache_stats().is_none() || !self.keeps_transfer_buffers() {
            return;
        }
        let budget_bytes = self.opts.budget_bytes;
        let bytes = match staging_mode() {
            StagingMode::Direct => None,
            StagingMode::Auto => staging_bytes(budget_bytes, room_bytes),
            StagingMode::Forced => Some((budget_bytes / 128).clamp(MIB, STAGING_MAX_BYTES)),
        };
        let Some(bytes) = bytes else {
            return;
        };
        let t = Transfer::Staging;
        let st = self.heap.alloc_buffer(
            t.label(),
            bytes,
            t.usage(),
            AllocKind::Staging,
            t.class(),
            SERIALIZED_ALIGNMENT,
        );
        match st {
            Ok(st) => self.put_back_transfer(t, st),
            Err(e) => tracing::debug!(error = %e, "structure transfers: no staging buffer; direct"),
        }
    }

    /// The kept staging buffer of staged transfers (module docs), taken for one transfer
    /// (give it back with [`Self::put_back_transfer`]); `None`: transfers go direct.
    pub(super) fn transfer_staging(&mut self) -> Option<HeapBuffer> {
        self.reuse.take_transfer(Transfer::Staging)
    }

    /// Frees the kept staging buffer for a structure's room, where nothing else can be
    /// evicted (transfers go direct from then on). Returns whether it held one.
    pub(super) fn release_staging_for_room(&mut self) -> bool {
        match self.reuse.take_transfer(Transfer::Staging) {
            Some(st) => {
                tracing::debug!(
                    bytes = st.size_bytes(),
                    "structure transfers: staging released for room"
                );
                self.heap.free(st);
                self.frame.stats_mut().transfer_staging_released += 1;
                true
            }
            None => false,
        }
    }

    /// Keeps `buf` for the next batch where that is the policy (see the module docs), else
    /// frees it.
    pub(super) fn put_back_transfer(&mut self, t: Transfer, buf: HeapBuffer) {
        if self.keeps_transfer_buffers() && buf.size_bytes() <= TRANSFER_CAP_BYTES {
            if let Some(old) = self.reuse.keep_transfer(t, buf) {
                self.heap.free(old);
            }
        } else {
            self.heap.free(buf);
        }
    }
}

#[cfg(test)]
mod tests;
