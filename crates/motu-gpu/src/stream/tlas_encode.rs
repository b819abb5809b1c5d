//! One instance record of a streamed TLAS (`VkAccelerationStructureInstanceKHR`), as the host
//! writes it (`tlas_records.rs`) and as the GPU keeps it for the compaction (`tlas_compact.rs`):
//! a leaf both use, so neither uses the other for it.

use motu_abi::{HierarchyView, InstanceRecord, BLAS_AABBS, FLAG_NEEDS_ANY_HIT};

use super::TRIANGLE_MASK;
use motu_vk::InstanceHit;

use crate::scene::{encode_instance, set_instance_mask};

/// Bytes of one encoded instance record (`VkAccelerationStructureInstanceKHR`).
pub(super) const RECORD_BYTES: usize = 64;

/// The record of `inst`, index `index` in its TLAS (the custom index the shaders read),
/// referencing `addr` (its resident BLAS, or a persistent TLAS's placeholder): flags and shader
/// offset from its BLAS's kind, triangle instances under [`TRIANGLE_MASK`].
pub(super) fn instance_record(
    view: &HierarchyView<'_>,
    inst: &InstanceRecord,
    index: u32,
    addr: u64,
) -> [u8; RECORD_BYTES] {
    let aabbs = view.blases[inst.blas as usize].kind == BLAS_AABBS;
    let mut enc = encode_instance(
        &inst.tlas_from_blas,
        aabbs,
        inst.flags & FLAG_NEEDS_ANY_HIT != 0,
        addr,
        index,
    );
    if !aabbs {
        set_instance_mask(&mut enc, TRIANGLE_MASK);
    }
    enc
}

/// The record of `inst` (index `index` in its TLAS) as kept on the GPU (`tlas_compact.rs`):
/// [`instance_record`]'s with the BLAS id where the address goes (the compaction writes the
/// address, or leaves the instance out where its BLAS is not resident).
pub(super) fn kept_record(
    view: &HierarchyView<'_>,
    inst: &InstanceRecord,
    index: u32,
) -> [u8; RECORD_BYTES] {
    // Any non-zero address: the mask is an active instance's.
    let mut enc = instance_record(view, inst, index, 1);
    enc[56..64].copy_from_slice(&u64::from(inst.blas).to_le_bytes());
    enc
}

/// The record of a streamed TLAS's proxy (`marks` false) or marks BLAS at `addr`, whose GPU
/// BLAS record is `blas_record`: they follow the TLAS's own records; only probe passes' rays
/// see the marks. Their hit group is the proxies' own (`InstanceHit::Proxy`), whose shaders
/// read the PI record through the custom index, the BLAS record (an intersection shader
/// cannot read the payload's walked TLAS).
pub(super) fn tail_record(blas_record: u32, marks: bool, addr: u64) -> [u8; RECORD_BYTES] {
    let mut inst =
        motu_vk::encode_instance(&super::IDENTITY, InstanceHit::Proxy, addr, blas_record);
    if marks {
        set_instance_mask(&mut inst, super::MARKS_MASK);
    }
    inst
}
