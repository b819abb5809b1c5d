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

use motu_alloc::{AllocKind, MemoryClass, MIB};
use motu_vk::{BufferUsage, HeapBuffer, SERIALIZED_ALIGNMENT};

use super::StreamingRenderer;

/// The most bytes one serialise or deserialise batch moves (and a kept buffer holds).
pub(super) const TRANSFER_CAP_BYTES: u64 = 256 * MIB;

/// The least a kept buffer is allocated with, so small batches do not grow it step by step.
const TRANSFER_MIN_BYTES: u64 = 16 * MIB;

/// Which way a transfer buffer carries structures.
#[derive(Clone, Copy, Debug)]
pub(super) enum Transfer {
    /// Serialised structures, written by the GPU and read by the host (storing).
    Readback,
    /// Serialised structures, written by the host and read by the GPU (restoring).
    Upload,
}

impl Transfer {
    fn label(self) -> &'static str {
        match self {
            Transfer::Readback => "serialised blases",
            Transfer::Upload => "restore blobs",
        }
    }

    fn usage(self) -> BufferUsage {
        match self {
            Transfer::Readback => BufferUsage::DEVICE_ADDRESS.union(BufferUsage::TRANSFER_DST),
            Transfer::Upload => {
                BufferUsage::DEVICE_ADDRESS.union(BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT)
            }
        }
    }
}

/// The kept buffers (none on unified memory).
#[derive(Default)]
pub(super) struct TransferBuffers {
    readback: Option<HeapBuffer>,
    upload: Option<HeapBuffer>,
}

impl TransferBuffers {
    pub(super) fn slot(&mut self, t: Transfer) -> &mut Option<HeapBuffer> {
        match t {
            Transfer::Readback => &mut self.readback,
            Transfer::Upload => &mut self.upload,
        }
    }
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
            MemoryClass::HostVisible,
            SERIALIZED_ALIGNMENT,
        )
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
