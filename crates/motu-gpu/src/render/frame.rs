//! A frame's GPU buffers (parameters, AOV, colour, counters, read-back) and the recording
//! that traces into them and reads them back.

use motu_abi::aov::AovRecord;
use motu_abi::shade::Shading;
use motu_alloc::{AllocKind, MemoryClass};
use motu_vk::{BufferUsage, CommandRecorder, Context, GpuHeap, HeapBuffer, TimestampQueries};

use super::{
    check_texture_residency, params_bytes, write_params, FrameParams, Tracer, RENDER_STAT_WORDS,
};
use crate::error::{GpuError, Result};
use crate::scene::{GpuScene, Slot, SLOT_COUNT};

pub(crate) struct Frame {
    pub(crate) params: HeapBuffer,
    aov: HeapBuffer,
    rgba: HeapBuffer,
    stats: HeapBuffer,
    readback: HeapBuffer,
}

impl Frame {
    pub(crate) fn release(self, heap: &mut GpuHeap) {
        for b in [self.params, self.aov, self.rgba, self.stats, self.readback] {
            heap.free(b);
        }
    }
}

/// Sizes of the buffers [`alloc_frame`] allocates for `pixels`: parameters, AOV (16 B a
/// pixel), colour (4), counters, readback (20 a pixel and the counters). One list for the
/// allocation and for [`frame_bytes`].
fn frame_buffer_sizes(pixels: u64, params_size: u64) -> [u64; 5] {
    let stats = (RENDER_STAT_WORDS * 4) as u64;
    [
        params_size,
        pixels * 16,
        pixels * 4,
        stats,
        pixels * 20 + stats,
    ]
}

/// What [`alloc_frame`] allocates for `pixels` (each buffer rounded to 16 bytes).
pub(crate) fn frame_bytes(pixels: u64) -> u64 {
    frame_buffer_sizes(pixels, std::mem::size_of::<FrameParams>() as u64)
        .iter()
        .map(|v| v.max(&16).div_ceil(16) * 16)
        .sum()
}

pub(crate) fn alloc_frame(
    heap: &mut GpuHeap,
    pixels: u64,
    params: &FrameParams,
    shading: &Shading,
) -> Result<Frame> {
    let out = BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS | BufferUsage::TRANSFER_SRC;
    let [params_size, aov_size, rgba_size, stats_size, readback_size] =
        frame_buffer_sizes(pixels, params_bytes(shading));
    let p = heap.alloc_buffer(
        "frame-params",
        params_size,
        BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
        AllocKind::Other,
        MemoryClass::HostVisible,
        16,
    )?;
    if let Err(e) = write_params(&p, params, shading) {
        heap.free(p);
        return Err(e);
    }
    let mut bufs = vec![p];
    let sizes = [aov_size, rgba_size, stats_size];
    for (i, size) in sizes.into_iter().enumerate() {
        let usage = if i == 2 {
            out | BufferUsage::TRANSFER_DST
        } else {
            out
        };
        match heap.alloc_buffer(
            ["aov", "rgba", "stats"][i],
            size,
            usage,
            AllocKind::Other,
            MemoryClass::DeviceLocal,
            16,
        ) {
            Ok(b) => bufs.push(b),
            Err(e) => {
                bufs.into_iter().for_each(|b| heap.free(b));
                return Err(e.into());
            }
        }
    }
    let readback = match heap.alloc_buffer(
        "readback",
        readback_size,
        BufferUsage::TRANSFER_DST,
        AllocKind::Staging,
        MemoryClass::HostVisible,
        16,
    ) {
        Ok(b) => b,
        Err(e) => {
            bufs.into_iter().for_each(|b| heap.free(b));
            return Err(e.into());
        }
    };
    let mut it = bufs.into_iter();
    let (Some(params), Some(aov), Some(rgba), Some(stats)) =
        (it.next(), it.next(), it.next(), it.next())
    else {
        return Err(GpuError::InvalidRequest("frame buffers".into()));
    };
    Ok(Frame {
        params,
        aov,
        rgba,
        stats,
        readback,
    })
}

/// What [`run_frames`] read back: the last frame's pixels and counters, every frame's time.
pub(crate) struct FrameResult {
    /// The hit AOV, one record a pixel.
    pub records: Vec<AovRecord>,
    /// The shaded image, one RGBA8 word a pixel.
    pub rgba_words: Vec<u32>,
    /// The shaders' counters (`RENDER_STAT_WORDS` of them).
    pub counters: Vec<u32>,
    /// Per frame: its GPU time in nanoseconds.
    pub frame_ns: Vec<f64>,
}

