//! Whether a budget holds the whole scene: then `render --stream` renders the full build,
//! which is never slower than streaming it (no proxy tables, no passes, no cache stores).
//!
//! The test is an upper bound of the full build's peak, from the device's build sizes before
//! compaction (the full build compacts, so it holds less): a budget at or above it holds the
//! full build with room to spare, and a budget below it streams as before. The bound is
//! conservative on purpose: a wrong "fits" would cost a failed full build and then the stream.

use motu_abi::{HierarchyView, BLAS_AABBS, BLAS_TRIANGLES};
use motu_vk::{AsBuildFlags, BlasBuild, BlasGeometry, Context};

use crate::error::Result;
use crate::scene::{full_build_overhead, streamed_mesh_bytes, usable_budget_bytes};

/// The outcome of [`full_build_fits`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FullBuildFit {
    /// The budget the full build would get (`--vram-budget`, lowered to what the device has).
    pub budget_bytes: u64,
    /// An upper bound of the full build's peak at the image size (see the module docs).
    pub upper_bytes: u64,
}

impl FullBuildFit {
    /// The whole scene fits: the full build renders it.
    pub fn fits(&self) -> bool {
        self.upper_bytes <= self.budget_bytes
    }
}

fn align(v: u64, a: u64) -> u64 {
    v.div_ceil(a) * a
}

/// The full build's budget on `ctx` under `user_budget_bytes` (`u64::MAX`: none) and an upper
/// bound of its peak for `view` at `width × height` with BLASes built as `blas_build`: every
/// mesh with its shading attributes, every BLAS and TLAS uncompacted, every instance record,
/// the largest BLAS and TLAS build scratch, node and shading tables with every texel, the
/// frame, the staging ring and allocator slack (`full_build_overhead`).
pub fn full_build_fits(
    ctx: &Context,
    view: &HierarchyView<'_>,
    width: u32,
    height: u32,
    user_budget_bytes: u64,
    blas_build: BlasBuild,
) -> Result<FullBuildFit> {
    let blas_flags = blas_build.flags();
    let budget_bytes = usable_budget_bytes(ctx, user_budget_bytes)?;
    let as_align = |v: u64| align(v, 256);
    let tables: u64 = [
        std::mem::size_of_val(view.tlases),
        std::mem::size_of_val(view.instances),
        std::mem::size_of_val(view.blases),
        std::mem::size_of_val(view.geometries),
        std::mem::size_of_val(view.pis),
        std::mem::size_of_val(view.lod_selectors),
        std::mem::size_of_val(view.lod_levels),
        std::mem::size_of_val(view.meshes),
        std::mem::size_of_val(view.materials),
    ]
    .iter()
    .map(|&b| as_align(b as u64))
    .sum();
    let shading = crate::shading::table_bytes(view, crate::shading::Texels::Resident)
        + as_align(std::mem::size_of_val(view.texels) as u64);
    let meshes: u64 = view.meshes.iter().map(streamed_mesh_bytes).sum();
    let mut structures = 0u64;
    let mut scratch_max = 0u64;
    for r in view.blases {
        let shape: Vec<BlasGeometry> = match r.kind {
            BLAS_TRIANGLES => super::floor::triangle_shape(view, r),
            BLAS_AABBS => vec![BlasGeometry::Aabbs {
                aabb_count: r.item_count,
                opaque: false,
            }],
            _ => continue,
        };
        if r.item_count == 0 {
            continue;
        }
        let s = ctx.blas_build_sizes(&shape, blas_flags)?;
        structures += as_align(s.acceleration_structure_size_bytes);
        scratch_max = scratch_max.max(align(s.build_scratch_size_bytes, 256));
        if r.kind == BLAS_AABBS {
            // The boxes the build reads (24 bytes each).
            structures += align(u64::from(r.item_count) * 24, 16);
        }
    }
    for t in view.tlases {
        let s = ctx.tlas_build_sizes(t.instance_count, AsBuildFlags::tlas(true))?;
        structures += as_align(s.acceleration_structure_size_bytes);
        scratch_max = scratch_max.max(align(s.build_scratch_size_bytes, 256));
    }
    let instance_records = view.instances.len() as u64 * 64;
    let resident = tables + shading + meshes + structures + instance_records + scratch_max;
    let upper_bytes = resident + full_build_overhead(resident, width, height).total_bytes;
    Ok(FullBuildFit {
        budget_bytes,
        upper_bytes,
    })
}
