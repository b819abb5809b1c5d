//! AOV reader (`motu compare`'s input) on arbitrary bytes: a header may claim any size; the
//! reader must fail without allocating what the bytes cannot hold.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "alloc_guard.rs"]
mod alloc_guard;
#[global_allocator]
static GUARD: alloc_guard::Guard = alloc_guard::Guard(256 << 20);

fuzz_target!(|data: &[u8]| {
    if let Ok(aov) = motu_abi::aov::Aov::read_from(data) {
        assert_eq!(aov.records.len(), aov.width as usize * aov.height as usize);
        assert!(data.len() >= aov.to_bytes().len());
    }
});