pub(crate) fn run_frames(
    ctx: &Context,
    scene: &GpuScene,
    tracer: &Tracer,
    frame: &Frame,
    w: u32,
    h: u32,
    frames: u32,
) -> Result<FrameResult> {
    let mut addresses = scene.addresses;
    addresses[Slot::Frame as usize] = frame.params.device_address()?.0;
    addresses[Slot::Aov as usize] = frame.aov.device_address()?.0;
    addresses[Slot::Rgba as usize] = frame.rgba.device_address()?.0;
    addresses[Slot::Stats as usize] = frame.stats.device_address()?.0;
    let push: [u64; SLOT_COUNT] = addresses;
    let push_bytes: &[u8] = bytemuck::cast_slice(&push);
    let pixels = u64::from(w) * u64::from(h);
    // Two per frame, then one at the end of the instance-LOD pass (when a frame runs it).
    let timestamps = TimestampQueries::new(ctx, 2 * frames + 1)?;
    let mut rec: CommandRecorder<'_> = ctx.record(match tracer {
        Tracer::Pipeline(_) => "trace (pipeline)",
        Tracer::Query(_) => "trace (query)",
    })?;
    rec.reset_queries(&timestamps);
    // Instance-level LOD: every frame of this call has the same camera, so the levels are
    // picked on the host and applied (the slot TLASes rebuilt) in the first frame at most,
    // and not at all when the slot TLASes already hold exactly those levels (lod_instances.rs).
    let lod_levels = match &scene.instance_lod {
        Some(lod) => {
            let params: Vec<FrameParams> = frame.params.read_vec(0, 1)?;
            let (camera, lod_params) = params[0].camera_and_lod();
            Some(lod.levels(camera, lod_params))
        }
        None => None,
    };
    let lod_pass = match (&scene.instance_lod, &lod_levels) {
        (Some(lod), Some(levels)) => lod.needs_pass(levels, frames),
        _ => None,
    };
    for f in 0..frames {
        rec.fill_buffer(&frame.stats, 0, (RENDER_STAT_WORDS * 4) as u64, 0)?;
        rec.barrier();
        rec.write_timestamp(&timestamps, 2 * f)?;
        // In the first frame (`frames` ≥ 1), counted in its time.
        if let (0, Some(kind), Some(lod), Some(levels)) =
            (f, lod_pass, &scene.instance_lod, &lod_levels)
        {
            lod.record(&mut rec, levels, kind)?;
            rec.write_timestamp(&timestamps, 2 * frames)?;
        }
        tracer.record(&mut rec, push_bytes, [w, h], None)?;
        rec.write_timestamp(&timestamps, 2 * f + 1)?;
        rec.barrier();
    }
    if lod_pass.is_none() {
        // Every query is read back: the LOD one too, unused without a pass.
        rec.write_timestamp(&timestamps, 2 * frames)?;
    }
    let rgba_off = pixels * 16;
    let stats_off = pixels * 20;
    rec.copy_buffer(&frame.aov, 0, &frame.readback, 0, pixels * 16)?;
    rec.copy_buffer(&frame.rgba, 0, &frame.readback, rgba_off, pixels * 4)?;
    rec.copy_buffer(
        &frame.stats,
        0,
        &frame.readback,
        stats_off,
        (RENDER_STAT_WORDS * 4) as u64,
    )?;
    rec.submit_and_wait()?;
    let ticks = timestamps.read_ticks()?;
    if let (Some(lod), Some(levels), Some(kind)) = (&scene.instance_lod, lod_levels, lod_pass) {
        let pass_ms = timestamps.elapsed_ns(&ticks, 0, 2 * frames)? / 1e6;
        lod.built(levels, kind, pass_ms);
    }
    let records: Vec<AovRecord> = frame.readback.read_vec(0, pixels as usize)?;
    let rgba_words: Vec<u32> = frame.readback.read_vec(rgba_off, pixels as usize)?;
    let counters: Vec<u32> = frame.readback.read_vec(stats_off, RENDER_STAT_WORDS)?;
    check_texture_residency(&counters)?;
    let frame_ns = (0..frames)
        .map(|f| timestamps.elapsed_ns(&ticks, 2 * f, 2 * f + 1))
        .collect::<motu_vk::Result<Vec<f64>>>()?;
    Ok(FrameResult {
        records,
        rgba_words,
        counters,
        frame_ns,
    })
}
