use super::*;

#[test]
fn the_cache_can_move_to_a_worker_thread() {
    fn is_send<T: Send>() {}
    is_send::<AsCache>();
    is_send::<DiskCache>();
    is_send::<HostCache>();
}

/// ARCHITECTURE.md's invariant: cache policy is plain Rust, usable below every crate.
#[test]
fn depends_on_no_workspace_crate_and_no_vulkan() {
    let manifest = include_str!("../Cargo.toml");
    for line in manifest.lines().map(str::trim) {
        let name = line.split(['=', '.', ' ']).next().unwrap_or("");
        assert!(
            !name.starts_with("motu") && !name.starts_with("pbrt") && name != "ash",
            "motu-ascache must stay GPU-free and below the workspace: {line}"
        );
    }
}
