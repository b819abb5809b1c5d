//! The GLSL sample sequence (`shaders/sampling.glsl`) against its Rust source of truth
//! (`motu_abi::sampling`): equal bit for bit, so the CPU and the GPU draw the same numbers.

use crate::testing::{assert_no_validation_errors, context_or_skip};
use crate::{
    Buffer, BufferDesc, BufferUsage, ComputePipeline, ComputePipelineDesc, MemoryLocation,
    Requirement,
};
use motu_abi::sampling::{sample_bits, SAMPLE_INDEX_BITS};

#[test]
fn glsl_sample_sequence_equals_the_rust_one_bit_for_bit() {
    let Some(ctx) = context_or_skip("glsl_sample_sequence_mirror", Requirement::Compute) else {
        return;
    };
    // Pixels, sample indices (with and without a path vertex), dimensions: edges and a spread.
    let mut cases: Vec<[u32; 4]> = Vec::new();
    let mut seed = 0x2545_f491u32;
    for i in 0..4096u32 {
        seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let pixel = match i % 4 {
            0 => i,
            1 => seed,
            2 => u32::MAX - i,
            _ => seed >> 12,
        };
        let index = match i % 3 {
            0 => i % 64,
            1 => seed >> 12,
            _ => (1 << SAMPLE_INDEX_BITS) - 1 - (i % 7),
        };
        let vertex = (i / 7) % 9;
        cases.push([pixel, index | vertex << SAMPLE_INDEX_BITS, i % 19, 0]);
    }
    let usage = BufferUsage::STORAGE | BufferUsage::DEVICE_ADDRESS;
    let mk = |label: &str, bytes: u64| {
        Buffer::new_dedicated(
            &ctx,
            label,
            &BufferDesc {
                size_bytes: bytes,
                usage,
            },
            MemoryLocation::Readback,
        )
        .expect("buffer")
    };
    let case_buf = mk("cases", (cases.len() * 16) as u64);
    case_buf.write(0, &cases).expect("write");
    let bits_buf = mk("bits", (cases.len() * 4) as u64);
    let pipe = ComputePipeline::new(
        &ctx,
        &ComputePipelineDesc {
            label: "sampling mirror",
            spirv: crate::shaders::TEST_SAMPLING_MIRROR_COMP,
            storage_buffer_count: 0,
            push_constant_size_bytes: 24,
            specialization: &[],
        },
    )
    .expect("pipeline");
    let mut push = Vec::new();
    for b in [&case_buf, &bits_buf] {
        push.extend_from_slice(&b.device_address().expect("address").0.to_le_bytes());
    }
    for v in [cases.len() as u32, 0] {
        push.extend_from_slice(&v.to_le_bytes());
    }
    let mut rec = ctx.record("sampling mirror").expect("record");
    rec.dispatch(
        &pipe,
        None,
        &push,
        [(cases.len() as u32).div_ceil(64), 1, 1],
    )
    .expect("dispatch");
    rec.submit_and_wait().expect("submit");
    let gpu: Vec<u32> = bits_buf.read_vec(0, cases.len()).expect("read");
    let differ: Vec<String> = cases
        .iter()
        .zip(&gpu)
        .filter(|(c, &g)| sample_bits(c[0], c[1], c[2]) != g)
        .take(5)
        .map(|(c, g)| {
            format!(
                "pixel {} sample {:#x} dim {}: cpu {:#010x} gpu {g:#010x}",
                c[0],
                c[1],
                c[2],
                sample_bits(c[0], c[1], c[2])
            )
        })
        .collect();
    assert!(differ.is_empty(), "{}", differ.join("\n"));
    assert_no_validation_errors(&ctx);
}
