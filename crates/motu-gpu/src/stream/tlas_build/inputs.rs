//! A TLAS rebuild's inputs: the proxies' box buffer and uploads, their build sizes and
//! geometry, the instance records' buffer (both [`super::TlasBuild`] paths use them).

use motu_abi::PiRecord;
use motu_alloc::{AllocKind, BuildSize, MemoryClass};
use motu_vk::{AsGeometry, BufferUsage, Context, GpuHeap, HeapBuffer};

use super::{ProxyItem, ProxyPlan};
use crate::error::Result;
use crate::scene::{aabbs_geometry, BuildOptions};
use crate::stream::buffers::staging_released;
use crate::stream::topology::{proxy_blas_record, proxy_pi};
use crate::stream::StreamingRenderer;

/// Queues the planned proxies' boxes into `buf` (in plan order), and their TLASes' PI slots
/// and marks records, into the staging ring (not flushed; abandoned on failure: the copies
/// must not outlive `buf`).
pub(super) fn queue_proxy_uploads(
    ctx: &Context,
    r: &mut StreamingRenderer<'_>,
    plan: &ProxyPlan,
    buf: &HeapBuffer,
) -> Result<()> {
    let view = r.view;
    let pis_buf = r.gpu.pis();
    let blases_buf = r.gpu.blases();
    let up = r.up.as_mut().ok_or_else(staging_released)?;
    let mut at = 0u64;
    for o in &plan.orders {
        let t = o.tlas as usize;
        let clusters = r.topo.clusters(t);
        let order = &o.order;
        let (base, marks_blas) = r.topo.proxy_slots(t);
        let marks = proxy_blas_record(
            &view.tlases[t],
            base + o.non_resident,
            order.len() as u32 - o.non_resident,
        );
        let marks_offset =
            u64::from(marks_blas) * std::mem::size_of::<motu_abi::BlasRecord>() as u64;
        // Written by the pool: a piece's boxes and PI records were a serial loop on the
        // rebuild's critical path.
        let uploaded = up
            .upload_with(ctx, buf, at, order.len(), |k| {
                clusters[order[k] as usize].bounds
            })
            .and_then(|()| {
                up.upload_with(
                    ctx,
                    pis_buf,
                    u64::from(base) * std::mem::size_of::<PiRecord>() as u64,
                    order.len(),
                    |k| proxy_pi(&clusters[order[k] as usize]),
                )
            })
            .and_then(|()| up.upload(ctx, blases_buf, marks_offset, bytemuck::bytes_of(&marks)));
        if let Err(e) = uploaded {
            // Copies queued for the box buffer must not outlive it.
            up.abandon();
            return Err(e);
        }
        at += order.len() as u64 * 24;
    }
    Ok(())
}

/// The build sizes of the planned proxy and marks BLASes (`rb`'s flags).
pub(super) fn proxy_sizes(
    ctx: &Context,
    plan: &ProxyPlan,
    rb: &BuildOptions,
) -> Result<Vec<BuildSize>> {
    plan.items
        .iter()
        .map(|item| {
            let sz = ctx.blas_build_sizes(
                &[motu_vk::BlasGeometry::Aabbs {
                    aabb_count: item.box_count,
                    opaque: false,
                }],
                rb.blas_flags(),
            )?;
            Ok(BuildSize {
                result_bytes: sz.acceleration_structure_size_bytes,
                scratch_bytes: sz.build_scratch_size_bytes,
            })
        })
        .collect()
}

/// The buffer the planned proxies' boxes are uploaded to (24 bytes a box), read by their builds.
pub(super) fn alloc_box_buffer(heap: &mut GpuHeap, plan: &ProxyPlan) -> Result<HeapBuffer> {
    heap.alloc_buffer(
        "proxy-aabbs",
        u64::from(plan.box_count) * 24,
        BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT | BufferUsage::TRANSFER_DST,
        AllocKind::Geometry,
        MemoryClass::DeviceLocal,
        16,
    )
    .map_err(Into::into)
}

/// The buffer of a rebuild's instance records (`total_bytes`), written by the host's copies
/// and the GPU records' pass, read by the TLAS builds.
pub(super) fn alloc_instance_buffer(heap: &mut GpuHeap, total_bytes: u64) -> Result<HeapBuffer> {
    heap.alloc_buffer(
        "stream-tlas-instances",
        total_bytes.max(64),
        BufferUsage::ACCELERATION_STRUCTURE_BUILD_INPUT
            | BufferUsage::TRANSFER_DST
            | BufferUsage::STORAGE
            | BufferUsage::DEVICE_ADDRESS,
        AllocKind::InstanceBuffer,
        MemoryClass::DeviceLocal,
        16,
    )
    .map_err(Into::into)
}

/// Proxy or marks BLAS `item`'s geometry over the box buffer at device address `base`.
pub(super) fn proxy_geometry(base: u64, item: &ProxyItem) -> (Vec<AsGeometry>, Vec<u32>) {
    (
        vec![aabbs_geometry(base + u64::from(item.first_box) * 24, false)],
        vec![item.box_count],
    )
}
