//! Decoded zstd chunks kept for reuse ([`Package::chunk_shared`]). A streamed build group reads
//! many meshes out of each chunk, and each read decoded the whole chunk (up to 64 MiB by
//! default) again: three times a mesh (positions and indices, the primitive map, the shading
//! attributes), into fresh zeroed memory each time.

use std::collections::VecDeque;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, OnceLock};

use super::storage::AlignedBytes;
use crate::PackageError;

/// Decoded bytes the cache holds at most (at least its newest chunk): 16 chunks of the
/// default 64 MiB, about as many as the threads of a 16-core host read from at once.
pub const DECODED_CACHE_BYTES: u64 = 1 << 30;

/// One chunk's decoded bytes, filled once by whichever thread asked first (the others wait
/// for it); `None` when that decode failed.
type Slot = Arc<OnceLock<Option<Arc<AlignedBytes>>>>;

/// Least recently used decoded chunks (newest last), bounded by [`DECODED_CACHE_BYTES`].
#[derive(Default)]
pub(super) struct DecodedChunks {
    entries: Mutex<VecDeque<(u32, u64, Slot)>>,
    /// Chunks decompressed, through the cache or not ([`Package::chunk_decodes`]).
    decodes: AtomicU64,
}

impl DecodedChunks {
    /// Notes one decompression.
    pub(super) fn counted(&self) {
        self.decodes.fetch_add(1, Ordering::Relaxed);
    }

    pub(super) fn decodes(&self) -> u64 {
        self.decodes.load(Ordering::Relaxed)
    }

    /// Chunk `id`'s decoded bytes (`raw_len` of them): from the cache, or `decode`d now and
    /// kept. A failed decode is not kept: the error goes to each caller that asks.
    pub(super) fn get_or_decode(
        &self,
        id: u32,
        raw_len: u64,
        decode: impl Fn() -> Result<AlignedBytes, PackageError>,
    ) -> Result<Arc<AlignedBytes>, PackageError> {
        let slot = self.slot(id, raw_len);
        let mut failed = None;
        let got = slot.get_or_init(|| match decode() {
            Ok(bytes) => {
                self.counted();
                Some(Arc::new(bytes))
            }
            Err(e) => {
                failed = Some(e);
                None
            }
        });
        if let Some(bytes) = got {
            return Ok(Arc::clone(bytes));
        }
        self.forget(id);
        match failed {
            Some(e) => Err(e),
            // Another thread's decode failed: this caller gets the error of its own.
            None => decode().map(Arc::new),
        }
    }

    /// The slot of chunk `id`, now the newest; a new one evicts the oldest beyond the bound.
    fn slot(&self, id: u32, raw_len: u64) -> Slot {
        // A poisoned lock only means a panic elsewhere mid-update of a plain list: keep going.
        let mut entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(i) = entries.iter().position(|e| e.0 == id) {
            let entry = entries.remove(i).expect("position is in range");
            let slot = Arc::clone(&entry.2);
            entries.push_back(entry);
            return slot;
        }
        let slot: Slot = Arc::default();
        entries.push_back((id, raw_len, Arc::clone(&slot)));
        let mut held: u64 = entries.iter().map(|e| e.1).sum();
        while held > DECODED_CACHE_BYTES && entries.len() > 1 {
            held -= entries.pop_front().map_or(0, |e| e.1);
        }
        slot
    }

    fn forget(&self, id: u32) {
        let mut entries = self.entries.lock().unwrap_or_else(|e| e.into_inner());
        entries.retain(|e| e.0 != id);
    }
}
