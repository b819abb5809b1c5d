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

/// The crates whose `[dependencies]` name `dep`.
fn users_of(dep: &str) -> Vec<String> {
    let mut users: Vec<String> = manifests()
        .into_iter()
        .filter(|(_, m)| dependencies(m).iter().any(|d| d == dep))
        .map(|(n, _)| n)
        .collect();
    users.sort();
    users
}

/// The device layer alone speaks Vulkan; the renderer above it is safe code over its types.
#[test]
fn only_motu_vk_uses_ash() {
    assert_eq!(users_of("ash"), ["motu-vk"]);
    assert_eq!(users_of("ash-window"), ["motu-vk"]);
}

/// The crates above the GPU crate reach the device layer through motu-gpu's re-exports, so
/// the device layer can change under one crate.
#[test]
fn only_motu_gpu_uses_the_device_layer() {
    assert_eq!(users_of("motu-vk"), ["motu-gpu"]);
}

/// Where `unsafe` may appear outside the device layer, and why: each an mmap, an FFI
/// boundary or a SIMD intrinsic no safe API can express.
const UNSAFE_OUTSIDE_THE_DEVICE_LAYER: &[(&str, &str)] = &[
    (
        "pbrt-import/src/source.rs",
        "mmap of a scene file (a truncated input's SIGBUS becomes an error in motu-cli)",
    ),
    (
        "pbrt-import/src/lexer/blocks.rs",
        "SSE2 intrinsics (x86_64 baseline) finding the blanks of mesh arrays 64 bytes at a \
         time, one unaligned load inside the block; the safe loops the compiler was given \
         ran 7-110% slower than the byte loop they replace (imp53, session 53)",
    ),
    (
        "crates/motu-scene/src/edge_file.rs",
        "mmap of an import's own unnamed edge file, and MADV_DONTNEED on it (read-only, \
         nobody else can write it: dropped pages fault back unchanged)",
    ),
    (
        "crates/motu-compile/src/instance_table.rs",
        "shared writable mmap of the compile's own unnamed instance file, grown by remapping, and \
         MADV_DONTNEED on it (dropped pages keep their data in the page cache and fault back)",
    ),
    (
        "crates/motu-compile/src/instance_map.rs",
        "mmap of an import's own unnamed file of the stream split's instances, and MADV_DONTNEED \
         on it (read-only, nobody else can write it: dropped pages fault back unchanged)",
    ),
    (
        "crates/motu-package/src/reader/storage.rs",
        "mmap of a package (offsets validated against the mapped length, chunks checksummed)",
    ),
    (
        "crates/motu-cli/src/signals.rs",
        "the SIGBUS handler (sigaction, async-signal-safe libc calls)",
    ),
    (
        "crates/motu-cli/src/signals/tests.rs",
        "the SIGBUS handler's test maps a file and truncates it under the mapping",
    ),
    (
        "crates/motu-import/src/memory.rs",
        "glibc's malloc_trim after an import's phases (FFI: returns free heap pages to the \
         system, touches no live allocation)",
    ),
    (
        "crates/motu-view/src/app.rs",
        "`Presenter::new` takes winit's raw window handles, whose window must outlive the surface",
    ),
];

/// The lines of `text` that use the `unsafe` keyword, comments left out.
fn unsafe_lines(text: &str) -> Vec<usize> {
    let ident = |c: char| c.is_alphanumeric() || c == '_';
    text.lines()
        .enumerate()
        .filter(|(_, l)| {
            let code = l.split("//").next().unwrap_or("");
            code.match_indices("unsafe").any(|(at, _)| {
                let before = code[..at].chars().next_back();
                let after = code[at + "unsafe".len()..].chars().next();
                !before.is_some_and(ident) && !after.is_some_and(ident)
            })
        })
        .map(|(i, _)| i + 1)
        .collect()
}

/// No `unsafe` outside motu-vk and the named mmap/FFI places: the renderer, the streamer and
/// every other crate are safe code.
#[test]
fn unsafe_only_in_the_device_layer_and_named_places() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut dirs = vec![root.join("pbrt-import/src"), root.join("tests/src")];
    for e in std::fs::read_dir(root.join("crates")).unwrap().flatten() {
        dirs.push(e.path().join("src"));
    }
    let mut device_layer = 0;
    let mut found = Vec::new();
    for dir in dirs.iter().filter(|d| d.exists()) {
        for (path, text) in rust_files(dir) {
            let lines = unsafe_lines(&text);
            if lines.is_empty() {
                continue;
            }
            let rel = path
                .strip_prefix(&root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            if rel.starts_with("crates/motu-vk/") {
                device_layer += lines.len();
            } else if UNSAFE_OUTSIDE_THE_DEVICE_LAYER
                .iter()
                .all(|(allowed, _)| *allowed != rel)
            {
                found.push(format!("{rel}: lines {lines:?}"));
            }
        }
    }
    assert!(
        found.is_empty(),
        "`unsafe` outside motu-vk and the named mmap/FFI places (move the Vulkan call into \
         motu-vk behind a safe API, or name the place and why in this test):\n{}",
        found.join("\n")
    );
    assert!(
        device_layer > 50,
        "the checker sees motu-vk's unsafe ({device_layer} lines)"
    );
    for (allowed, why) in UNSAFE_OUTSIDE_THE_DEVICE_LAYER {
        let text = std::fs::read_to_string(root.join(allowed)).unwrap();
        assert!(
            !unsafe_lines(&text).is_empty(),
            "{allowed} ({why}) has no unsafe any more: take it off the list"
        );
    }
}

/// The checker sees `unsafe` in code and not in comments or longer names.
#[test]
fn the_unsafe_check_reads_code_not_comments() {
    let text =
        "fn a() {}\n// unsafe in a comment\nlet x = unsafe { y() };\n#![deny(unsafe_code)]\n\
                fn b() { c() } // unsafe after code\nunsafe fn d() {}\n";
    assert_eq!(unsafe_lines(text), [3, 6]);
}

