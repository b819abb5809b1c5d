//! A writer's open chunk (its bytes, page-aligned when writing direct) and what an append
//! puts in it.

use crate::{ChunkId, PackageError};

pub(super) struct OpenChunk {
    pub(super) id: ChunkId,
    /// `pad` zero bytes, then the chunk's bytes: with direct writes the pad puts them on a
    /// page boundary, so the sink writes them in place (`sink.rs`); 0 otherwise.
    pub(super) data: Vec<u8>,
    pub(super) pad: usize,
}

impl OpenChunk {
    /// The chunk's bytes so far.
    pub(super) fn bytes(&self) -> &[u8] {
        &self.data[self.pad..]
    }

    /// How many bytes the chunk holds so far.
    pub(super) fn len(&self) -> usize {
        self.data.len() - self.pad
    }
}

/// What an append puts in its chunk: bytes to copy, or a fill that pushes them itself.
pub(super) enum Put<'a> {
    Bytes(&'a [u8]),
    Fill(&'a mut dyn FnMut(&mut Vec<u8>)),
}

impl Put<'_> {
    /// Pushes the bytes onto `out`; returns how many it pushed.
    pub(super) fn onto(&mut self, out: &mut Vec<u8>) -> u64 {
        let start = out.len();
        match self {
            Put::Bytes(bytes) => out.extend_from_slice(bytes),
            Put::Fill(fill) => fill(out),
        }
        (out.len() - start) as u64
    }
}

pub(super) fn fill_error(pushed: u64, promised: u64) -> PackageError {
    PackageError::InvalidArgument(format!(
        "an append's fill pushed {pushed} bytes of the {promised} it promised"
    ))
}
