//! Per TLAS, the BLASes its instances place, each once with its instance count: what
//! `motu report` walks instead of every instance (the cost graph's edges), and the table a
//! package stores (`blas_counts` section, FORMAT.md) so a report of millions of instances reads
//! it instead of counting them again.
//!
//! An entry is a (BLAS, element) pair of one TLAS with the number of its instances that place
//! that BLAS with that element tag (root placements carry their element; below the root the tag
//! is `NONE`), so a TLAS of a million instances of fifty BLASes is fifty entries. Entries of a
//! TLAS are ascending by (BLAS, element). Deterministic: the same view gives the same table,
//! stored or made.

use motu_abi::blob::{BlobReader, BlobWriter};
use motu_abi::HierarchyView;
use rayon::prelude::*;

/// One (BLAS, element) pair of a TLAS and how many of its instances place it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C)]
pub struct BlasCount {
    pub blas: u32,
    /// The instances' element tag (`NONE` below the root).
    pub element: u32,
    pub count: u64,
}

/// [`BlasCount`]s of every TLAS of a view: TLAS `t`'s are `entries[first[t]..first[t + 1]]`.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BlasCounts {
    /// `tlas_count + 1` offsets into `entries`.
    pub first: Vec<u64>,
    pub entries: Vec<BlasCount>,
}

/// TLASes of more instances than this are counted in parallel pieces.
const PIECE_INSTANCES: usize = 1 << 16;

/// Pieces a thread counts between two `after_batch` calls of [`BlasCounts::of_then`] (16 MiB
/// of records a thread).
const BATCH_PIECES: usize = 4;

impl BlasCounts {
    /// Counts every TLAS's instances (parallel over TLASes and over large TLASes' pieces).
    /// O(instances / threads + entries · log).
    pub fn of(view: &HierarchyView<'_>) -> BlasCounts {
        Self::of_then(view, &mut || {})
    }

    /// [`BlasCounts::of`] read a batch of instances at a time (small TLASes together, a large
    /// one in groups of pieces, at most [`BATCH_PIECES`] pieces a thread), calling
    /// `after_batch` once each batch is counted: the import drops the pages of a mapped
    /// instance table read so far there (issue 48 item 1). The same table.
    pub fn of_then(view: &HierarchyView<'_>, after_batch: &mut dyn FnMut()) -> BlasCounts {
        let count_small = |rec: &motu_abi::TlasRecord| {
            let instances = view.instances.get(rec.instance_range()).unwrap_or(&[]);
            count_sorted(instances.iter().map(|i| (i.blas, i.element, 1)).collect())
        };
        let batch = rayon::current_num_threads().max(1) * BATCH_PIECES * PIECE_INSTANCES;
        let count = |t: usize| view.tlases[t].instance_count as usize;
        let n = view.tlases.len();
        let mut per_tlas: Vec<Vec<BlasCount>> = Vec::with_capacity(n);
        let mut t = 0;
        while t < n {
            // Small TLASes, as many as the batch holds.
            let (mut end, mut instances) = (t, 0usize);
            while end < n && count(end) <= PIECE_INSTANCES && instances + count(end) <= batch {
                instances += count(end);
                end += 1;
            }
            if end > t {
                per_tlas.par_extend(view.tlases[t..end].par_iter().map(count_small));
                after_batch();
                t = end;
                continue;
            }
            // A large TLAS: pieces counted in parallel a group at a time, then merged.
            let instances = view
                .instances
                .get(view.tlases[t].instance_range())
                .unwrap_or(&[]);
            let mut pieces: Vec<BlasCount> = Vec::new();
            for group in instances.chunks(batch) {
                pieces.par_extend(group.par_chunks(PIECE_INSTANCES).flat_map_iter(|piece| {
                    count_sorted(piece.iter().map(|i| (i.blas, i.element, 1)).collect())
                }));
                after_batch();
            }
            per_tlas.push(count_sorted(
                pieces
                    .into_iter()
                    .map(|e| (e.blas, e.element, e.count))
                    .collect(),
            ));
            t += 1;
        }
        let mut first = Vec::with_capacity(per_tlas.len() + 1);
        let mut entries = Vec::with_capacity(per_tlas.iter().map(Vec::len).sum());
        for e in per_tlas {
            first.push(entries.len() as u64);
            entries.extend(e);
        }
        first.push(entries.len() as u64);
        BlasCounts { first, entries }
    }