#[test]
fn the_window_system_stays_behind_the_viewer_and_the_device_layer() {
    let users = |dep: &str| -> Vec<String> {
        manifests()
            .into_iter()
            .filter(|(_, m)| dependencies(m).iter().any(|d| d == dep))
            .map(|(n, _)| n)
            .collect()
    };
    assert_eq!(users("winit"), ["motu-view"]);
    assert_eq!(users("ash-window"), ["motu-vk"]);
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

#[test]
fn motu_import_stays_below_the_gpu_and_the_cli() {
    let (_, m) = manifests()
        .into_iter()
        .find(|(n, _)| n == "motu-import")
        .unwrap();
    let deps = dependencies(&m);
    for stage in ["motu-ingest", "motu-compile", "motu-pack"] {
        assert!(deps.iter().any(|d| d == stage), "{stage} missing: {deps:?}");
    }
    for above in [
        "motu-gpu",
        "motu-view",
        "motu-report",
        "motu-trace",
        "motu-cli",
        "ash",
        "motu-vk",
    ] {
        assert!(!deps.iter().any(|d| d == above), "motu-import uses {above}");
    }
}

/// The bench harness is a library below the CLI: it never reaches up into the CLI or the
/// viewer, `ash` stays in motu-vk, and `motu bench` in the CLI only parses, delegates, prints.
#[test]
fn motu_bench_stays_below_the_cli() {
    let all = manifests();
    let (_, m) = all.iter().find(|(n, _)| n == "motu-bench").unwrap();
    let deps = dependencies(m);
    assert!(deps.iter().any(|d| d == "motu-gpu"), "{deps:?}");
    for above in ["motu-cli", "motu-view", "ash", "anyhow", "clap"] {
        assert!(!deps.iter().any(|d| d == above), "motu-bench uses {above}");
    }
    let (_, cli) = all.iter().find(|(n, _)| n == "motu-cli").unwrap();
    assert!(dependencies(cli).iter().any(|d| d == "motu-bench"));
    let cmd = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../crates/motu-cli/src/cmd/bench.rs");
    let text = std::fs::read_to_string(&cmd).unwrap();
    for harness in [
        "std::process::Command",
        "fn run_step",
        "fn fill_ratios",
        "fn median",
    ] {
        assert!(
            !text.contains(harness),
            "{} holds {harness}: the harness lives in motu-bench",
            cmd.display()
        );
    }
}

/// Render set-up (package meshes, cameras, scene shading, streaming bounds) and `motu render`'s
/// render paths (the streaming frame loop, the stats) are a library below the CLI, the viewer
/// and the bench harness; it needs no Vulkan of its own (`ash` stays in motu-vk), and the CLI
/// neither holds it nor the camera-path flights.
#[test]
fn motu_render_stays_below_the_cli_the_viewer_and_bench() {
    let all = manifests();
    let (_, m) = all.iter().find(|(n, _)| n == "motu-render").unwrap();
    let deps = dependencies(m);
    assert!(deps.iter().any(|d| d == "motu-pack"), "{deps:?}");
    for above in [
        "motu-cli",
        "motu-view",
        "motu-bench",
        "motu-import",
        "ash",
        "anyhow",
        "clap",
    ] {
        assert!(!deps.iter().any(|d| d == above), "motu-render uses {above}");
    }
    for user in ["motu-cli", "motu-bench"] {
        let (_, u) = all.iter().find(|(n, _)| n == user).unwrap();
        assert!(dependencies(u).iter().any(|d| d == "motu-render"), "{user}");
    }
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../crates/motu-cli/src");
    assert!(
        !src.join("cmd/flight.rs").exists(),
        "flights live in motu-bench"
    );
    for (path, text) in rust_files(&src) {
        for glue in [
            "impl motu_trace::MeshSource",
            "impl motu_gpu::MeshBlobSource",
            "LightKind::",
            "ao_distance",
            "fn percentile",
            "fn choose_lod_mode",
            ".apply_levels(",
            "PI_LOD_SELECTOR",
            "StreamingRenderer::new(ctx, *view",
            // `motu render`'s render paths and stats (motu_render::render).
            "render_counted",
            "streaming_floor",
            "check_validation",
            "mean_passes_after_first",
            "fn contract_stats",
        ] {
            assert!(
                !text.contains(glue),
                "{} holds {glue}: render set-up lives in motu-render, flights in motu-bench",
                path.display()
            );
        }
    }
}

/// `motu view`'s frame source (device opening, the full build or streaming set-up, the
/// per-frame render; the scene's cameras and fly speed) is motu-view's, above motu-render and
/// below the CLI: the viewer never reaches up into the CLI, bench or import, and the CLI drives
/// no renderer itself.
#[test]
fn the_view_frame_source_lives_in_motu_view_not_the_cli() {
    let all = manifests();
    let (_, m) = all.iter().find(|(n, _)| n == "motu-view").unwrap();
    let deps = dependencies(m);
    for below in ["motu-render", "motu-gpu"] {
        assert!(deps.iter().any(|d| d == below), "{below} missing: {deps:?}");
    }
    for above in [
        "motu-cli",
        "motu-bench",
        "motu-import",
        "ash",
        "anyhow",
        "clap",
    ] {
        assert!(!deps.iter().any(|d| d == above), "motu-view uses {above}");
    }
    let view = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../crates/motu-view/src");
    assert!(
        rust_files(&view)
            .iter()
            .any(|(_, t)| t.contains("impl FrameSource for PackageSource")),
        "motu-view holds the package frame source"
    );
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../crates/motu-cli/src");
    for (path, text) in rust_files(&src) {
        for glue in [
            "StreamingRenderer",
            "LiveRenderer",
            "FrameSource for",
            "render_progressive",
            "StreamOptions {",
            "ContextOptions {",
            // The viewer's start over a package (default fly speed from the root's bounds).
            "bounds_max",
        ] {
            assert!(
                !text.contains(glue),
                "{} holds {glue}: the viewer's frame source lives in motu-view",
                path.display()
            );
        }
    }
}

/// The CLI parses arguments and prints; the import pipeline's stages are motu-import's job.
#[test]
fn the_cli_calls_the_import_pipeline_not_its_stages() {
    let src = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../crates/motu-cli/src");
    for (path, text) in rust_files(&src) {
        for stage in [
            "motu_ingest::",
            "compile_with_loader",
            "write_hierarchy",
            "PackageGeometry",
        ] {
            assert!(
                !text.contains(stage),
                "{} uses {stage}: the import pipeline lives in motu-import",
                path.display()
            );
        }
    }
}

/// Every `.rs` file under `dir` with its text (build output and hidden folders left out).
fn rust_files(dir: &std::path::Path) -> Vec<(PathBuf, String)> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                let name = e.file_name();
                let name = name.to_string_lossy();
                if !(name.starts_with('.') || name == "target") {
                    todo.push(p);
                }
            } else if p.extension().is_some_and(|x| x == "rs") {
                let text = std::fs::read_to_string(&p).unwrap();
                out.push((p, text));
            }
        }
    }
    out.sort();
    out
}

/// The module path of a source file (`cmd/render.rs` → `["cmd", "render"]`).
fn module_of(src: &std::path::Path, file: &std::path::Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().into_owned())
        .collect();
    if matches!(
        parts.last().map(String::as_str),
        Some("mod" | "lib" | "main")
    ) {
        parts.pop();
    }
    parts
}

