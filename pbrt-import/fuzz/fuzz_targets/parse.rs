//! Tokenizer + parser on arbitrary bytes, under both version semantics.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "alloc_guard.rs"]
mod alloc_guard;
#[global_allocator]
static GUARD: alloc_guard::Guard = alloc_guard::Guard(256 << 20);
use pbrt_import::{lexer::Lexer, parse_bytes, CollectSink, FileId, ParseOptions, VersionOption};

fuzz_target!(|data: &[u8]| {
    let _ = Lexer::new(data, FileId(0)).count_tokens();
    for version in [VersionOption::V3, VersionOption::V4] {
        let opts = ParseOptions {
            version,
            ..Default::default()
        };
        let _ = parse_bytes(
            data,
            std::path::Path::new("/nonexistent"),
            &opts,
            &mut CollectSink::default(),
        );
    }
});
