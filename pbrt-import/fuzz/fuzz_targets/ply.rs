//! PLY reader on arbitrary bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[global_allocator]
static GUARD: pbrt_import_fuzz::Guard = pbrt_import_fuzz::Guard(256 << 20);

fuzz_target!(|data: &[u8]| {
    let _ = pbrt_import::ply::parse_ply(data);
});