/// Which files of a crate each file uses, by `crate::…`/`super::…` paths in its code (doc and
/// line comments and the unit-test module at the end are left out). A module's own child files
/// (one `impl` split by job, like pbrt-import's `parser/`) count as part of it.
fn file_uses(src: &std::path::Path) -> Vec<(String, Vec<String>)> {
    let files = rust_files(src);
    let modules: Vec<Vec<String>> = files.iter().map(|(p, _)| module_of(src, p)).collect();
    let mut out = Vec::new();
    for ((_, text), me) in files.iter().zip(&modules) {
        let code = text
            .split("#[cfg(test)]\nmod tests")
            .next()
            .unwrap()
            .lines()
            .filter(|l| !l.trim_start().starts_with("//"))
            .collect::<Vec<_>>()
            .join("\n");
        let mut refs: Vec<Vec<String>> = Vec::new();
        for (anchor, base) in [
            ("crate::", Vec::new()),
            ("super::", me[..me.len().saturating_sub(1)].to_vec()),
        ] {
            // `super::` is the file's parent module (`cmd/render.rs` → `cmd`, `cmd/mod.rs` → the
            // crate root).
            for (at, _) in code.match_indices(anchor) {
                let before = code[..at].chars().last();
                if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                    continue;
                }
                let rest = &code[at + anchor.len()..];
                let mut path = base.clone();
                if let Some(group) = rest.strip_prefix('{') {
                    // `use crate::{a::x, b::y}`: each entry's first segment.
                    let group = &group[..group.find('}').unwrap_or(group.len())];
                    for item in group.split(',') {
                        let seg: String = item
                            .trim()
                            .chars()
                            .take_while(|c| c.is_alphanumeric() || *c == '_')
                            .collect();
                        let mut p = path.clone();
                        p.push(seg);
                        refs.push(p);
                    }
                    continue;
                }
                for seg in rest.split("::") {
                    let name: String = seg
                        .chars()
                        .take_while(|c| c.is_alphanumeric() || *c == '_')
                        .collect();
                    let whole = name.len() == seg.len();
                    path.push(name);
                    if !whole {
                        break;
                    }
                }
                refs.push(path);
            }
        }
        let mut uses: Vec<String> = Vec::new();
        for r in refs {
            // The longest file module the path starts with.
            let Some(target) = modules
                .iter()
                .filter(|m| !m.is_empty() && r.starts_with(m))
                .max_by_key(|m| m.len())
            else {
                continue;
            };
            // Not itself, its ancestors (a child file of a split module) or its descendants.
            if me.starts_with(target) || target.starts_with(me) {
                continue;
            }
            let t = target.join("::");
            if !uses.contains(&t) {
                uses.push(t);
            }
        }
        out.push((me.join("::"), uses));
    }
    out
}

/// A circle of files, if any (depth-first search for a back edge).
fn file_circle(uses: &[(String, Vec<String>)]) -> Option<Vec<String>> {
    fn visit(
        n: &str,
        uses: &[(String, Vec<String>)],
        stack: &mut Vec<String>,
        done: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = stack.iter().position(|s| s == n) {
            let mut circle = stack[i..].to_vec();
            circle.push(n.to_string());
            return Some(circle);
        }
        if done.iter().any(|d| d == n) {
            return None;
        }
        stack.push(n.to_string());
        let next = uses.iter().find(|(m, _)| m == n).map(|(_, u)| u.clone());
        for m in next.unwrap_or_default() {
            if let Some(c) = visit(&m, uses, stack, done) {
                return Some(c);
            }
        }
        stack.pop();
        done.push(n.to_string());
        None
    }
    let mut done = Vec::new();
    uses.iter()
        .find_map(|(n, _)| visit(n, uses, &mut Vec::new(), &mut done))
}

/// Each file uses only files below it: no circles of `crate::`/`super::` uses between the
/// files of a crate (every crate, motu-gpu's `stream/` folder included).
#[test]
fn no_use_circles_between_files() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut crates = vec![root.join("pbrt-import/src")];
    for e in std::fs::read_dir(root.join("crates")).unwrap().flatten() {
        crates.push(e.path().join("src"));
    }
    let mut all = Vec::new();
    for src in crates.iter().filter(|s| s.exists()) {
        let uses = file_uses(src);
        all.extend(
            uses.iter()
                .map(|(m, u)| (src.clone(), m.clone(), u.clone())),
        );
        if let Some(circle) = file_circle(&uses) {
            panic!(
                "{}: files use each other: {}",
                src.display(),
                circle.join(" → ")
            );
        }
    }
    // The reader sees real uses (so a pass means something): known edges of the fixed crates.
    for (krate, from, to) in [
        ("pbrt-import/src", "parser", "parallel"),
        ("pbrt-import/src", "parallel", "lexer"),
        ("motu-report/src", "budget", "rows"),
        ("motu-report/src", "presets", "sizes"),
        ("motu-cli/src", "cmd::demo", "cmd::render"),
        ("motu-trace/src", "traverse", "coverage"),
        ("motu-trace/src", "shade", "options"),
        ("motu-trace/src", "render", "shade"),
        ("motu-gpu/src", "lod_instances", "scene"),
        ("motu-gpu/src", "render", "scene"),
        ("motu-gpu/src", "stream::passes", "stream::params"),
        ("motu-gpu/src", "stream::buffers", "stream::params"),
        ("motu-vk/src", "command", "conv"),
        ("motu-vk/src", "conv", "accel"),
        ("motu-vk/src", "structure", "heap"),
    ] {
        assert!(
            all.iter()
                .any(|(s, m, u)| s.ends_with(krate) && m == from && u.iter().any(|x| x == to)),
            "{krate}: {from} should be seen using {to}"
        );
    }
}

/// The checker sees the circles the structure issue found (a test that it can fail).
#[test]
fn the_circle_check_finds_a_circle() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path();
    std::fs::write(src.join("lib.rs"), "mod a;\nmod b;\n").unwrap();
    std::fs::write(src.join("a.rs"), "use crate::b::x;\npub fn y() {}\n").unwrap();
    std::fs::write(src.join("b.rs"), "pub fn x() { crate::a::y() }\n").unwrap();
    let circle = file_circle(&file_uses(src)).expect("a circle");
    assert!(circle.contains(&"a".to_string()) && circle.contains(&"b".to_string()));
    std::fs::write(src.join("b.rs"), "/// [`crate::a::y`]\npub fn x() {}\n").unwrap();
    assert_eq!(
        file_circle(&file_uses(src)),
        None,
        "doc comments are not uses"
    );
}

