//! SPIR-V of every GLSL shader under `shaders/`, compiled and validated by `build.rs`.
//! A file `shaders/foo/bar.rgen` becomes `FOO_BAR_RGEN: &[u32]`.

/// One embedded shader.
#[derive(Clone, Copy, Debug)]
pub struct EmbeddedShader {
    /// Path relative to `shaders/`.
    pub path: &'static str,
    /// The file extension: `comp`, `rgen`, `rchit`, `rahit`, `rint` or `rmiss`.
    pub stage: &'static str,
    pub words: &'static [u32],
}

include!(concat!(env!("OUT_DIR"), "/shaders.rs"));

#[cfg(test)]
mod tests {
    use std::collections::HashMap;

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
}
