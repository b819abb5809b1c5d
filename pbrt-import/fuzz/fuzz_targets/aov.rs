//! AOV reader (`motu compare`'s input) on arbitrary bytes: a header may claim any size; the
//! reader must fail without allocating what the bytes cannot hold.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[global_allocator]
static GUARD: pbrt_import_fuzz::Guard = pbrt_import_fuzz::Guard(256 << 20);

fuzz_target!(|data: &[u8]| {
    if let Ok(aov) = motu_abi::aov::Aov::read_from(data) {
        assert_eq!(aov.records.len(), aov.width as usize * aov.height as usize);
        assert!(data.len() >= aov.to_bytes().len());
    }
});