/// `text` with comments, string and character literals blanked (newlines kept), so that
/// braces and `fn` are seen only in code. Lifetimes (`'a`) stay.
fn code_only(text: &str) -> String {
    let c: Vec<char> = text.chars().collect();
    let mut out = String::with_capacity(text.len());
    let blank = |out: &mut String, s: &[char]| {
        out.extend(s.iter().map(|&ch| if ch == '\n' { '\n' } else { ' ' }))
    };
    let mut i = 0;
    while i < c.len() {
        let rest = &c[i..];
        let end = if rest.starts_with(&['/', '/']) {
            rest.iter().position(|&ch| ch == '\n').unwrap_or(rest.len())
        } else if rest.starts_with(&['/', '*']) {
            // Block comments nest in Rust.
            let (mut depth, mut k) = (0, 0);
            while k < rest.len() {
                if rest[k..].starts_with(&['/', '*']) {
                    depth += 1;
                    k += 2;
                } else if rest[k..].starts_with(&['*', '/']) {
                    depth -= 1;
                    k += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    k += 1;
                }
            }
            k
        } else if rest[0] == 'r'
            && (i == 0 || !(c[i - 1].is_alphanumeric() || c[i - 1] == '_'))
            && rest.len() > 1
            && (rest[1] == '"' || rest[1] == '#')
        {
            // A raw string: r"…", r#"…"#.
            let hashes = rest[1..].iter().take_while(|&&ch| ch == '#').count();
            if rest.get(1 + hashes) != Some(&'"') {
                1
            } else {
                let mut k = 2 + hashes;
                while k < rest.len()
                    && !(rest[k] == '"' && rest[k + 1..].iter().take(hashes).all(|&h| h == '#'))
                {
                    k += 1;
                }
                (k + 1 + hashes).min(rest.len())
            }
        } else if rest[0] == '"' {
            let mut k = 1;
            while k < rest.len() && rest[k] != '"' {
                k += if rest[k] == '\\' { 2 } else { 1 };
            }
            (k + 1).min(rest.len())
        } else if rest[0] == '\'' && rest.get(1) == Some(&'\\') {
            // An escaped character: '\n', '\'', '\u{…}'.
            2 + rest[2..]
                .iter()
                .skip(1)
                .position(|&ch| ch == '\'')
                .map_or(0, |p| p + 2)
        } else if rest[0] == '\'' && rest.get(2) == Some(&'\'') {
            3
        } else {
            out.push(rest[0]);
            i += 1;
            continue;
        };
        blank(&mut out, &rest[..end]);
        i += end;
    }
    out
}

/// Every function with a body in `text`: its name, first line and length in lines (from the
/// `fn` line to the closing brace's).
fn fn_lengths(text: &str) -> Vec<(String, usize, usize)> {
    let code = code_only(text);
    let b = code.as_bytes();
    let ident = |ch: u8| ch.is_ascii_alphanumeric() || ch == b'_';
    let line_of = |at: usize| code[..at].matches('\n').count() + 1;
    let mut out = Vec::new();
    for (at, _) in code.match_indices("fn") {
        let before_ok = at == 0 || !ident(b[at - 1]);
        let after = b.get(at + 2).copied().unwrap_or(b' ');
        if !before_ok || !after.is_ascii_whitespace() {
            continue;
        }
        let name: String = code[at + 2..]
            .trim_start()
            .chars()
            .take_while(|&ch| ch.is_alphanumeric() || ch == '_')
            .collect();
        if name.is_empty() {
            continue;
        }
        // The body: the first `{` before any `;` (a declaration without a body).
        let Some(open) = code[at..].find(['{', ';']).map(|k| at + k) else {
            continue;
        };
        if b[open] == b';' {
            continue;
        }
        let mut depth = 0usize;
        let mut close = open;
        for (k, &ch) in b.iter().enumerate().skip(open) {
            match ch {
                b'{' => depth += 1,
                b'}' => {
                    depth -= 1;
                    if depth == 0 {
                        close = k;
                        break;
                    }
                }
                _ => {}
            }
        }
        let first = line_of(at);
        out.push((name, first, line_of(close) - first + 1));
    }
    out
}

/// The GPU crate's procedures stay readable: no function in `crates/motu-gpu/src` (the
/// streamer, the renderer, the scene build, their tests) or in the device layer under it
/// (`crates/motu-vk/src`) over 150 lines; a long procedure becomes a context struct with a
/// method per phase (issue 46).
#[test]
fn no_long_functions_in_motu_gpu() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut long = Vec::new();
    let mut seen = 0;
    let mut streamer = 0;
    let mut device_layer = 0;
    for dir in ["crates/motu-gpu/src", "crates/motu-vk/src"] {
        for (path, text) in rust_files(&root.join(dir)) {
            let rel = path.strip_prefix(&root).unwrap().display().to_string();
            for (name, line, lines) in fn_lengths(&text) {
                seen += 1;
                if rel.contains("/stream") {
                    streamer += 1;
                }
                if rel.contains("motu-vk") {
                    device_layer += 1;
                }
                if lines > 150 {
                    long.push(format!("{rel}:{line}: fn {name}: {lines} lines"));
                }
            }
        }
    }
    assert!(
        seen > 300 && streamer > 100 && device_layer > 100,
        "the scan sees motu-gpu's and motu-vk's functions ({seen}, {streamer} in the streamer, \
         {device_layer} in the device layer)"
    );
    assert!(
        long.is_empty(),
        "functions over 150 lines in motu-gpu or motu-vk (split them into phases):\n{}",
        long.join("\n")
    );
}

/// Every `.rs` file of the repository whose path does not name tests (`tests/`, `tests.rs`):
/// (path relative to the root, line count).
fn non_test_file_lengths(root: &std::path::Path) -> Vec<(String, usize)> {
    rust_files(root)
        .into_iter()
        .filter_map(|(path, text)| {
            let rel = path
                .strip_prefix(root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            (!rel.contains("tests")).then(|| (rel, text.lines().count()))
        })
        .collect()
}

/// Files a reader can hold (issue 46): no non-test `.rs` file over 800 lines; a longer one is
/// split by job into `foo.rs` + `foo/` (tests in `<module>/tests.rs` do not count).
#[test]
fn no_long_files() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let files = non_test_file_lengths(&root);
    assert!(
        files.len() > 300
            && files
                .iter()
                .any(|(f, _)| f.ends_with("motu-gpu/src/lib.rs")),
        "the scan sees the sources ({} files)",
        files.len()
    );
    let long: Vec<String> = files
        .iter()
        .filter(|(_, lines)| *lines > 800)
        .map(|(f, lines)| format!("{f}: {lines} lines"))
        .collect();
    assert!(
        long.is_empty(),
        "non-test files over 800 lines (split each by job into foo.rs + foo/):\n{}",
        long.join("\n")
    );
}

