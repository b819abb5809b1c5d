//! Small helpers over the compiled tables, shared by emission, splits and finalisation.

use crate::{xform, CompileError};
use motu_abi::{BlasRecord, InstanceRecord};
use motu_scene::Aabb;

/// Checked conversion of a table length to the next 32-bit id.
pub(crate) fn next_id(len: usize, what: &'static str) -> Result<u32, CompileError> {
    u32::try_from(len)
        .ok()
        .filter(|&id| id != u32::MAX)
        .ok_or(CompileError::TooMany {
            what,
            count: len as u64,
        })
}

pub(crate) fn set_bounds(min: &mut [f32; 3], max: &mut [f32; 3], b: &Aabb) {
    *min = b.min;
    *max = b.max;
}

/// An instance's bounds in its TLAS's space (its BLAS's box, transformed).
pub(crate) fn instance_bounds(blases: &[BlasRecord], inst: &InstanceRecord) -> Aabb {
    let b = &blases[inst.blas as usize];
    xform::aabb_from_record(b.bounds_min, b.bounds_max)
        .transformed(&xform::from_array(&inst.tlas_from_blas))
}
