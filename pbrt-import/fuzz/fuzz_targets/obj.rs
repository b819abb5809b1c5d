//! OBJ import (tobj plus motu's error locator and mesh checks) on arbitrary bytes, through a
//! file as `motu import` reads it.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[global_allocator]
static GUARD: pbrt_import_fuzz::Guard = pbrt_import_fuzz::Guard(512 << 20);

fuzz_target!(|data: &[u8]| {
    let dir = std::env::temp_dir().join(format!("motu-fuzz-obj-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join("input.obj");
    // After a `#--mtl--` line, the bytes are the material library `input.mtl` beside the OBJ
    // (an OBJ naming `mtllib input.mtl` reads it): one input fuzzes both readers.
    let (obj, mtl) = split_mtl(data);
    if std::fs::write(&path, obj).is_err() || std::fs::write(dir.join("input.mtl"), mtl).is_err() {
        return;
    }
    let store = Box::new(motu_scene::InMemoryGeometry::default());
    let _ = motu_ingest::ingest_obj(&path, true, store);
});

/// (the OBJ, the material library) of a fuzz input (see `#--mtl--` above).
fn split_mtl(data: &[u8]) -> (&[u8], &[u8]) {
    const MARK: &[u8] = b"#--mtl--\n";
    match data.windows(MARK.len()).position(|w| w == MARK) {
        Some(i) => (&data[..i], &data[i + MARK.len()..]),
        None => (data, &[]),
    }
}
