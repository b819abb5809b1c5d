//! The streamed TLAS records' compaction (`shaders/tlas_compact.comp`, run by motu-gpu's
//! `stream/tlas_compact.rs`): a streamed TLAS keeps every instance's record on the GPU with
//! the BLAS id where the address goes; a rebuild writes, for each instance whose BLAS is
//! resident, the record with the BLAS's device address, in instance order.
//!
//! The order is the host path's: the instances are cut into chunks of
//! [`TLAS_COMPACT_CHUNK`], the host counts each chunk's resident instances and gives each
//! chunk its first output slot (prefix sums); a workgroup compacts one chunk, each of its
//! [`TLAS_COMPACT_GROUP`] invocations [`TLAS_COMPACT_PER_THREAD`] consecutive instances,
//! placed by an exclusive scan of the invocations' counts. No atomics: the output is
//! deterministic. [`compact_order`] is the same rule on the host (tested against the host
//! path's order).

use bytemuck::{Pod, Zeroable};

/// Invocations of one compaction workgroup.
pub const TLAS_COMPACT_GROUP: u32 = 256;
/// Consecutive instances one invocation compacts.
pub const TLAS_COMPACT_PER_THREAD: u32 = 4;
/// Instances of one chunk (one workgroup).
pub const TLAS_COMPACT_CHUNK: u32 = TLAS_COMPACT_GROUP * TLAS_COMPACT_PER_THREAD;

/// `tlas_compact.comp`'s push constants: one dispatch per TLAS, one workgroup per chunk.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
#[repr(C)]
pub struct TlasCompactPush {
    /// The TLAS's kept records: 64 bytes per instance, the BLAS id in the address's low word.
    pub kept: u64,
    /// The instance buffer the build reads (records of 64 bytes).
    pub dst: u64,
    /// Per chunk of this TLAS: the index of its first record in `dst` (u32).
    pub chunk_first: u64,
    /// Per BLAS id: its device address, 0 where not resident (u64).
    pub blas_addresses: u64,
    /// The TLAS's instances (records in `kept`).
    pub instance_count: u32,
    pub _pad: [u32; 3],
}

/// Per chunk of `resident` counts: the first output slot (exclusive prefix sums), and the
/// total.
pub fn chunk_firsts(counts: &[u32]) -> (Vec<u32>, u32) {
    let mut at = 0u32;
    let firsts = counts
        .iter()
        .map(|&n| {
            let f = at;
            at += n;
            f
        })
        .collect();
    (firsts, at)
}

/// The compaction on the host, exactly as the shader does it: for `resident` (one flag per
/// instance), per output slot the instance written there.
pub fn compact_order(resident: &[bool]) -> Vec<u32> {
    let chunk = TLAS_COMPACT_CHUNK as usize;
    let per = TLAS_COMPACT_PER_THREAD as usize;
    let counts: Vec<u32> = resident
        .chunks(chunk)
        .map(|c| c.iter().filter(|&&r| r).count() as u32)
        .collect();
    let (firsts, total) = chunk_firsts(&counts);
    let mut out = vec![u32::MAX; total as usize];
    for (g, &first) in firsts.iter().enumerate() {
        // Each invocation's count, then an exclusive scan (the shader's shared-memory scan).
        let base = g * chunk;
        let n_of = |t: usize| {
            (0..per)
                .filter(|k| resident.get(base + t * per + k).copied().unwrap_or(false))
                .count() as u32
        };
        let mut scan = 0u32;
        for t in 0..TLAS_COMPACT_GROUP as usize {
            let mut at = first + scan;
            for k in 0..per {
                let i = base + t * per + k;
                if resident.get(i).copied().unwrap_or(false) {
                    out[at as usize] = i as u32;
                    at += 1;
                }
            }
            scan += n_of(t);
        }
    }
    out
}

#[cfg(test)]
mod tests;
