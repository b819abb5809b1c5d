//! The streamed skeleton's GPU instance table, described rather than copied: each TLAS's own
//! instances (a range of the view's table, usually the package's mapped section), then, for a
//! TLAS with proxy clusters, its proxy and marks instances. [`InstanceTable::write`] fills any
//! range of it straight into the upload ring, several threads at once. Copying the whole
//! table into a vector first cost island 0.63's start ~1 s (26M records, 1.7 GB) before the
//! ring copied it again.

use motu_abi::InstanceRecord;
use rayon::prelude::*;

use super::IDENTITY;

/// One TLAS's part of the table.
#[derive(Clone, Copy, Debug)]
struct Piece {
    /// First record of the piece in the table.
    out_first: usize,
    /// Its own instances: `view_first..view_first + view_count` of the view's table.
    view_first: usize,
    view_count: usize,
    /// The proxy BLAS record (its marks BLAS is the next one), or `None`: no clusters.
    proxy_blas: Option<u32>,
}

impl Piece {
    fn len(&self) -> usize {
        self.view_count + if self.proxy_blas.is_some() { 2 } else { 0 }
    }
}

/// Where the streamer keeps its large static tables (`MOTU_STREAM_TABLES`): host memory the GPU
/// reads over the bus (as it keeps meshes on a discrete GPU) is outside the VRAM budget, which
/// then has their bytes for structures. Where host memory counts against the budget (unified
/// memory) it changes nothing but where the bytes live. Opt-in until a device measures what
/// the trace pays for it: member tests read the instance table, the member table and the boxes
/// inside BLASes for every proxy box a ray enters; every hit reads its instance record.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum TableMemory {
    /// `device` (default): every table in VRAM.
    Device,
    /// `instances`: the instance table (64 bytes an instance) in host memory.
    Instances,
    /// `host`: the instance table, the clusters' member table and the boxes inside BLASes.
    Host,
}

impl TableMemory {
    /// `MOTU_STREAM_TABLES` (`device`, `instances`, `host`; anything else is `device`).
    pub fn from_env() -> TableMemory {
        match std::env::var("MOTU_STREAM_TABLES").as_deref() {
            Ok("instances") => TableMemory::Instances,
            Ok("host") => TableMemory::Host,
            _ => TableMemory::Device,
        }
    }

    /// Whether the instance table lives in host memory.
    pub fn instances_in_host(self) -> bool {
        self != TableMemory::Device
    }

    /// Whether the member table and the boxes inside BLASes live in host memory.
    pub fn proxy_tables_in_host(self) -> bool {
        self == TableMemory::Host
    }

    /// Host bytes these tables take for `view` at most: the instance table (its own instances
    /// and a proxy and marks instance a TLAS), a member a clustered instance (4 bytes) and the
    /// boxes inside streamable BLASes (with their index), each 16-byte aligned.
    pub fn host_bytes_bound(self, view: &motu_abi::HierarchyView<'_>) -> u64 {
        let record = std::mem::size_of::<InstanceRecord>();
        let instances = ((view.instances.len() + 2 * view.tlases.len()) * record) as u64;
        let proxy = || {
            let (index, boxes) =
                super::proxy_boxes::layout(view, |b| super::streamable(&view.blases[b]));
            let box_bytes = std::mem::size_of::<super::proxy_boxes::Box6>();
            (view.instances.len() * 4 + index.len() * 8 + boxes * box_bytes + 3 * 16) as u64
        };
        match self {
            TableMemory::Device => 0,
            TableMemory::Instances => instances,
            TableMemory::Host => instances + proxy(),
        }
    }
}

/// See the module docs.
#[derive(Debug, Default)]
pub(super) struct InstanceTable {
    pieces: Vec<Piece>,
    len: usize,
}

/// Records a worker fills at a time: large enough that a task's overhead vanishes, small
/// enough that a ring region splits over every thread.
const RECORDS_PER_TASK: usize = 16 * 1024;

impl InstanceTable {
    /// Appends the next TLAS's piece: `view_count` instances of the view from `view_first`,
    /// then, with `proxy_blas`, the proxy instance and the marks instance (BLAS record
    /// `proxy_blas + 1`). Returns the piece's first record in the table.
    pub fn push(&mut self, view_first: usize, view_count: usize, proxy_blas: Option<u32>) -> usize {
        let piece = Piece {
            out_first: self.len,
            view_first,
            view_count,
            proxy_blas,
        };
        self.len += piece.len();
        self.pieces.push(piece);
        piece.out_first
    }

    /// Records in the table.
    pub fn len(&self) -> usize {
        self.len
    }

    /// Writes records `first..first + out.len()` of the table into `out`, reading the TLASes'
    /// own instances from `view` (the view the pieces index).
    pub fn write(&self, view: &[InstanceRecord], first: usize, out: &mut [InstanceRecord]) {
        debug_assert!(first + out.len() <= self.len);
        // The piece holding `first`: the last one starting at or before it.
        let mut p = self
            .pieces
            .partition_point(|p| p.out_first <= first)
            .saturating_sub(1);
        let mut at = first;
        let mut done = 0;
        while done < out.len() {
            let piece = &self.pieces[p];
            let local = at - piece.out_first;
            let n = (piece.len() - local).min(out.len() - done);
            let dst = &mut out[done..done + n];
            // The piece's own instances, then its two extra records.
            let own = piece.view_count.saturating_sub(local).min(n);
            if own > 0 {
                let src = piece.view_first + local;
                dst[..own].copy_from_slice(&view[src..src + own]);
            }
            if let Some(proxy) = piece.proxy_blas {
                for (k, rec) in dst[own..].iter_mut().enumerate() {
                    let extra = (local + own + k - piece.view_count) as u32;
                    *rec = InstanceRecord {
                        tlas_from_blas: IDENTITY,
                        blas: proxy + extra,
                        flags: 0,
                        element: motu_abi::NONE_U32,
                        _pad: 0,
                    };
                }
            }
            done += n;
            at += n;
            p += 1;
        }
    }

    /// [`Self::write`] on rayon's threads, [`RECORDS_PER_TASK`] records a task.
    pub fn write_parallel(
        &self,
        view: &[InstanceRecord],
        first: usize,
        out: &mut [InstanceRecord],
    ) {
        out.par_chunks_mut(RECORDS_PER_TASK)
            .enumerate()
            .for_each(|(i, chunk)| self.write(view, first + i * RECORDS_PER_TASK, chunk));
    }
}

#[cfg(test)]
mod tests;
