//! Tests on the real device (lavapipe in CI) with validation on. Each prints
//! `SKIPPED: no Vulkan device: …` without a device, and fails under `MOTU_REQUIRE_GPU=1`.
//! These need the embedded shaders; the device layer's own tests are motu-vk's.

use std::borrow::Cow;

use motu_trace::testutil::OwnedHierarchy;
use motu_trace::MeshGeometry;

use crate::testutil::{assert_no_validation_errors, context_or_skip};
use crate::*;

/// The crate's GPU tests build motu-trace's test hierarchies: each is its own mesh source
/// (positions and indices, and the normals and texture coordinates a mesh has).
impl MeshBlobSource for OwnedHierarchy {
    fn mesh_data(
        &self,
        mesh_record: u32,
    ) -> std::result::Result<(Cow<'_, [[f32; 3]]>, Cow<'_, [u32]>), MeshSourceError> {
        let g = geometry(self, mesh_record)?;
        Ok((Cow::Borrowed(&g.positions), Cow::Borrowed(&g.indices)))
    }

    #[allow(clippy::type_complexity)]
    fn mesh_shading(
        &self,
        mesh_record: u32,
    ) -> std::result::Result<
        (Option<Cow<'_, [[f32; 3]]>>, Option<Cow<'_, [[f32; 2]]>>),
        MeshSourceError,
    > {
        let g = geometry(self, mesh_record)?;
        Ok((
            g.normals.as_deref().map(Cow::Borrowed),
            g.uvs.as_deref().map(Cow::Borrowed),
        ))
    }
}

/// A buffer a mirror test's shader reads its cases from or writes its results to (by device
/// address), readable by the host.
pub(crate) fn mirror_buffer(ctx: &Context, label: &str, size_bytes: u64) -> Buffer {
    Buffer::new_dedicated(
        ctx,
        label,
        &BufferDesc {
            size_bytes,
            usage: BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS,
        },
        MemoryLocation::Readback,
    )
    .expect("buffer")
}

/// Runs a mirror test's compute shader (`label`) over `groups` workgroups and waits: its push
/// constants are `buffers`' device addresses, then `values`.
pub(crate) fn run_mirror(
    ctx: &Context,
    label: &str,
    spirv: &[u32],
    buffers: &[&Buffer],
    values: &[u32],
    groups: u32,
) {
    let mut push = Vec::new();
    for b in buffers {
        push.extend_from_slice(&b.device_address().expect("address").0.to_le_bytes());
    }
    for v in values {
        push.extend_from_slice(&v.to_le_bytes());
    }
    let pipe = ComputePipeline::new(
        ctx,
        &ComputePipelineDesc {
            label,
            spirv,
            storage_buffer_count: 0,
            push_constant_size_bytes: push.len() as u32,
            specialization: &[],
        },
    )
    .expect("pipeline");
    let mut rec = ctx.record(label).expect("record");
    rec.dispatch(&pipe, None, &push, [groups, 1, 1])
        .expect("dispatch");
    rec.submit_and_wait().expect("submit");
}

fn geometry(h: &OwnedHierarchy, mesh_record: u32) -> std::result::Result<&MeshGeometry, String> {
    h.geometry
        .get(mesh_record as usize)
        .ok_or_else(|| format!("no mesh {mesh_record}"))
}

fn smoke_expected(input: &[u32]) -> Vec<u32> {
    input
        .iter()
        .enumerate()
        .map(|(i, v)| v.wrapping_mul(2).wrapping_add(i as u32))
        .collect()
}

