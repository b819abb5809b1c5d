//! Issue 49 (hardening, round 3): special files, all-or-nothing outputs, `gen` atomic, nothing
//! non-finite or silently dropped, errors that say what is wrong. One test per finding, through
//! the real `motu` binary.

use motu_tests::{motu, motu_bin, motu_env, motu_ok, s};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A one-triangle scene with a camera and a light; `world` goes after `WorldBegin`.
fn scene(dir: &Path, name: &str, camera: &str, world: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(
        &p,
        format!(
            "LookAt 0 0 5  0 0 0  0 1 0\n{camera}\nFilm \"image\" \"integer xresolution\" [16] \"integer yresolution\" [16]\nWorldBegin\nLightSource \"distant\" \"rgb L\" [1 1 1]\n{world}\nShape \"trianglemesh\" \"point P\" [-1 -1 0 1 -1 0 0 1 0] \"integer indices\" [0 1 2]\nWorldEnd\n"
        ),
    )
    .unwrap();
    p
}

const CAMERA: &str = "Camera \"perspective\" \"float fov\" [ 40 ]";

/// An imported one-triangle package.
fn package(dir: &Path) -> PathBuf {
    let sc = scene(dir, "ok.pbrt", CAMERA, "");
    let pkg = dir.join("ok.motu");
    motu_ok(&["import", s(&sc), "-o", s(&pkg)]);
    pkg
}

/// Runs motu, killing it after `secs` (a special file that blocks must fail the test, not
/// hang the suite).
fn motu_within(args: &[&str], secs: u64) -> Output {
    let mut child = Command::new(motu_bin())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t = Instant::now();
    while child.try_wait().unwrap().is_none() {
        if t.elapsed() > Duration::from_secs(secs) {
            let _ = child.kill();
            let out = child.wait_with_output().unwrap();
            panic!(
                "motu {} still running after {secs} s (blocked on a special file?): {}",
                args.join(" "),
                String::from_utf8_lossy(&out.stderr)
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

/// Asserts motu fails within a minute with one clean paragraph holding every needle.
fn fails_with(args: &[&str], needles: &[&str]) -> String {
    let o = motu_within(args, 60);
    let e = String::from_utf8_lossy(&o.stderr).into_owned();
    assert!(
        !o.status.success(),
        "motu {} succeeded: {e}",
        args.join(" ")
    );
    assert!(!e.contains("panicked"), "{e}");
    for n in needles {
        assert!(e.contains(n), "motu {}: `{n}` not in: {e}", args.join(" "));
    }
    e
}

fn mkfifo(p: &Path) -> bool {
    let ok = Command::new("mkfifo")
        .arg(p)
        .status()
        .is_ok_and(|st| st.success());
    if !ok {
        eprintln!("SKIPPED the FIFO cases: mkfifo is not available");
    }
    ok
}

fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".motu-tmp"))
        .collect()
}

// ---- 1: special files ---------------------------------------------------------------------

#[test]
fn regression_special_files_are_named_and_never_opened() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = package(d);
    let fifo = d.join("fifo");
    let have_fifo = mkfifo(&fifo);
    let (a, b) = (d.join("loop_a"), d.join("loop_b"));
    std::os::unix::fs::symlink(&a, &b).unwrap();
    std::os::unix::fs::symlink(&b, &a).unwrap();
    let sub = d.join("sub");
    std::fs::create_dir(&sub).unwrap();
    let mut specials: Vec<(&Path, &str)> = vec![
        (&sub, "a directory"),
        (Path::new("/dev/null"), "a character device"),
        (&a, "a symbolic-link loop"),
    ];
    if have_fifo {
        specials.push((&fifo, "a FIFO"));
    }
    let png = d.join("x.png");
    for (path, what) in &specials {
        // A package for info, verify and render.
        for cmd in [&["info", s(path)][..], &["verify", s(path)]] {
            let e = fails_with(cmd, &[what, "not a regular file"]);
            assert!(!e.contains("too short") && !e.contains("os error"), "{e}");
        }
        fails_with(
            &["render", s(path), "-o", s(&png), "--backend", "cpu"],
            &[what],
        );
        // An AOV for compare; a camera path for render; a scene for import.
        fails_with(&["compare", s(path), s(path)], &[what]);
        fails_with(
            &["import", s(path), "-o", s(&d.join("special.motu"))],
            // A directory is the pipeline's to judge (Moana's base package is a folder):
            // "is a directory, not a scene file"; the rest "not a regular file".
            &["scene", what, "not a "],
        );
        fails_with(
            &[
                "render",
                s(&pkg),
                "-o",
                s(&png),
                "--backend",
                "cpu",
                "--camera-path",
                s(path),
            ],
            &["--camera-path", what],
        );
    }
    // `--camera-path /dev/zero` read until out of memory.
    fails_with(
        &[
            "render",
            s(&pkg),
            "-o",
            s(&png),
            "--backend",
            "cpu",
            "--camera-path",
            "/dev/zero",
        ],
        &["--camera-path /dev/zero", "a character device"],
    );
    assert!(!png.exists());
    // An OBJ's mtllib: /dev/zero aborted the allocator, /dev/urandom was "missing", a FIFO
    // blocked.
    let mut libs = vec![
        ("/dev/zero".to_string(), "a character device"),
        ("/dev/urandom".to_string(), "a character device"),
    ];
    if have_fifo {
        libs.push((s(&fifo).to_string(), "a FIFO"));
    }
    for (lib, what) in libs {
        let obj = d.join("m.obj");
        std::fs::write(
            &obj,
            format!("mtllib {lib}\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"),
        )
        .unwrap();
        let out = d.join("m.motu");
        let e = fails_with(
            &["import", s(&obj), "-o", s(&out), "--allow-missing"],
            &["m.obj:1", what],
        );
        assert!(!e.contains("missing file"), "{e}");
        assert!(
            !out.exists() && temp_files(d).is_empty(),
            "{:?}",
            temp_files(d)
        );
    }
}

