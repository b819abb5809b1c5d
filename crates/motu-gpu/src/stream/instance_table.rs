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

/// `MOTU_STREAM_INSTANCE_TABLE=host`: the streamer keeps the instance table in host memory the
/// GPU reads over the bus (as it keeps meshes on a discrete GPU), outside the VRAM budget,
/// which then has its 64 bytes an instance for structures. Opt-in until a device measures
/// what the trace pays for it (member tests and every hit read the table); `device` (the
/// default) keeps it in VRAM. Where host memory counts against the budget (unified memory)
/// it changes nothing but where the bytes live.
pub(super) fn instance_table_in_host() -> bool {
    std::env::var("MOTU_STREAM_INSTANCE_TABLE").is_ok_and(|v| v == "host")
}

/// Bytes of the streamer's instance table for `view` at most (its own instances and a proxy
/// and marks instance a TLAS).
pub(super) fn instance_table_bytes_bound(view: &motu_abi::HierarchyView<'_>) -> u64 {
    ((view.instances.len() + 2 * view.tlases.len()) * std::mem::size_of::<InstanceRecord>()) as u64
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
