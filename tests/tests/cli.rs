//! The command-line contract (shared/CLI.md): commands exist, errors are clean, JSON is one object.

use motu_tests::{motu, motu_json};

#[test]
fn every_command_has_help() {
    for cmd in [
        "devices", "gen", "import", "info", "verify", "report", "render", "compare", "bench",
        "demo",
    ] {
        let out = motu(&[cmd, "--help"]);
        assert!(out.status.success(), "motu {cmd} --help failed");
    }
}

#[test]
fn bad_input_is_a_clean_error() {
    let out = motu(&["info", "/nonexistent/x.motu"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.starts_with("error:") && !err.contains("panicked"),
        "{err}"
    );
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.motu");
    std::fs::write(&junk, b"\x89PNG\r\n\x1a\nnot a package at all").unwrap();
    let out = motu(&["verify", junk.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(!String::from_utf8_lossy(&out.stderr).contains("panicked"));
    let out = motu(&[
        "import",
        "/nonexistent.pbrt",
        "-o",
        dir.path().join("o.motu").to_str().unwrap(),
    ]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("does not exist"));
}

#[test]
fn devices_json_reports_ray_tracing_and_limits() {
    let out = motu(&["devices", "--json"]);
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            std::env::var_os("MOTU_REQUIRE_GPU").is_none(),
            "no Vulkan device but MOTU_REQUIRE_GPU is set: {err}"
        );
        eprintln!("SKIPPED: no Vulkan device: {err}");
        return;
    }
    let v = motu_json(&["devices", "--json"]);
    let devices = v["devices"].as_array().expect("devices array");
    assert!(!devices.is_empty());
    for d in devices {
        for key in [
            "name",
            "driver",
            "ray_pipeline",
            "ray_query",
            "max_instance_count",
            "max_primitive_count",
            "max_memory_allocation_count",
            "max_memory_allocation_size",
            "heaps",
        ] {
            assert!(!d[key].is_null(), "device lacks {key}: {d}");
        }
    }
    if let Some(lvp) = devices
        .iter()
        .find(|d| d["name"].as_str().is_some_and(|n| n.contains("llvmpipe")))
    {
        assert_eq!(lvp["ray_pipeline"], true);
        assert_eq!(lvp["ray_query"], true);
        assert_eq!(lvp["max_instance_count"], 16_777_215);
    }
}
