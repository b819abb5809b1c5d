//! The command-line contract (shared/CLI.md): commands exist, errors are clean, JSON is one object.

use motu_tests::{gpu_available, motu, motu_json, motu_ok, s};
use std::path::Path;

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
        for key in ["size_bytes", "budget_bytes", "usage_bytes", "device_local"] {
            assert!(d["heaps"][0].get(key).is_some(), "heap lacks {key}: {d}");
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

#[test]
fn regression_a_closed_stdout_ends_quietly_not_with_a_panic() {
    // `motu info pkg | head -1`: the reader goes away before motu writes.
    let d = tempfile::tempdir().unwrap();
    let obj = d.path().join("tri.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let pkg = d.path().join("tri.motu");
    motu_tests::import(&obj, &pkg, &[]);
    for _ in 0..3 {
        let mut child = std::process::Command::new(motu_tests::motu_bin())
            .args(["info", motu_tests::s(&pkg)])
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .expect("spawning motu");
        drop(child.stdout.take());
        let out = child.wait_with_output().expect("waiting for motu");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!err.contains("panicked"), "{err}");
        assert!(
            out.status.success() || out.status.code() == Some(141),
            "{:?}: {err}",
            out.status
        );
    }
}

/// The lines of `help` under `heading` (up to the next blank-line-separated heading).
fn help_section<'a>(help: &'a str, heading: &str) -> Vec<&'a str> {
    let mut lines = help.lines().skip_while(|l| *l != heading).skip(1);
    let mut out = Vec::new();
    for l in lines.by_ref() {
        if !l.starts_with(' ') && !l.is_empty() {
            break;
        }
        out.push(l);
    }
    out
}

/// Issue 46 item 7: `render` and `view` list their flags under headings, the expert streaming
/// knobs only in `--help`, and no flag of CLI.md's contract is lost.
#[test]
fn render_and_view_help_group_their_flags() {
    let text = |args: &[&str]| {
        let out = motu(args);
        assert!(out.status.success(), "motu {args:?}");
        String::from_utf8(out.stdout).unwrap()
    };
    let expert = [
        "--stream-probe ",
        "--stream-probe-rounds",
        "--stream-probe-verify",
        "--stream-probe-pass-rows",
        "--stream-probe-paths",
        "--stream-tlas",
        "--stream-split-instances",
        "--stream-defrag",
        "--stream-mesh-memory",
    ];
    for cmd in ["render", "view"] {
        let short = text(&[cmd, "-h"]);
        let long = text(&[cmd, "--help"]);
        for heading in [
            "Output:",
            "Camera:",
            "Shading:",
            "Scene subset and level of detail:",
            "Device and budget:",
            "Streaming:",
            "Debugging:",
        ] {
            assert!(
                short.contains(heading),
                "{cmd} -h lacks {heading}:\n{short}"
            );
            assert!(long.contains(heading), "{cmd} --help lacks {heading}");
        }
        assert!(long.contains("Streaming, expert (--help only):"), "{long}");
        assert!(!short.contains("Streaming, expert"), "{short}");
        for flag in expert {
            assert!(long.contains(flag), "{cmd} --help lacks {flag}");
            assert!(!short.contains(flag), "{cmd} -h shows the expert {flag}");
        }
        // Every flag sits under a heading: the generic list holds only the global ones.
        let generic: Vec<&str> = help_section(&short, "Options:")
            .into_iter()
            .filter(|l| l.trim_start().starts_with('-'))
            .collect();
        assert!(
            generic.iter().all(|l| ["--help", "--version", "--verbose"]
                .iter()
                .any(|f| l.contains(f))),
            "{cmd}: flags without a heading: {generic:?}"
        );
    }
    // CLI.md's `render` flags, all still there in the short help.
    let short = text(&["render", "-h"]);
    for flag in [
        "--output",
        "--camera",
        "--width",
        "--height",
        "--backend",
        "--view",
        "--aov",
        "--vram-budget",
        "--max-allocations",
        "--stream",
        "--frames",
        "--stats",
        "--subset",
    ] {
        assert!(short.contains(flag), "render -h lacks {flag}");
    }
}

/// The keys CLI.md (the contract, `../shared/CLI.md` beside the workspace) names in the table
/// row starting with `row`, after `marker`, up to the cell's end: its backticked names.
fn cli_md_keys(row: &str, marker: &str) -> Vec<String> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/CLI.md");
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("reading the CLI contract {}: {e}", path.display()));
    let line = text
        .lines()
        .find(|l| l.starts_with(row))
        .unwrap_or_else(|| panic!("CLI.md has no row {row:?}"));
    let (_, after) = line
        .split_once(marker)
        .unwrap_or_else(|| panic!("CLI.md's row {row:?} lost {marker:?}"));
    let cell = after.split(" |").next().unwrap_or(after);
    let keys: Vec<String> = cell
        .split('`')
        .skip(1)
        .step_by(2)
        .filter(|k| k.chars().all(|c| c.is_ascii_lowercase() || c == '_'))
        .map(String::from)
        .collect();
    assert!(
        keys.len() >= 5,
        "too few keys parsed from {row:?}: {keys:?}"
    );
    keys
}

