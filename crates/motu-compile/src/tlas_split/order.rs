//! Reordering a split's instance table: origins tagged and the table put back in its order,
//! a TLAS's range moved to the tail, each a piece at a time, so that a mapped table
//! ([`InstanceTable::in_file`]) is never resident whole.

use crate::instance_map::RELEASE_EVERY_RECORDS;
use crate::tables::next_id;
use crate::{CompileError, CompiledScene, InstanceTable};
use motu_abi::{InstanceRecord, NONE_U32};
use std::path::Path;

/// Each instance remembers where it came from (its index + 1 in `_pad`, always 0 in a package)
/// so that [`StreamSplit::stored`] can store the split as a map.
pub(super) fn tag_origins(instances: &mut InstanceTable) -> Result<(), CompileError> {
    if instances.len() >= NONE_U32 as usize {
        return Err(CompileError::TooMany {
            what: "instances",
            count: instances.len() as u64,
        });
    }
    for_each_released(instances, |i, inst| inst._pad = i as u32 + 1);
    Ok(())
}

/// `f(index, record)` over every record of `table`, a piece at a time (a mapped table's pages
/// dropped behind).
pub(crate) fn for_each_released(
    table: &mut InstanceTable,
    mut f: impl FnMut(usize, &mut InstanceRecord),
) {
    let mut at = 0;
    while at < table.len() {
        let end = (at + RELEASE_EVERY_RECORDS).min(table.len());
        for (k, r) in table[at..end].iter_mut().enumerate() {
            f(at + k, r);
        }
        table.release_range(at, end);
        at = end;
    }
}
/// The `n` tagged instances of a split back in their original order, untagged: the split's
/// own AABB-BLAS instances and copies of shared ranges dropped, then each record swapped to
/// its index (every origin is there once, so each swap places one record for good).
pub(super) fn untag_in_order(
    mut instances: Vec<InstanceRecord>,
    n: usize,
) -> Result<Vec<InstanceRecord>, CompileError> {
    let mut seen = vec![false; n];
    instances.retain(|r| {
        let t = r._pad as usize;
        let keep = (1..=n).contains(&t) && !seen[t - 1];
        if keep {
            seen[t - 1] = true;
        }
        keep
    });
    if instances.len() != n {
        return Err(CompileError::Internal(format!(
            "the stream split kept {} of {n} instances",
            instances.len()
        )));
    }
    for i in 0..n {
        loop {
            let t = instances[i]._pad as usize - 1;
            if t == i {
                break;
            }
            instances.swap(i, t);
        }
    }
    for r in &mut instances {
        r._pad = 0;
    }
    instances.shrink_to_fit();
    Ok(instances)
}

/// [`untag_in_order`] of a parked split table whose origins are `source` (index per record,
/// `NONE_U32` for the split's own): each origin's first record in the split's order put in its
/// place, reading the map in order and dropping its pages behind.
pub(super) fn gather_in_order(
    map: &crate::instance_map::InstanceMap,
    source: &[u32],
    n: usize,
) -> Result<Vec<InstanceRecord>, CompileError> {
    use crate::instance_map::RELEASE_EVERY_RECORDS;
    let mut out = vec![InstanceRecord::default(); n];
    let mut seen = vec![false; n];
    let mut placed = 0usize;
    for (j, (r, &s)) in map.records().iter().zip(source).enumerate() {
        if j > 0 && j % RELEASE_EVERY_RECORDS == 0 {
            // A failed drop leaves pages resident; the records read the same either way.
            let _ = map.release_range(j - RELEASE_EVERY_RECORDS, j);
        }
        let s = s as usize;
        if s < n && !seen[s] {
            seen[s] = true;
            out[s] = InstanceRecord { _pad: 0, ..*r };
            placed += 1;
        }
    }
    let _ = map.release_pages();
    if placed != n {
        return Err(CompileError::Internal(format!(
            "the stream split kept {placed} of {n} instances"
        )));
    }
    Ok(out)
}
/// Makes TLAS `t`'s instance range the table's tail, which [`split_tlas`] needs: rotated there
/// (later TLASes' ranges shifted down), or copied when another TLAS shares a part of it.
pub(super) fn move_range_to_tail(
    out: &mut CompiledScene,
    t: u32,
    scratch: Option<&Path>,
) -> Result<(), CompileError> {
    let rec = out.tlases[t as usize];
    let (base, count) = (rec.instance_base as usize, rec.instance_count as usize);
    let (end, len) = (base + count, out.instances.len());
    if end == len {
        return Ok(());
    }
    let shared = out.tlases.iter().enumerate().any(|(u, r)| {
        let (b, n) = (r.instance_base as usize, r.instance_count as usize);
        u != t as usize && n > 0 && b < end && base < b + n
    });
    if shared {
        next_id(len + count, "instances")?;
        out.instances.extend_from_within(base..end)?;
        out.tlases[t as usize].instance_base = next_id(len, "instances")?;
        return Ok(());
    }
    rotate_to_tail(&mut out.instances, base, count, scratch)?;
    for (u, r) in out.tlases.iter_mut().enumerate() {
        if u != t as usize && r.instance_base as usize >= end {
            r.instance_base -= count as u32;
        }
    }
    out.tlases[t as usize].instance_base = next_id(len - count, "instances")?;
    Ok(())
}

/// `table[base..].rotate_left(count)`: records `base..base + count` moved to the end. A mapped
/// table's range waits in an unnamed file in `scratch` (else on the heap) while the rest moves
/// down a piece at a time, so no more of the table is resident than a piece.
pub(crate) fn rotate_to_tail(
    table: &mut InstanceTable,
    base: usize,
    count: usize,
    scratch: Option<&Path>,
) -> Result<(), CompileError> {
    let len = table.len();
    let (Some(dir), true) = (scratch, table.is_mapped()) else {
        table[base..].rotate_left(count);
        return Ok(());
    };
    use std::io::{Read, Seek, SeekFrom};
    let err = |source| CompileError::Scratch {
        dir: dir.to_path_buf(),
        source,
    };
    let mut file =
        crate::instance_map::write_scratch_then(&table[base..base + count], dir, &mut |b, e| {
            table.release_range(base + b, base + e)
        })
        .map_err(err)?;
    table.copy_within_released(base + count..len, base);
    file.seek(SeekFrom::Start(0)).map_err(err)?;
    let mut at = len - count;
    while at < len {
        let end = (at + RELEASE_EVERY_RECORDS).min(len);
        file.read_exact(bytemuck::cast_slice_mut(&mut table[at..end]))
            .map_err(err)?;
        table.release_range(at, end);
        at = end;
    }
    Ok(())
}