// ---- 2: all-or-nothing outputs -------------------------------------------------------------

#[test]
fn regression_render_outputs_are_all_or_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = package(d);
    let png = d.join("out.png");
    let stats = d.join("stats.json");
    std::fs::write(&png, b"old png").unwrap();
    std::fs::write(&stats, b"old stats").unwrap();
    // procfs refuses new files (even to root): the AOV cannot be written, so nothing is,
    // and the refusal comes before the render.
    let e = fails_with(
        &[
            "render",
            s(&pkg),
            "-o",
            s(&png),
            "--stats",
            s(&stats),
            "--aov",
            "/proc/motu-test.aov",
            "--backend",
            "cpu",
        ],
        &["--aov /proc/motu-test.aov", "before any work"],
    );
    assert!(!e.contains("rendered"), "{e}");
    assert_eq!(std::fs::read(&png).unwrap(), b"old png");
    assert_eq!(std::fs::read(&stats).unwrap(), b"old stats");
    assert!(temp_files(d).is_empty(), "{:?}", temp_files(d));
    // All writable: all replaced.
    let aov = d.join("out.aov");
    motu_ok(&[
        "render",
        s(&pkg),
        "-o",
        s(&png),
        "--stats",
        s(&stats),
        "--aov",
        s(&aov),
        "--backend",
        "cpu",
    ]);
    assert_ne!(std::fs::read(&png).unwrap(), b"old png");
    assert!(std::fs::read_to_string(&stats)
        .unwrap()
        .contains("\"backend\""));
    assert!(aov.exists() && temp_files(d).is_empty());
}

// ---- 3: gen atomic -------------------------------------------------------------------------

