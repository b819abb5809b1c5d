//! OBJ import (tobj plus motu's error locator and mesh checks) on arbitrary bytes, through a
//! file as `motu import` reads it.
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "alloc_guard.rs"]
mod alloc_guard;
#[global_allocator]
static GUARD: alloc_guard::Guard = alloc_guard::Guard(512 << 20);

fuzz_target!(|data: &[u8]| {
    let dir = std::env::temp_dir().join(format!("motu-fuzz-obj-{}", std::process::id()));
    let _ = std::fs::create_dir_all(&dir);
    let path = dir.join("input.obj");
    if std::fs::write(&path, data).is_err() {
        return;
    }
    let store = Box::new(motu_scene::InMemoryGeometry::default());
    let _ = motu_ingest::ingest_obj(&path, true, store);
});
