//! Several host-mapped ranges lent at once, so a caller can fill them in parallel.
//!
//! A mapping's bytes are lent under its lock ([`DeviceMemory::with_mapped_mut`]), one range at
//! a time: threads filling buffers sub-allocated in one block would take turns. Here every
//! memory's lock is taken once (in address order, so two callers cannot deadlock), the ranges
//! are checked in bounds and pairwise disjoint, and the caller gets one `&mut [u8]` per range.

use std::sync::{Arc, MutexGuard};

use super::{Buffer, DeviceMemory, Mapping};
use crate::error::{Result, VkError};

/// `len` bytes at `offset` of `buffer` (bound to host-mapped memory): one destination of
/// [`with_mapped_ranges_mut`].
#[derive(Clone, Copy, Debug)]
pub struct MappedRange<'b> {
    pub buffer: &'b Buffer,
    pub offset: u64,
    pub len: usize,
}

/// Lends the bytes of every range of `ranges` to `fill` at once, as disjoint mutable slices in
/// the order given (the caller may fill them from several threads). Every range must lie in
/// its buffer, the buffer bound to host-mapped memory, and no two ranges may overlap in memory
/// (buffers sub-allocated in one block included): otherwise an error, and `fill` does not run.
/// The mapping locks of the memories involved are held while `fill` runs. The GPU must not be
/// using the ranges (as for [`Buffer::write_bytes`]).
pub fn with_mapped_ranges_mut<R>(
    ranges: &[MappedRange<'_>],
    fill: impl FnOnce(&mut [&mut [u8]]) -> R,
) -> Result<R> {
    // (memory, absolute start, length, index into `ranges`).
    let mut placed: Vec<(&Arc<DeviceMemory>, u64, u64, usize)> = Vec::with_capacity(ranges.len());
    for (i, r) in ranges.iter().enumerate() {
        r.buffer.check_range(r.offset, r.len)?;
        let (mem, base) = r.buffer.mapped()?;
        if !mem.is_mapped() {
            return Err(VkError::InvalidRequest(format!(
                "buffer {:?} is not bound to host-mapped memory",
                r.buffer.label
            )));
        }
        let start = base + r.offset;
        mem.check_range(start, r.len)?;
        placed.push((mem, start, r.len as u64, i));
    }
    let key = |m: &Arc<DeviceMemory>| Arc::as_ptr(m) as usize;
    placed.sort_unstable_by_key(|&(m, start, _, _)| (key(m), start));
    for w in placed.windows(2) {
        let ((ma, sa, la, ia), (mb, sb, _, ib)) = (w[0], w[1]);
        if key(ma) == key(mb) && sa + la > sb {
            return Err(VkError::InvalidRequest(format!(
                "mapped ranges {ia} and {ib} overlap (bytes {sa}..{} and {sb}.. of one memory)",
                sa + la
            )));
        }
    }
    // One lock per memory, taken in address order.
    let mut guards: Vec<(usize, MutexGuard<'_, Mapping>)> = Vec::new();
    for &(mem, _, _, _) in &placed {
        if guards.last().is_none_or(|(k, _)| *k != key(mem)) {
            guards.push((key(mem), mem.mapping()?));
        }
    }
    let mut slices: Vec<Option<&mut [u8]>> = (0..ranges.len()).map(|_| None).collect();
    let mut g = 0;
    for &(mem, start, len, i) in &placed {
        while guards[g].0 != key(mem) {
            g += 1;
        }
        let ptr = guards[g].1 .0;
        // SAFETY: the range lies inside the persistently mapped allocation (checked above);
        // the ranges are pairwise disjoint (checked above) and the mapping lock of their
        // memory is held until `fill` returns, so each slice is the only reference to its
        // bytes while it lives.
        let bytes =
            unsafe { std::slice::from_raw_parts_mut(ptr.add(start as usize), len as usize) };
        slices[i] = Some(bytes);
    }
    let mut slices: Vec<&mut [u8]> = slices.into_iter().flatten().collect();
    let out = fill(&mut slices);
    drop(slices);
    drop(guards);
    Ok(out)
}