#[test]
fn regression_gen_is_atomic_and_refuses_a_non_empty_target() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("sf");
    // Bad options found by the generator leave nothing (was: an empty directory).
    fails_with(
        &["gen", "sphereflake", "--depth", "30", "-o", s(&out)],
        &["depth"],
    );
    fails_with(
        &["gen", "island", "--scale", "nan", "-o", s(&out)],
        &["scale"],
    );
    assert!(!out.exists());
    // `gen --threads 0` is refused, as import refuses it.
    fails_with(
        &["gen", "forest", "--threads", "0", "-o", s(&out)],
        &["--threads 0"],
    );
    assert!(!out.exists());
    motu_ok(&["gen", "sphereflake", "--depth", "1", "-o", s(&out)]);
    let first = std::fs::read(out.join("scene.pbrt")).unwrap();
    // A non-empty target is refused (its files were overwritten in place) …
    std::fs::write(out.join("mine.txt"), b"mine").unwrap();
    fails_with(
        &["gen", "sphereflake", "--depth", "2", "-o", s(&out)],
        &["not empty", "--force"],
    );
    assert_eq!(std::fs::read(out.join("scene.pbrt")).unwrap(), first);
    // … unless --force, which replaces it whole.
    let json = motu_ok(&[
        "gen",
        "sphereflake",
        "--depth",
        "2",
        "-o",
        s(&out),
        "--force",
        "--json",
    ]);
    assert!(
        json.contains(&format!("{}", out.join("scene.pbrt").display())),
        "{json}"
    );
    assert!(!out.join("mine.txt").exists());
    assert_ne!(std::fs::read(out.join("scene.pbrt")).unwrap(), first);
    assert!(temp_files(d).is_empty(), "{:?}", temp_files(d));
    // `-o .` in the working directory: its entries are replaced (the shell's directory is
    // never renamed away), the scene file last.
    let here = d.join("here");
    std::fs::create_dir(&here).unwrap();
    std::fs::write(here.join("old.txt"), b"old").unwrap();
    let gen_here = |force: bool| {
        let mut args = vec!["gen", "sphereflake", "--depth", "1", "-o", "."];
        if force {
            args.push("--force");
        }
        Command::new(motu_bin())
            .args(&args)
            .current_dir(&here)
            .output()
            .unwrap()
    };
    assert!(!gen_here(false).status.success());
    let o = gen_here(true);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(here.join("scene.pbrt").is_file() && !here.join("old.txt").exists());
    assert!(temp_files(d).is_empty(), "{:?}", temp_files(d));
    // The written scene imports.
    motu_ok(&[
        "import",
        s(&out.join("scene.pbrt")),
        "-o",
        s(&d.join("sf.motu")),
    ]);
}

// ---- 5: silently dropped or wrong data -----------------------------------------------------

#[test]
fn regression_dropped_or_wrong_scene_data_is_an_error_with_a_location() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("x.motu");
    let import_fails = |sc: &Path, needles: &[&str]| {
        fails_with(&["import", s(sc), "-o", s(&out)], needles);
        assert!(!out.exists());
    };
    // A PLY body with more faces than its header declares (the extra one was dropped).
    std::fs::write(
        d.join("m.ply"),
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n-1 -1 0\n1 -1 0\n0 1 0\n3 0 1 2\n3 2 1 0\n",
    )
    .unwrap();
    let sc = scene(
        d,
        "ply.pbrt",
        CAMERA,
        "Shape \"plymesh\" \"string filename\" \"m.ply\"",
    );
    import_fails(&sc, &["m.ply", "line 14", "more than the header declares"]);
    // `"float fov" [0]` rendered a flat image with exit 0.
    let sc = scene(
        d,
        "fov.pbrt",
        "Camera \"perspective\" \"float fov\" [0]",
        "",
    );
    import_fails(&sc, &["fov.pbrt:2:22", "fov"]);
    // Non-finite material values; a NaN area light, now with its location.
    let sc = scene(
        d,
        "kd.pbrt",
        CAMERA,
        "Material \"matte\" \"color Kd\" [nan 0 0]",
    );
    import_fails(&sc, &["kd.pbrt:6:18", "finite"]);
    let sc = scene(
        d,
        "refl.pbrt",
        CAMERA,
        "Material \"diffuse\" \"rgb reflectance\" [-5 1e400 0]",
    );
    import_fails(&sc, &["refl.pbrt:6:20", "finite"]);
    let sc = scene(
        d,
        "area.pbrt",
        CAMERA,
        "AreaLightSource \"diffuse\" \"rgb L\" [nan 1 1]",
    );
    import_fails(&sc, &["area.pbrt:6:27", "finite"]);
    // OBJ faces of 1 or 2 vertices (degenerate triangles before).
    let obj = d.join("short.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2\n").unwrap();
    import_fails(&obj, &["short.obj:5:1", "at least 3 vertices"]);
}

// ---- 6: misleading errors ------------------------------------------------------------------