/// The length scan matches braces in code only and skips declarations.
#[test]
fn the_function_scan_reads_code_not_strings_or_comments() {
    let text = "trait T { fn decl(&self); }\n\
                fn a<'x>(s: &'x str) -> char {\n\
                    let _ = \"}}} fn fake() {\";\n\
                    // } fn in a comment {\n\
                    let _ = r#\"}\"#; /* { /* } */ { */\n\
                    if s.is_empty() { '}' } else { '\\'' }\n\
                }\n\
                fn b() {}\n";
    let got = fn_lengths(text);
    assert_eq!(
        got,
        [("a".to_string(), 2, 6), ("b".to_string(), 8, 1)],
        "{got:?}"
    );
}

/// The source folders of every crate: `crates/*/src`, `pbrt-import/src` and its fuzz crate's,
/// and the integration-test crate's `src`.
fn source_dirs(root: &std::path::Path) -> Vec<PathBuf> {
    let mut dirs = vec![
        root.join("pbrt-import/src"),
        root.join("pbrt-import/fuzz/src"),
        root.join("pbrt-import/fuzz/fuzz_targets"),
        root.join("tests/src"),
    ];
    for e in std::fs::read_dir(root.join("crates")).unwrap().flatten() {
        dirs.push(e.path().join("src"));
    }
    dirs.retain(|d| d.exists());
    dirs.sort();
    dirs
}

/// How a source file breaks the one layout habit, if it does: a module's tests in
/// `<module>/tests.rs` (not inline, not a crate-root `*_tests.rs`, not `#[path]`), test helpers
/// in `testutil`, and `foo.rs` + `foo/` rather than `foo/mod.rs`.
fn layout_faults(rel: &str, text: &str) -> Vec<String> {
    let mut faults = Vec::new();
    let name = rel.rsplit('/').next().unwrap_or(rel);
    if name == "mod.rs" {
        faults.push("a mod.rs file (write foo.rs beside foo/)".to_string());
    }
    if name.ends_with("_tests.rs") || name == "proptests.rs" {
        faults.push("a *_tests.rs file (a module's tests go in <module>/tests.rs)".to_string());
    }
    if matches!(
        name,
        "fixtures.rs" | "helpers.rs" | "test_helpers.rs" | "test_util.rs" | "testing.rs"
    ) {
        faults.push("a test-helper module not named testutil".to_string());
    }
    let code = code_only(text);
    let lines: Vec<&str> = code.lines().collect();
    for (i, line) in lines.iter().enumerate() {
        let t = line.trim_start();
        if t.starts_with("#[path") {
            faults.push(format!("line {}: a #[path] attribute", i + 1));
        }
        // A test module written inline (`#[cfg(test)] mod x {`), not in its own file.
        let after_cfg_test = lines[..i]
            .iter()
            .rev()
            .map(|l| l.trim())
            .find(|l| !l.is_empty() && !l.starts_with("#[allow"))
            .is_some_and(|l| l == "#[cfg(test)]");
        if after_cfg_test && t.starts_with("mod ") && t.trim_end().ends_with('{') {
            faults.push(format!(
                "line {}: an inline test module (move it to <module>/tests.rs)",
                i + 1
            ));
        }
        if after_cfg_test && t.starts_with("mod ") && t.trim_end().ends_with(';') {
            let module = t["mod ".len()..].trim_end().trim_end_matches(';');
            if !matches!(module, "tests" | "testutil") {
                faults.push(format!(
                    "line {}: test module `{module}` (tests are `tests`, helpers `testutil`)",
                    i + 1
                ));
            }
        }
    }
    faults
}

/// One layout habit in every crate (issue 46 item 6): tests in `<module>/tests.rs`, helpers in
/// `testutil`, no `mod.rs`, no `#[path]`, no `*_tests.rs`.
#[test]
fn one_module_layout_everywhere() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut found = Vec::new();
    let mut files = 0;
    for dir in source_dirs(&root) {
        for (path, text) in rust_files(&dir) {
            files += 1;
            let rel = path
                .strip_prefix(&root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            let faults = layout_faults(&rel, &text);
            found.extend(faults.into_iter().map(|f| format!("{rel}: {f}")));
        }
    }
    assert!(
        files > 300,
        "the layout check sees the sources ({files} files)"
    );
    assert!(
        found.is_empty(),
        "files off the one layout habit (`#[cfg(test)] mod tests;` with the tests in \
         <module>/tests.rs, helpers in testutil, foo.rs + foo/):\n{}",
        found.join("\n")
    );
}

/// The layout check sees each fault it names (a test that it can fail).
#[test]
fn the_layout_check_finds_each_fault() {
    let clean = "pub fn a() {}\n\n#[cfg(test)]\nmod tests;\n";
    assert!(layout_faults("crates/x/src/a.rs", clean).is_empty());
    let doc = "/// #[path = \"x.rs\"] in a comment\nfn f() { let s = \"mod tests {\"; }\n";
    assert!(layout_faults("crates/x/src/a.rs", doc).is_empty());
    for (rel, text) in [
        ("crates/x/src/a/mod.rs", ""),
        ("crates/x/src/a_tests.rs", ""),
        ("crates/x/src/fixtures.rs", ""),
        (
            "crates/x/src/a.rs",
            "#[cfg(test)]\n#[path = \"a_tests.rs\"]\nmod tests;\n",
        ),
        (
            "crates/x/src/a.rs",
            "#[cfg(test)]\nmod tests {\n    #[test]\n    fn t() {}\n}\n",
        ),
        ("crates/x/src/a.rs", "#[cfg(test)]\nmod proptests;\n"),
    ] {
        assert!(!layout_faults(rel, text).is_empty(), "{rel}: {text:?}");
    }
}

