//! The sides of the global memory barriers commands are ordered with.

/// One side of a global memory barrier: the pipeline stages and the accesses it orders
/// (`conv.rs` spells them in Vulkan flags).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MemoryScope {
    /// Every stage, every write before / every read and write after.
    All,
    /// Transfer writes (uploads and copies).
    TransferWrites,
    /// What acceleration-structure builds read (geometry, instances, other structures).
    BuildReads,
}
