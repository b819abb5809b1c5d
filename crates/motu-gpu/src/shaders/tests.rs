//! The embedded shaders' SPIR-V (call graphs) and, on the device, the GLSL sample sequence
//! (`shaders/sampling.glsl`) against its Rust source of truth (`motu_abi::sampling`): equal
//! bit for bit, so the CPU and the GPU draw the same numbers.

use std::collections::HashMap;

use crate::testutil::{assert_no_validation_errors, context_or_skip};
use crate::Requirement;
use motu_abi::sampling::{sample_bits, SAMPLE_INDEX_BITS};

/// A SPIR-V module's call graph by debug name (glslang does not inline: each GLSL call
/// stays an OpFunctionCall; OpName gives `name(` + mangled parameters).
struct CallGraph {
    names: HashMap<u32, String>,
    calls: HashMap<u32, Vec<u32>>,
    entry: u32,
}

impl CallGraph {
    fn parse(words: &[u32]) -> CallGraph {
        const OP_NAME: u32 = 5;
        const OP_ENTRY_POINT: u32 = 15;
        const OP_FUNCTION: u32 = 54;
        const OP_FUNCTION_CALL: u32 = 57;
        let mut g = CallGraph {
            names: HashMap::new(),
            calls: HashMap::new(),
            entry: 0,
        };
        let mut current = 0u32;
        let mut i = 5; // after the header
        while i < words.len() {
            let count = (words[i] >> 16) as usize;
            let op = words[i] & 0xffff;
            assert!(
                count > 0 && i + count <= words.len(),
                "malformed SPIR-V at word {i}"
            );
            let operands = &words[i + 1..i + count];
            match op {
                OP_NAME => {
                    let bytes: Vec<u8> =
                        operands[1..].iter().flat_map(|w| w.to_le_bytes()).collect();
                    let end = bytes.iter().position(|&b| b == 0).unwrap_or(bytes.len());
                    let name = String::from_utf8_lossy(&bytes[..end]).into_owned();
                    g.names.insert(operands[0], name);
                }
                OP_ENTRY_POINT => g.entry = operands[1],
                OP_FUNCTION => current = operands[1],
                OP_FUNCTION_CALL => g.calls.entry(current).or_default().push(operands[2]),
                _ => {}
            }
            i += count;
        }
        g
    }

    fn function(&self, name: &str) -> u32 {
        let prefix = format!("{name}(");
        let ids: Vec<u32> = self
            .names
            .iter()
            .filter(|(_, n)| n.starts_with(&prefix))
            .map(|(&id, _)| id)
            .collect();
        assert_eq!(ids.len(), 1, "one function named {name}");
        ids[0]
    }

    /// Copies of `to` inlined into `from` when every call is inlined: the call paths.
    fn copies(&self, from: u32, to: u32) -> usize {
        if from == to {
            return 1;
        }
        self.calls
            .get(&from)
            .map_or(0, |c| c.iter().map(|&g| self.copies(g, to)).sum())
    }
}

/// Drivers inline every call, so each call path to the traversal loop is a copy whose
/// traceRayEXT keeps its caller's live state. With a copy per ray kind (primary, light, AO,
/// guard probe: 7 copies) and the shading state live across them, TLAS hops cost ~1.3x
/// more on the H200 (issue 15, BENCHMARKS.md); render_pixel.glsl traces every ray kind
/// through one copy per entry: the full build's (streaming folded out) and streaming's.
#[test]
fn each_render_path_inlines_the_traversal_loop_once() {
    // The streamed variants (MOTU_STREAMED) run only streaming passes: one entry.
    let full: &[&str] = &["render_pixel", "render_stream_item"];
    let streamed: &[&str] = &["render_stream_item"];
    for (words, what, entries) in [
        (super::PIPELINE_TRACE_RGEN, "pipeline/trace.rgen", full),
        (super::QUERY_TRACE_COMP, "query/trace.comp", full),
        (
            super::PIPELINE_TRACE_STREAM_RGEN,
            "pipeline/trace_stream.rgen",
            streamed,
        ),
        (
            super::QUERY_TRACE_STREAM_COMP,
            "query/trace_stream.comp",
            streamed,
        ),
    ] {
        let g = CallGraph::parse(words);
        for callee in ["traverse", "backend_trace"] {
            let to = g.function(callee);
            for &entry in entries {
                assert_eq!(
                    g.copies(g.function(entry), to),
                    1,
                    "{what}: copies of {callee}() under {entry}()"
                );
            }
            assert_eq!(
                g.copies(g.entry, to),
                entries.len(),
                "{what}: copies of {callee}()"
            );
        }
    }
}

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
    let case_buf = crate::tests::mirror_buffer(&ctx, "cases", (cases.len() * 16) as u64);
    case_buf.write(0, &cases).expect("write");
    let bits_buf = crate::tests::mirror_buffer(&ctx, "bits", (cases.len() * 4) as u64);
    crate::tests::run_mirror(
        &ctx,
        "sampling mirror",
        crate::shaders::TEST_SAMPLING_MIRROR_COMP,
        &[&case_buf, &bits_buf],
        &[cases.len() as u32, 0],
        (cases.len() as u32).div_ceil(64),
    );
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