/// Each `map_err` closure in `text` that builds an error (`XError::…`, `XError { … }`, or a
/// local `err`/`invalid`/`bad` helper) from its argument's text (`e.to_string()`, `{e}` in a
/// format string): (line, the closure body). Comments are left out; strings are kept.
fn stringified_causes(text: &str) -> Vec<(usize, String)> {
    let no_comments: String = text
        .lines()
        .map(|l| match l.find("//") {
            Some(at) if !l[..at].contains('"') => &l[..at],
            _ => l,
        })
        .collect::<Vec<_>>()
        .join("\n");
    let t = no_comments.as_str();
    let ident_char = |c: char| c.is_alphanumeric() || c == '_';
    let mut found = Vec::new();
    let mut from = 0;
    while let Some(at) = t[from..].find("map_err(") {
        let start = from + at + "map_err(".len();
        from = start;
        let rest = t[start..].trim_start();
        let rest = rest.strip_prefix("move").unwrap_or(rest).trim_start();
        let Some(params) = rest.strip_prefix('|') else {
            continue;
        };
        let Some(close) = params.find('|') else {
            continue;
        };
        // The closure's argument: the last name in its parameter list (`|e|`, `|(i, e)|`),
        // its type left out (`|e: E|`).
        let list = &params[..close];
        let list = list.split(':').next().unwrap_or(list);
        let Some(ident) = list
            .split(|c: char| !ident_char(c))
            .rfind(|s| !s.is_empty())
        else {
            continue;
        };
        // The body: up to the parenthesis that closes `map_err(`.
        let body_start = t.len() - params[close + 1..].len();
        let mut depth = 1;
        let mut end = body_start;
        for (i, c) in t[body_start..].char_indices() {
            match c {
                '(' => depth += 1,
                ')' => depth -= 1,
                _ => {}
            }
            if depth == 0 {
                end = body_start + i;
                break;
            }
        }
        let body = &t[body_start..end];
        let word_at = |s: &str, at: usize| {
            !s[..at].chars().next_back().is_some_and(ident_char)
                && !s[at..].chars().nth(ident.len()).is_some_and(ident_char)
        };
        let stringified = body
            .match_indices(&format!("{ident}.to_string()"))
            .any(|(i, _)| word_at(body, i))
            || body.contains(&format!("{{{ident}}}"))
            || body.contains(&format!("{{{ident}:"));
        // Words of code only: a message's words ("bad stats") are not calls.
        let code = code_only(body);
        let builds_error = code.split(|c: char| !ident_char(c)).any(|w| {
            (w.ends_with("Error") && w.starts_with(|c: char| c.is_uppercase()))
                || ((w.contains("err") || w.contains("invalid") || w.contains("bad"))
                    && w != ident
                    && w.starts_with(|c: char| c.is_lowercase()))
        });
        if stringified && builds_error {
            let line = t[..start].matches('\n').count() + 1;
            found.push((line, body.split_whitespace().collect::<Vec<_>>().join(" ")));
        }
    }
    found
}

/// Errors keep their cause (issue 46 item 4): no library error is built from another error's
/// text (`e.to_string()`, `format!("…{e}")`); a variant holds the typed cause as `#[source]`
/// (or `#[from]`, or `#[error(transparent)]`), so `Error::source()` walks the chain and the
/// CLI prints each cause once.
#[test]
fn errors_keep_their_cause() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let mut found = Vec::new();
    for dir in source_dirs(&root) {
        for (path, text) in rust_files(&dir) {
            let rel = path
                .strip_prefix(&root)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            let name = rel.rsplit('/').next().unwrap_or("");
            // Tests may stringify errors to assert on their text.
            if matches!(name, "tests.rs" | "testutil.rs") || rel.contains("/fuzz") {
                continue;
            }
            for (line, body) in stringified_causes(&text) {
                found.push(format!("{rel}:{line}: {body}"));
            }
        }
    }
    assert!(
        found.is_empty(),
        "errors built from another error's text (keep the cause: a variant with a \
         `#[source]` field, or `#[from]`; the message may still show it):\n{}",
        found.join("\n")
    );
}

/// The cause check sees the patterns it names and not their fixed forms.
#[test]
fn the_cause_check_finds_stringified_causes() {
    for bad in [
        "x.map_err(|e| PackError::Schema { path, reason: e.to_string() })?;",
        "x.map_err(|e| GpuError::InvalidRequest(format!(\"mesh {m}: {e}\")))?;",
        "x.map_err(|e| invalid(e.to_string()))?;",
        "x.map_err(|(i, e)| VkError::Budget(format!(\"{}: {e}\", w[i])))",
        "x.map_err(move |err| SinkError::new(format!(\"{at}: {err:?}\")))",
    ] {
        assert_eq!(stringified_causes(bad).len(), 1, "{bad}");
    }
    for good in [
        "x.map_err(|source| PackError::Meta { path, source })?;",
        "x.map_err(ReportError::Floor)?;",
        "x.map_err(|e| e.to_string())?; // a String error, not an error type",
        "x.map_err(|_| CompileError::Internal(format!(\"node {n} is unreachable\")))?;",
        "// x.map_err(|e| Error::A(e.to_string()))",
        "x.map_err(|reason| PackError::Mesh { mesh, reason })?;",
    ] {
        assert!(stringified_causes(good).is_empty(), "{good}");
    }
}

/// ARCHITECTURE.md maps every crate in a short section of its own (job, key types, invariants:
/// at most ~10 lines, the detail in the crate's `//!` docs) and no line runs past 200 characters.
#[test]
fn architecture_md_has_a_short_section_per_crate_and_short_lines() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    let text = std::fs::read_to_string(root.join("ARCHITECTURE.md")).unwrap();
    let long: Vec<(usize, usize)> = text
        .lines()
        .enumerate()
        .filter(|(_, l)| l.chars().count() > 200)
        .map(|(i, l)| (i + 1, l.chars().count()))
        .collect();
    assert!(
        long.is_empty(),
        "lines over 200 characters (line, length): {long:?}"
    );
    // Each `### ` section's non-empty lines, by heading.
    let mut sections: Vec<(String, usize)> = Vec::new();
    for line in text.lines() {
        if let Some(h) = line.strip_prefix("### ") {
            sections.push((h.to_string(), 0));
        } else if line.starts_with("## ") {
            sections.push((String::new(), 0));
        } else if !line.trim().is_empty() {
            if let Some(s) = sections.last_mut() {
                s.1 += 1;
            }
        }
    }
    for (name, _) in manifests() {
        let path = if name == "pbrt-import" {
            "`pbrt-import/`".to_string()
        } else {
            format!("`crates/{name}`")
        };
        let Some((_, lines)) = sections.iter().find(|(h, _)| *h == path) else {
            panic!("ARCHITECTURE.md has no `### {path}` section");
        };
        assert!(
            (2..=10).contains(lines),
            "ARCHITECTURE.md's section {path} has {lines} lines (a job, key types and invariants in at most 10)"
        );
    }
}

