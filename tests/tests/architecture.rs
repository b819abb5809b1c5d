//! The invariants ARCHITECTURE.md states, checked on the manifests so they cannot rot.

use std::path::PathBuf;

fn manifests() -> Vec<(String, String)> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut out = vec![(
        "pbrt-import".to_string(),
        root.join("pbrt-import/Cargo.toml"),
    )];
    for e in std::fs::read_dir(root.join("crates")).unwrap().flatten() {
        out.push((
            e.file_name().to_string_lossy().into_owned(),
            e.path().join("Cargo.toml"),
        ));
    }
    out.into_iter()
        .filter(|(_, p)| p.exists())
        .map(|(n, p)| (n, std::fs::read_to_string(p).unwrap()))
        .collect()
}

/// Dependency names in a manifest's `[dependencies]` section (not dev-dependencies).
fn dependencies(manifest: &str) -> Vec<String> {
    let mut in_deps = false;
    let mut out = Vec::new();
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            in_deps = line == "[dependencies]";
            continue;
        }
        if in_deps {
            if let Some((name, _)) = line.split_once(['=', '.']) {
                if !name.trim().is_empty() && !name.starts_with('#') {
                    out.push(name.trim().to_string());
                }
            }
        }
    }
    out
}

#[test]
fn only_motu_gpu_uses_ash() {
    let users: Vec<String> = manifests()
        .into_iter()
        .filter(|(_, m)| dependencies(m).iter().any(|d| d == "ash"))
        .map(|(n, _)| n)
        .collect();
    assert_eq!(users, ["motu-gpu"]);
}

#[test]
fn the_window_system_stays_behind_the_viewer_and_gpu_crates() {
    let users = |dep: &str| -> Vec<String> {
        manifests()
            .into_iter()
            .filter(|(_, m)| dependencies(m).iter().any(|d| d == dep))
            .map(|(n, _)| n)
            .collect()
    };
    assert_eq!(users("winit"), ["motu-view"]);
    assert_eq!(users("ash-window"), ["motu-gpu"]);
}

#[test]
fn pbrt_import_depends_on_no_workspace_crate() {
    let (_, m) = manifests()
        .into_iter()
        .find(|(n, _)| n == "pbrt-import")
        .unwrap();
    let deps = dependencies(&m);
    assert!(!deps.is_empty());
    assert!(deps.iter().all(|d| !d.starts_with("motu")), "{deps:?}");
}

#[test]
fn libraries_use_thiserror_not_anyhow() {
    for (name, m) in manifests() {
        if name == "motu-cli" {
            continue;
        }
        assert!(
            !dependencies(&m).iter().any(|d| d == "anyhow"),
            "{name} is a library: thiserror, not anyhow"
        );
    }
}