#[test]
fn regression_misleading_errors_say_what_is_wrong() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = package(d);
    let png = d.join("x.png");
    // --vram-budget 0 named the allocator's field.
    let e = fails_with(
        &["render", s(&pkg), "-o", s(&png), "--vram-budget", "0"],
        &["--vram-budget", "0 bytes holds nothing"],
    );
    assert!(!e.contains("budget_bytes"), "{e}");
    // A MOTU_LOG that is not a filter is said, not dropped.
    let o = motu_env(&["info", s(&pkg)], &[("MOTU_LOG", "[[[")]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && e.contains("MOTU_LOG"), "{e}");
    // OBJ `v nan` / `v 1e400` with their line; usemtl of an undefined material is warned.
    let obj = d.join("nan.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1e400 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    fails_with(
        &["import", s(&obj), "-o", s(&d.join("nan.motu"))],
        &["nan.obj:2:3", "not a finite number"],
    );
    // A UTF-16 scene names its encoding (was "unknown directive" at 1:1).
    let u16 = d.join("u16.pbrt");
    let mut bytes = vec![0xFF, 0xFE];
    for u in "WorldBegin\n".encode_utf16() {
        bytes.extend_from_slice(&u.to_le_bytes());
    }
    std::fs::write(&u16, bytes).unwrap();
    let e = fails_with(
        &["import", s(&u16), "-o", s(&d.join("u16.motu"))],
        &["u16.pbrt:1:1", "UTF-16"],
    );
    assert!(!e.contains("unknown directive"), "{e}");
    // Control bytes from a scene are escaped, never sent to the terminal.
    let ctl = d.join("ctl.pbrt");
    std::fs::write(&ctl, "WorldBegin\n\x1b[31mBad\x07\n").unwrap();
    let e = fails_with(
        &["import", s(&ctl), "-o", s(&d.join("ctl.motu"))],
        &["ctl.pbrt:2:1"],
    );
    assert!(!e.contains('\x1b') && !e.contains('\x07'), "{e:?}");
    // An empty scene is said, not a silent empty package.
    let empty = d.join("empty.pbrt");
    std::fs::write(&empty, "WorldBegin\n").unwrap();
    let o = motu(&["import", s(&empty), "-o", s(&d.join("empty.motu"))]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && e.contains("holds no geometry"), "{e}");
    // A scene whose flattened single-level variant has 2^64 instances: `report` asked the
    // device for a 2^32 − 1 box BLAS and failed on a package import accepted.
    let dag = d.join("dag.pbrt");
    let mut t = String::from(
        "LookAt 0 0 5  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" [ 40 ]\nFilm \"image\" \"integer xresolution\" [8] \"integer yresolution\" [8]\nWorldBegin\nObjectBegin \"l0\"\nShape \"trianglemesh\" \"point P\" [-1 -1 0 1 -1 0 0 1 0] \"integer indices\" [0 1 2]\nObjectEnd\n",
    );
    for i in 1..=64 {
        t.push_str(&format!(
            "ObjectBegin \"l{i}\"\nObjectInstance \"l{p}\"\nAttributeBegin\nTranslate 0.0001 0 0\nObjectInstance \"l{p}\"\nAttributeEnd\nObjectEnd\n",
            p = i - 1
        ));
    }
    t.push_str("ObjectInstance \"l64\"\nWorldEnd\n");
    std::fs::write(&dag, t).unwrap();
    let dag_pkg = d.join("dag.motu");
    motu_ok(&["import", s(&dag), "-o", s(&dag_pkg)]);
    let o = motu(&["report", s(&dag_pkg), "--json"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{e}");
    assert!(!e.contains("4294967295"), "{e}");
}

#[test]
fn regression_an_instancing_cycle_is_located_at_the_instance_that_closes_it() {
    // pbrt-v4 forward references let objects instance each other; the scene builder used to
    // report it as "prototype 'world' instances itself", without a file or line.
    let d = tempfile::tempdir().unwrap();
    let scene = d.path().join("cycle.pbrt");
    std::fs::write(
        &scene,
        "LookAt 0 0 5  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" [45]\nWorldBegin\n\
         ObjectBegin \"a\"\nObjectInstance \"b\"\nShape \"sphere\"\nObjectEnd\n\
         ObjectBegin \"b\"\nObjectInstance \"a\"\nObjectEnd\nObjectInstance \"a\"\n",
    )
    .unwrap();
    let pkg = d.path().join("cycle.motu");
    let err = fails_with(
        &["import", s(&scene), "-o", s(&pkg), "--pbrt-version", "4"],
        &[
            "cycle.pbrt:9:1:",
            "instancing cycle",
            "\"a\" → \"b\" → \"a\"",
        ],
    );
    assert!(!err.contains("'world'"), "{err}");
    assert!(!pkg.exists());
}