    /// TLAS `t`'s entries (empty past the table).
    pub fn tlas(&self, t: usize) -> &[BlasCount] {
        match (self.first.get(t), self.first.get(t + 1)) {
            (Some(&a), Some(&b)) => self.entries.get(a as usize..b as usize).unwrap_or(&[]),
            _ => &[],
        }
    }

    /// Whether this table can be `view`'s: one entry list per TLAS, each adding up to its
    /// TLAS's instance count, every BLAS in range, entries ascending. O(entries). (A stored
    /// table is the import's own count of the package's tables, covered by the section's
    /// checksum; this guards against a table of another package or a damaged one.)
    pub fn fits(&self, view: &HierarchyView<'_>) -> bool {
        if self.first.len() != view.tlases.len() + 1 {
            return false;
        }
        view.tlases.iter().enumerate().all(|(t, rec)| {
            let (a, b) = (self.first[t], self.first[t + 1]);
            if a > b || b > self.entries.len() as u64 {
                return false;
            }
            let e = &self.entries[a as usize..b as usize];
            let total = e
                .iter()
                .try_fold(0u64, |s, c| s.checked_add(c.count).filter(|_| c.count > 0));
            total == Some(u64::from(rec.instance_count))
                && e.iter().all(|c| (c.blas as usize) < view.blases.len())
                && e.windows(2)
                    .all(|w| (w[0].blas, w[0].element) < (w[1].blas, w[1].element))
        })
    }
}

/// Sorts (BLAS, element, count) triples and merges equal pairs.
fn count_sorted(mut v: Vec<(u32, u32, u64)>) -> Vec<BlasCount> {
    v.sort_unstable_by_key(|&(b, e, _)| (b, e));
    let mut out: Vec<BlasCount> = Vec::new();
    for (blas, element, count) in v {
        match out.last_mut() {
            Some(l) if l.blas == blas && l.element == element => l.count += count,
            _ => out.push(BlasCount {
                blas,
                element,
                count,
            }),
        }
    }
    out
}

/// The `blas_counts` section's first bytes (FORMAT.md): the name and the version.
pub const SECTION_MAGIC: &[u8; 16] = b"motu bcounts v1\0";

/// The `blas_counts` section (FORMAT.md): the instance and TLAS counts of the view it was made
/// for, then the offsets and the entries.
pub fn encode_section(view: &HierarchyView<'_>, t: &BlasCounts) -> Vec<u8> {
    let mut w = BlobWriter::new(
        SECTION_MAGIC,
        24 + std::mem::size_of_val(&t.first[..]) + std::mem::size_of_val(&t.entries[..]),
    );
    w.u64(view.instances.len() as u64)
        .u64(view.tlases.len() as u64)
        .u64(t.entries.len() as u64)
        .pods(&t.first)
        .pods(&t.entries);
    w.finish()
}

/// Reads what [`encode_section`] wrote for `view`; `None` for another magic (another version),
/// a cut or long section, or a table that does not fit `view` ([`BlasCounts::fits`]).
pub fn decode_section(bytes: &[u8], view: &HierarchyView<'_>) -> Option<BlasCounts> {
    let mut r = BlobReader::new(bytes, SECTION_MAGIC)?;
    let instances = r.u64()?;
    let n_tlases = usize::try_from(r.u64()?).ok()?;
    let n_entries = usize::try_from(r.u64()?).ok()?;
    if instances != view.instances.len() as u64 || n_tlases != view.tlases.len() {
        return None;
    }
    let need = (n_tlases.checked_add(1)?)
        .checked_mul(8)?
        .checked_add(n_entries.checked_mul(std::mem::size_of::<BlasCount>())?)?;
    if need != r.remaining() {
        return None;
    }
    let first: Vec<u64> = r.pods(n_tlases + 1)?;
    let entries: Vec<BlasCount> = r.pods(n_entries)?;
    r.finish()?;
    let t = BlasCounts { first, entries };
    t.fits(view).then_some(t)
}

#[cfg(test)]
mod tests;