/// Issue 46 item 3: every key CLI.md names for `render --stats` (CPU, a full GPU build and a
/// streamed render), `info --json` and `devices --json` is written, not null.
#[test]
fn json_outputs_write_every_key_cli_md_names() {
    let render_keys = cli_md_keys(
        "| `motu render ",
        "`--stats` writes JSON with at least the top-level keys",
    );
    let info_keys = cli_md_keys("| `motu info PKG [--json]`", "JSON keys at least:");
    let device_keys = cli_md_keys("| `motu devices", "lists Vulkan devices:");
    let has = |v: &serde_json::Value, keys: &[String], what: &str| {
        for k in keys {
            assert!(
                v.get(k).is_some_and(|x| !x.is_null()),
                "{what}: CLI.md's key {k} is missing: {v}"
            );
        }
    };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gen = d.join("flake");
    motu_ok(&["gen", "sphereflake", "--depth", "1", "-o", s(&gen)]);
    let pkg = d.join("flake.motu");
    motu_ok(&["import", s(&gen.join("scene.pbrt")), "-o", s(&pkg)]);
    has(
        &motu_json(&["info", s(&pkg), "--json"]),
        &info_keys,
        "info --json",
    );
    let mut renders = vec![("cpu", vec!["--backend", "cpu"])];
    if gpu_available() {
        let v = motu_json(&["devices", "--json"]);
        for dev in v["devices"].as_array().expect("devices") {
            has(dev, &device_keys, "devices --json");
        }
        renders.push(("pipeline", vec!["--backend", "pipeline"]));
        // Streamed even though the budget holds the scene: the streamer's keys.
        renders.push((
            "stream",
            vec!["--backend", "pipeline", "--stream", "--stream-always"],
        ));
    }
    for (name, args) in renders {
        let stats = d.join(format!("{name}.json"));
        let png = d.join(format!("{name}.png"));
        let mut all = vec!["render", s(&pkg), "-o", s(&png), "--width", "16"];
        all.extend(["--height", "16", "--stats", s(&stats)]);
        all.extend(args);
        motu_ok(&all);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        has(&v, &render_keys, &format!("render --stats ({name})"));
        assert_eq!(v["width"], 16, "{name}: {v}");
    }
}

/// Issue 45 item 5: `render --pipeline-stats` lists the trace pipeline it made (`trace full`
/// for a full build, `trace streamed` streamed, per backend) in `pipeline_executables`, with
/// the driver's statistics where the device has VK_KHR_pipeline_executable_properties and
/// `executables: null` (a warning, not an error) where it has not; without the flag the key is
/// absent.
#[test]
fn render_pipeline_stats_lists_the_trace_pipelines() {
    if !gpu_available() {
        eprintln!("SKIPPED: no Vulkan device: render_pipeline_stats_lists_the_trace_pipelines");
        return;
    }
    let devices = motu_json(&["devices", "--json"]);
    let dev = &devices["devices"][0];
    let captures = dev["caps"]["pipeline_executable_info"] == true;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let gen = d.join("flake");
    motu_ok(&["gen", "sphereflake", "--depth", "1", "-o", s(&gen)]);
    let pkg = d.join("flake.motu");
    motu_ok(&["import", s(&gen.join("scene.pbrt")), "-o", s(&pkg)]);
    let mut runs = vec![
        ("plain", "pipeline", vec![], None),
        (
            "full",
            "pipeline",
            vec!["--pipeline-stats"],
            Some("trace full"),
        ),
        (
            "streamed",
            "pipeline",
            vec!["--pipeline-stats", "--stream", "--stream-always"],
            Some("trace streamed"),
        ),
    ];
    if dev["ray_query"] == true {
        runs.push((
            "query",
            "query",
            vec!["--pipeline-stats"],
            Some("trace full"),
        ));
    }
    for (name, backend, flags, label) in runs {
        let stats = d.join(format!("{name}.json"));
        let png = d.join(format!("{name}.png"));
        let mut all = vec!["render", s(&pkg), "-o", s(&png), "--width", "16"];
        all.extend(["--height", "16", "--backend", backend, "--stats", s(&stats)]);
        all.extend(flags);
        motu_ok(&all);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&stats).unwrap()).unwrap();
        let Some(label) = label else {
            assert!(v.get("pipeline_executables").is_none(), "{name}: {v}");
            continue;
        };
        let made = v["pipeline_executables"].as_array().expect("an array");
        let trace: Vec<_> = made.iter().filter(|p| p["label"] == label).collect();
        assert_eq!(trace.len(), 1, "{name}: one {label:?} pipeline: {made:?}");
        let kind = if backend == "query" {
            "compute"
        } else {
            "ray_tracing"
        };
        assert_eq!(trace[0]["kind"], kind, "{name}");
        match trace[0]["executables"].as_array() {
            Some(exes) => {
                assert!(captures, "{name}: statistics without the extension");
                assert!(!exes.is_empty(), "{name}: no executable");
                assert!(
                    exes.iter()
                        .any(|e| e["statistics"].as_array().is_some_and(|s| !s.is_empty())),
                    "{name}: no statistic: {exes:?}"
                );
            }
            None => {
                assert!(!captures, "{name}: the device captures, none written");
                eprintln!(
                    "{name}: {} lacks VK_KHR_pipeline_executable_properties: executables null",
                    dev["name"]
                );
            }
        }
    }
}
