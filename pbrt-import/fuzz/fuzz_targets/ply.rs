//! PLY reader on arbitrary bytes.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "alloc_guard.rs"]
mod alloc_guard;
#[global_allocator]
static GUARD: alloc_guard::Guard = alloc_guard::Guard(256 << 20);

fuzz_target!(|data: &[u8]| {
    let _ = pbrt_import::ply::parse_ply(data);
});
