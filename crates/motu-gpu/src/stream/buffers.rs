//! Per-frame buffers (parameters, AOV, colour, stats, streaming lists, readback).

use motu_alloc::{AllocKind, MemoryClass};
use motu_vk::{BufferUsage, GpuHeap, HeapBuffer};

use super::params::{StreamParams, CARRY_BYTES};
use crate::error::{GpuError, Result};
use crate::render::STAT_WORDS;

/// The error of a step that needs the staging ring after the renderer released it.
pub(super) fn staging_released() -> GpuError {
    GpuError::InvalidRequest("streaming: staging ring released".into())
}

/// Buffers of one frame, freed at its end.
pub(super) struct FrameBuffers {
    pub(super) params: HeapBuffer,
    pub(super) stream: HeapBuffer,
    pub(super) aov: HeapBuffer,
    pub(super) rgba: HeapBuffer,
    pub(super) stats: HeapBuffer,
    pub(super) incomplete: HeapBuffer,
    pub(super) requests: HeapBuffer,
    pub(super) carry: HeapBuffer,
    pub(super) pixel_list: HeapBuffer,
    pub(super) readback: HeapBuffer,
    /// Items a row of a pass's ray-tracing launch holds: the image's width (see
    /// [`launch_dims`]).
    pub(super) launch_row_items: u32,
}

/// The widest launch row: an image wider than this folds its rows.
const MAX_LAUNCH_ROW_ITEMS: u32 = 4096;

/// The ray-tracing launch of a pass's `n` items (the image's pixels in row order, then a
/// list), folded into rows of `row_items` (the image's width): the driver hands a warp a
/// block of neighbouring launch ids, which are then neighbouring pixels of neighbouring image
/// rows, as in the full build's 2-D launch. Rows of 4096 put a block's rows 6.4 image rows
/// apart at 640×360: H100, island 0.3 all resident, a streamed trace 83.4–83.9 → 57.2 ms.
pub(super) fn launch_dims(n: u32, row_items: u32) -> [u32; 2] {
    let width = n.clamp(1, row_items.clamp(1, MAX_LAUNCH_ROW_ITEMS));
    [width, n.div_ceil(width).max(1)]
}

impl FrameBuffers {
    pub(super) fn release(self, heap: &mut GpuHeap) {
        for b in [
            self.params,
            self.stream,
            self.aov,
            self.rgba,
            self.stats,
            self.incomplete,
            self.requests,
            self.carry,
            self.pixel_list,
            self.readback,
        ] {
            heap.free(b);
        }
    }
}

type Spec = (&'static str, u64, BufferUsage, AllocKind, MemoryClass);

/// The frame's buffers: label, bytes, usage, kind, memory class.
fn frame_buffer_specs(pixels: u64, guard_count: u64, items: u64, params_size: u64) -> [Spec; 10] {
    let dev = BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS | BufferUsage::TRANSFER_SRC;
    let host = BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS;
    let stamps_bytes = (items * 4).div_ceil(16) * 16;
    // The count, the packed pixels, then what each waits for (`passes.rs`).
    let inc_bytes = 4 + 8 * pixels;
    let readback_bytes =
        (2 * stamps_bytes + inc_bytes).div_ceil(16) * 16 + pixels * 20 + (STAT_WORDS as u64) * 4;
    [
        (
            "frame-params",
            params_size,
            host,
            AllocKind::Other,
            MemoryClass::HostVisible,
        ),
        (
            "stream-params",
            std::mem::size_of::<StreamParams>() as u64,
            host,
            AllocKind::Other,
            MemoryClass::HostVisible,
        ),
        (
            "aov",
            pixels * 16,
            dev,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "rgba",
            pixels * 4,
            dev,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "stats",
            (STAT_WORDS * 4) as u64,
            dev | BufferUsage::TRANSFER_DST,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "incomplete",
            inc_bytes,
            dev | BufferUsage::TRANSFER_DST,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "requests",
            (items * 4).max(4),
            dev | BufferUsage::TRANSFER_DST,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "carry",
            pixels * CARRY_BYTES,
            dev | BufferUsage::TRANSFER_DST,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
        ),
        (
            "pixel-list",
            4 * pixels.max(guard_count).max(1),
            host,
            AllocKind::Other,
            MemoryClass::HostVisible,
        ),
        (
            "stream-readback",
            readback_bytes,
            BufferUsage::TRANSFER_DST,
            AllocKind::Staging,
            MemoryClass::HostVisible,
        ),
    ]
}

/// Bytes of the frame's buffers (16-byte aligned each), for the floor.
pub(super) fn frame_buffer_bytes(pixels: u64, guard_count: u64, items: u64) -> u64 {
    let params = std::mem::size_of::<crate::render::FrameParams>() as u64;
    frame_buffer_specs(pixels, guard_count, items, params)
        .iter()
        .map(|s| s.1.max(16).div_ceil(16) * 16)
        .sum()
}

pub(super) fn alloc_frame_buffers(
    heap: &mut GpuHeap,
    width: u32,
    pixels: u64,
    guard_count: u64,
    items: u64,
    params: &crate::render::FrameParams,
    shading: &motu_abi::shade::Shading,
) -> Result<FrameBuffers> {
    let specs = frame_buffer_specs(
        pixels,
        guard_count,
        items,
        crate::render::params_bytes(shading),
    );
    let mut bufs: Vec<HeapBuffer> = Vec::with_capacity(specs.len());
    for (label, size, usage, kind, class) in specs {
        match heap.alloc_buffer(label, size, usage, kind, class, 16) {
            Ok(b) => bufs.push(b),
            Err(e) => {
                bufs.into_iter().for_each(|b| heap.free(b));
                return Err(e.into());
            }
        }
    }
    if let Err(e) = crate::render::write_params(&bufs[0], params, shading) {
        bufs.into_iter().for_each(|b| heap.free(b));
        return Err(e);
    }
    let mut it = bufs.into_iter();
    let mut next = || {
        it.next()
            .ok_or_else(|| GpuError::InvalidRequest("frame buffers".into()))
    };
    Ok(FrameBuffers {
        params: next()?,
        stream: next()?,
        aov: next()?,
        rgba: next()?,
        stats: next()?,
        incomplete: next()?,
        requests: next()?,
        carry: next()?,
        pixel_list: next()?,
        readback: next()?,
        launch_row_items: width,
    })
}
