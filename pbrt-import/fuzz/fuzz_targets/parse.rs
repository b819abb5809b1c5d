//! Tokenizer + parser on arbitrary bytes, under both version semantics.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[global_allocator]
static GUARD: pbrt_import_fuzz::Guard = pbrt_import_fuzz::Guard(256 << 20);
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