/// The error types defined in `text`: enums and structs that derive an `Error`
/// (`#[derive(…, thiserror::Error)]`) or implement `std::error::Error` by hand.
fn error_types_defined(text: &str) -> Vec<String> {
    let code = code_only(text);
    let lines: Vec<&str> = code.lines().collect();
    let mut names = Vec::new();
    let decl_name = |l: &str| -> Option<String> {
        let t = l.trim_start();
        let t = t
            .strip_prefix("pub(crate) ")
            .or_else(|| t.strip_prefix("pub(super) "));
        let t = t.unwrap_or(l.trim_start());
        let t = t.strip_prefix("pub ").unwrap_or(t);
        let rest = t
            .strip_prefix("enum ")
            .or_else(|| t.strip_prefix("struct "))?;
        let name: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        (!name.is_empty()).then_some(name)
    };
    for (i, line) in lines.iter().enumerate() {
        let Some(name) = decl_name(line) else {
            continue;
        };
        // The attributes right above the declaration.
        let derives_error = lines[..i]
            .iter()
            .rev()
            .map(|l| l.trim())
            .take_while(|l| l.starts_with("#[") || l.ends_with(')') || l.ends_with(','))
            .any(|l| {
                l.contains("Error")
                    && l.split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                        .any(|w| w == "Error" || w == "thiserror::Error")
            });
        let implements_error = code.contains(&format!("Error for {name} "))
            && (code.contains(&format!("impl std::error::Error for {name} "))
                || code.contains(&format!("impl Error for {name} ")));
        if derives_error || implements_error {
            names.push(name);
        }
    }
    names
}

/// Where `code_only` text `code` builds an error type another crate owns (issue 46 item 4,
/// "each crate builds only its own error type"): (line, `Type::Variant`, `Type { … }` or
/// `Type(…)`). `user`: the crate ident whose code this is (`motu_render`); `owners`: (error
/// type, owning crate ident) for every crate; `crates`: every workspace crate's ident.
///
/// A path counts as a construction unless it stands in a pattern: the left of a `let`/`if
/// let`/`while let` `=`, a `match` arm before its `=>`, or inside `matches!(…)`. Naming the
/// type is not building it (`-> GpuError`, `#[from] VkError`, `impl From<VkError>`), nor is
/// calling a constructor the owner publishes (`SinkError::new`, `BudgetRefusal::from_cause`:
/// the owner chose to let others build it). A path through another, non-workspace crate
/// (`std::io::Error`, `tobj::LoadError`) is not a workspace type; the bare name `Error` counts
/// only with its crate's path (`pbrt_import::Error::…`).
fn foreign_error_constructions(
    code: &str,
    user: &str,
    owners: &[(String, String)],
    crates: &[String],
) -> Vec<(usize, String)> {
    let b = code.as_bytes();
    let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    let mut found = Vec::new();
    let mut names: Vec<&str> = owners.iter().map(|(n, _)| n.as_str()).collect();
    names.sort();
    names.dedup();
    let defined_by = |name: &str, krate: &str| owners.iter().any(|(n, c)| n == name && c == krate);
    for name in names {
        for (at, _) in code.match_indices(name) {
            let end = at + name.len();
            if (at > 0 && ident(b[at - 1])) || b.get(end).copied().is_some_and(ident) {
                continue;
            }
            // The path before the name: `motu_vk::VkError` → first segment `motu_vk`.
            let mut start = at;
            while start >= 2 && &code[start - 2..start] == "::" {
                let mut s = start - 2;
                while s > 0 && ident(b[s - 1]) {
                    s -= 1;
                }
                start = s;
            }
            let first = code[start..at].split("::").next().unwrap_or("");
            let foreign = if first.is_empty() {
                name != "Error" && !defined_by(name, user) && owners.iter().any(|(n, _)| n == name)
            } else if crates.iter().any(|c| c == first) {
                first != user && owners.iter().any(|(n, c)| n == name && c != user)
            } else {
                // `crate::`, `self::`, `super::`: the user's own; another crate's path
                // (`std::`, `tobj::`): not a workspace type.
                false
            };
            if !foreign {
                continue;
            }
            // What follows the name: a variant, a struct literal or a tuple-struct call.
            let rest = &code[end..];
            let after = rest.trim_start();
            let (what, path_end) = if let Some(v) = after.strip_prefix("::") {
                let v = v.trim_start();
                let variant: String = v
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                if !variant.starts_with(|c: char| c.is_ascii_uppercase()) {
                    continue;
                }
                let off = code.len() - v.len() + variant.len();
                (format!("{name}::{variant}"), off)
            } else if after.starts_with('{') || after.starts_with('(') {
                // Not a type named before a body: `-> GpuError {`, `impl … for X {`.
                let before = code[..start].trim_end();
                if ["->", "impl", "for", "struct", "enum", "dyn", "as"]
                    .iter()
                    .any(|w| before.ends_with(w))
                {
                    continue;
                }
                (format!("{name} {}", &after[..1]), end)
            } else {
                continue;
            };
            if !in_pattern(code, start, path_end) {
                let line = code[..at].matches('\n').count() + 1;
                found.push((line, what));
            }
        }
    }
    found.sort();
    found
}

/// Whether the path `code[start..end]` stands in a pattern (see
/// [`foreign_error_constructions`]): read forward to the end of its expression or pattern.
fn in_pattern(code: &str, start: usize, end: usize) -> bool {
    // The brackets around the path, innermost first: `(` with whether `matches!` opens it.
    let mut enclosing: Vec<(u8, bool)> = Vec::new();
    let mut depth = 0i32;
    let b = code.as_bytes();
    for k in (0..start).rev() {
        match b[k] {
            b')' | b']' | b'}' => depth += 1,
            b'(' | b'[' | b'{' if depth > 0 => depth -= 1,
            c @ (b'(' | b'[' | b'{') => {
                let macro_call = code[..k].trim_end().ends_with("matches!");
                enclosing.push((c, macro_call));
                if c == b'{' {
                    break;
                }
            }
            b';' if depth == 0 => break,
            _ => {}
        }
    }
    if enclosing.iter().any(|&(c, m)| c == b'(' && m) {
        return true;
    }
    let mut depth = 0i32;
    let mut k = end;
    let mut climbed = 0;
    while k < b.len() {
        let c = b[k];
        let next = b.get(k + 1).copied().unwrap_or(b' ');
        let prev = if k > 0 { b[k - 1] } else { b' ' };
        match c {
            b'(' | b'[' | b'{' => depth += 1,
            b'}' if depth == 0 => return false,
            b')' | b']' if depth == 0 => climbed += 1,
            b')' | b']' | b'}' => depth -= 1,
            b';' if depth == 0 => return false,
            b',' if depth == 0 => {
                // A comma of the block around it (a match arm's end, a struct literal's
                // field) ends the expression; one inside a tuple or call does not.
                match enclosing.get(climbed) {
                    Some((b'(' | b'[', _)) => {}
                    _ => return false,
                }
            }
            b'=' if depth == 0 && next == b'>' => return true,
            b'=' if depth == 0
                && next != b'='
                && !matches!(
                    prev,
                    b'=' | b'!'
                        | b'<'
                        | b'>'
                        | b'+'
                        | b'-'
                        | b'*'
                        | b'/'
                        | b'%'
                        | b'&'
                        | b'|'
                        | b'^'
                ) =>
            {
                return true
            }
            _ => {}
        }
        k += 1;
    }
    false
}