#[test]
fn smoke_compute_shader_doubles_and_adds_index() {
    let Some(ctx) = context_or_skip("smoke_compute_shader", Requirement::Compute) else {
        return;
    };
    // Not a multiple of the workgroup size: the bounds check in the shader matters.
    let count = 1000usize;
    let input: Vec<u32> = (0..count as u32)
        .map(|i| i.wrapping_mul(2_654_435_761) >> 7)
        .collect();
    let size_bytes = (count * 4) as u64;

    let upload = Buffer::new_dedicated(
        &ctx,
        "smoke.in",
        &BufferDesc {
            size_bytes,
            usage: BufferUsage::STORAGE | BufferUsage::TRANSFER_SRC,
        },
        MemoryLocation::Upload,
    )
    .expect("input buffer");
    upload.write(0, &input).expect("write input");
    let output = Buffer::new_dedicated(
        &ctx,
        "smoke.out",
        &BufferDesc {
            size_bytes,
            usage: BufferUsage::STORAGE | BufferUsage::TRANSFER_DST,
        },
        MemoryLocation::Readback,
    )
    .expect("output buffer");

    let pipeline = ComputePipeline::new(
        &ctx,
        &ComputePipelineDesc {
            label: "smoke",
            spirv: shaders::SMOKE_COMP,
            storage_buffer_count: 2,
            push_constant_size_bytes: 4,
            specialization: &[],
        },
    )
    .expect("pipeline");
    let bindings = pipeline
        .bind_storage_buffers(&[&upload, &output])
        .expect("bindings");
    let timestamps = ctx
        .caps()
        .timestamps
        .then(|| TimestampQueries::new(&ctx, 2).expect("query pool"));

    let mut rec = ctx.record("smoke").expect("recorder");
    // Poison the output first so a dispatch that writes nothing cannot pass.
    rec.fill_buffer(&output, 0, size_bytes, 0xdead_beef)
        .expect("fill");
    rec.barrier();
    if let Some(ts) = &timestamps {
        rec.reset_queries(ts);
        rec.write_timestamp(ts, 0).expect("timestamp 0");
    }
    let groups = (count as u32).div_ceil(64);
    rec.dispatch(
        &pipeline,
        Some(&bindings),
        &(count as u32).to_ne_bytes(),
        [groups, 1, 1],
    )
    .expect("dispatch");
    if let Some(ts) = &timestamps {
        rec.write_timestamp(ts, 1).expect("timestamp 1");
    }
    rec.barrier();
    rec.submit_and_wait().expect("submit");

    let result: Vec<u32> = output.read_vec(0, count).expect("read back");
    assert_eq!(result, smoke_expected(&input));
    if let Some(ts) = &timestamps {
        let ticks = ts.read_ticks().expect("timestamps");
        let ns = ts.elapsed_ns(&ticks, 0, 1).expect("elapsed");
        assert!((0.0..60e9).contains(&ns), "dispatch took {ns} ns");
    } else {
        eprintln!("note: {}: no timestamps on this queue", ctx.device_name());
    }
    drop(bindings);
    drop(pipeline);
    assert_no_validation_errors(&ctx);
    ctx.check_validation().expect("no validation errors");
}

#[test]
fn shader_reads_and_writes_through_device_addresses() {
    let Some(ctx) = context_or_skip("smoke_bda", Requirement::Compute) else {
        return;
    };
    if !(ctx.caps().buffer_device_address && ctx.caps().shader_int64) {
        eprintln!(
            "SKIPPED: smoke_bda: {} lacks bufferDeviceAddress or shaderInt64",
            ctx.device_name()
        );
        return;
    }
    let count = 300usize;
    let usage = BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS;
    let desc = BufferDesc {
        size_bytes: (count * 4) as u64,
        usage,
    };
    let src = Buffer::new_dedicated(&ctx, "bda.src", &desc, MemoryLocation::Upload).expect("src");
    let dst = Buffer::new_dedicated(&ctx, "bda.dst", &desc, MemoryLocation::Readback).expect("dst");
    let input: Vec<u32> = (0..count as u32).map(|i| i * i).collect();
    src.write(0, &input).expect("write");
    let pipeline = ComputePipeline::new(
        &ctx,
        &ComputePipelineDesc {
            label: "smoke_bda",
            spirv: shaders::SMOKE_BDA_COMP,
            storage_buffer_count: 0,
            push_constant_size_bytes: 24,
            specialization: &[],
        },
    )
    .expect("pipeline");
    let mut push = Vec::with_capacity(24);
    push.extend_from_slice(&src.device_address().expect("src address").0.to_ne_bytes());
    push.extend_from_slice(&dst.device_address().expect("dst address").0.to_ne_bytes());
    push.extend_from_slice(&(count as u32).to_ne_bytes());
    push.extend_from_slice(&17u32.to_ne_bytes());
    let mut rec = ctx.record("smoke_bda").expect("recorder");
    let err = rec
        .dispatch(&pipeline, None, &push[..20], [1, 1, 1])
        .expect_err("short push");
    assert!(err.to_string().contains("push constants"), "{err}");
    rec.dispatch(&pipeline, None, &push, [(count as u32).div_ceil(64), 1, 1])
        .expect("dispatch");
    rec.submit_and_wait().expect("submit");
    let out: Vec<u32> = dst.read_vec(0, count).expect("read");
    let expected: Vec<u32> = input.iter().map(|v| v + 17).collect();
    assert_eq!(out, expected);
    assert_no_validation_errors(&ctx);
}

#[test]
fn embedded_shaders_are_listed_with_their_stage() {
    assert!(shaders::ALL
        .iter()
        .any(|s| s.path == "smoke.comp" && s.stage == "comp"));
    for s in shaders::ALL {
        assert_eq!(s.words.first(), Some(&0x0723_0203), "{}", s.path);
    }
}