/// Each crate builds only its own error type (issue 46 item 4): no library code constructs a
/// variant (or a struct) of an error type another crate owns; a crate wraps the other's error
/// as the `#[source]`/`#[from]` of its own (matching on it is fine). Tests may build any.
#[test]
fn each_crate_builds_only_its_own_error_type() {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("..");
    // (crate ident, its non-test files).
    let mut crates: Vec<(String, Vec<(PathBuf, String)>)> = Vec::new();
    let mut dirs = vec![("pbrt_import".to_string(), root.join("pbrt-import/src"))];
    for e in std::fs::read_dir(root.join("crates")).unwrap().flatten() {
        let name = e.file_name().to_string_lossy().replace('-', "_");
        dirs.push((name, e.path().join("src")));
    }
    for (name, dir) in dirs.into_iter().filter(|(_, d)| d.exists()) {
        let files = rust_files(&dir)
            .into_iter()
            .filter(|(p, _)| {
                let rel = p.strip_prefix(&dir).unwrap();
                let n = p.file_name().unwrap().to_string_lossy();
                n != "tests.rs"
                    && n != "testutil.rs"
                    && !rel.components().any(|c| c.as_os_str() == "tests")
            })
            .collect();
        crates.push((name, files));
    }
    let idents: Vec<String> = crates.iter().map(|(n, _)| n.clone()).collect();
    let owners: Vec<(String, String)> = crates
        .iter()
        .flat_map(|(krate, files)| {
            files.iter().flat_map(move |(_, text)| {
                error_types_defined(text)
                    .into_iter()
                    .map(move |t| (t, krate.clone()))
            })
        })
        .collect();
    for (ty, krate) in [
        ("GpuError", "motu_gpu"),
        ("VkError", "motu_vk"),
        ("Error", "pbrt_import"),
    ] {
        assert!(
            owners.iter().any(|(t, c)| t == ty && c == krate),
            "the scan sees {krate}'s {ty} ({} error types)",
            owners.len()
        );
    }
    let mut found = Vec::new();
    for (krate, files) in &crates {
        for (path, text) in files {
            let rel = path.strip_prefix(&root).unwrap().display().to_string();
            for (line, what) in
                foreign_error_constructions(&code_only(text), krate, &owners, &idents)
            {
                found.push(format!("{rel}:{line}: {what}"));
            }
        }
    }
    assert!(
        found.is_empty(),
        "another crate's error type built here (give this crate a variant of its own that \
         keeps the other's error as its #[source], or ask the owner for a constructor):\n{}",
        found.join("\n")
    );
}

/// The error-type check finds each way of building another crate's error and none of the
/// ways of only naming or matching it.
#[test]
fn the_error_type_check_finds_foreign_constructions() {
    let owners: Vec<(String, String)> = [
        ("GpuError", "motu_gpu"),
        ("SinkError", "pbrt_import"),
        ("HierarchyError", "motu_abi"),
        ("Error", "pbrt_import"),
        ("RenderError", "motu_render"),
    ]
    .iter()
    .map(|(t, c)| (t.to_string(), c.to_string()))
    .collect();
    let crates: Vec<String> = [
        "motu_gpu",
        "pbrt_import",
        "motu_abi",
        "motu_render",
        "motu_cli",
    ]
    .iter()
    .map(|c| c.to_string())
    .collect();
    let scan =
        |text: &str| foreign_error_constructions(&code_only(text), "motu_render", &owners, &crates);
    for bad in [
        "fn f() -> Result<(), GpuError> { Err(motu_gpu::GpuError::InvalidRequest(\"x\".into())) }",
        "fn f() -> R { x.map_err(GpuError::Budget)?; Ok(()) }",
        "fn f() { return Err(SinkError(Box::new(e))); }",
        "fn f() { let e = HierarchyError { at: 1 }; }",
        "fn f() -> E { match k { A => GpuError::Budget(r), B => x } }",
        "fn f() -> E { let e = if a { GpuError::Budget(r) } else { y }; e }",
        "fn f() { g(1, GpuError::InvalidRequest(s), 2); }",
        "fn f() -> E { Err(pbrt_import::Error::Io(e)) }",
    ] {
        assert_eq!(scan(bad).len(), 1, "{bad}: {:?}", scan(bad));
    }
    for good in [
        "fn f() { match e { GpuError::Budget(_) => 1, _ => 2 }; }",
        "fn f() { if let Err(GpuError::Budget(why)) = r { } }",
        "fn f() { assert!(matches!(e, Err(GpuError::Budget(_)) | Ok(_))); }",
        "fn f() { let motu_gpu::GpuError::Budget { floor, .. } = e else { return }; }",
        "fn f(e: GpuError) -> GpuError { e }",
        "impl From<HierarchyError> for X { fn from(e: HierarchyError) -> X { X::A(e) } }",
        "fn f() -> E { Err(GpuError::size_source(e)) }",
        "fn f() { let s = \"GpuError::Budget(x)\"; } // GpuError::Budget(y)",
        "fn f() -> E { match e { Err(e @ GpuError::Budget { .. }) => {} } }",
        "fn f() -> E { Err(std::io::Error::new(k, m)) }",
        "fn f() -> E { Err(Error::Parse(e)) }",
        "fn f() -> E { Err(crate::RenderError::NoFrame) }",
        "enum E { #[error(transparent)] Gpu(#[from] GpuError), Sink(SinkError) }",
        "fn f() { match (a, b) { (GpuError::Budget(_), _) => {} _ => {} } }",
    ] {
        assert!(scan(good).is_empty(), "{good}: {:?}", scan(good));
    }
    // The user's own type is its own to build.
    let own = "fn f() -> E { Err(GpuError::Budget(r)) }";
    assert!(foreign_error_constructions(&code_only(own), "motu_gpu", &owners, &crates).is_empty());
    assert_eq!(
        error_types_defined(
            "#[derive(Debug, thiserror::Error)]\npub enum AError { A }\n\
             #[derive(Debug)]\npub struct Refusal { w: u8 }\nimpl std::error::Error for Refusal {}\n\
             #[derive(Debug, Clone)]\npub struct NotAnError;\n"
        ),
        ["AError", "Refusal"]
    );
}
