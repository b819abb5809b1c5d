//! Issue 18: what a bad-input and fault campaign broke, one regression test per finding, all
//! through the real `motu` binary.

use motu_tests::{gpu_available, motu, motu_bin, motu_ok, s};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A one-triangle scene with a camera and a light (`extra` goes before `WorldBegin`).
fn scene(dir: &Path, name: &str, camera: &str, world: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(
        &p,
        format!(
            "LookAt 0 0 5  0 0 0  0 1 0\n{camera}\nFilm \"image\" \"integer xresolution\" [16] \"integer yresolution\" [16]\nWorldBegin\n{world}\nShape \"trianglemesh\" \"point P\" [-1 -1 0 1 -1 0 0 1 0] \"integer indices\" [0 1 2]\nWorldEnd\n"
        ),
    )
    .unwrap();
    p
}

fn ok_scene(dir: &Path) -> PathBuf {
    scene(
        dir,
        "ok.pbrt",
        "Camera \"perspective\" \"float fov\" [ 40 ]",
        "LightSource \"distant\" \"rgb L\" [1 1 1]",
    )
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Asserts failure with a clean one-paragraph error containing every `needle`.
fn fails_with(args: &[&str], needles: &[&str]) -> String {
    let o = motu(args);
    let e = stderr(&o);
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

fn temp_files(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".motu-tmp"))
        .collect()
}

// ---- 1 ------------------------------------------------------------------------------------

#[test]
fn regression_nonfinite_camera_and_light_rejected_at_import() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.motu");
    for (name, camera, world, at) in [
        (
            "nan_fov.pbrt",
            "Camera \"perspective\" \"float fov\" [ nan ]",
            "",
            "nan_fov.pbrt:2:22",
        ),
        (
            "inf_fov.pbrt",
            "Camera \"perspective\" \"float fov\" [ inf ]",
            "",
            "inf_fov.pbrt:2:22",
        ),
        (
            "nan_light.pbrt",
            "Camera \"perspective\" \"float fov\" [ 40 ]",
            "LightSource \"distant\" \"rgb L\" [nan nan nan]",
            "nan_light.pbrt:5:23",
        ),
        (
            "nan_lookat.pbrt",
            "Translate nan 0 0\nCamera \"perspective\"",
            "",
            "nan_lookat.pbrt:2:1",
        ),
    ] {
        let p = scene(dir.path(), name, camera, world);
        fails_with(&["import", s(&p), "-o", s(&out)], &[at, "finite"]);
        assert!(!out.exists(), "{name}: a package was written");
    }
    // The finite scene still imports, and every reader opens it.
    let p = ok_scene(dir.path());
    motu_ok(&["import", s(&p), "-o", s(&out)]);
    motu_ok(&["verify", s(&out)]);
    motu_ok(&["info", s(&out)]);
}

// ---- 2 ------------------------------------------------------------------------------------

#[test]
fn regression_outputs_never_overwrite_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = ok_scene(d);
    let scene_text = std::fs::read(&sc).unwrap();
    fails_with(
        &["import", s(&sc), "-o", s(&sc)],
        &["-o", "never replaces an input"],
    );
    assert_eq!(std::fs::read(&sc).unwrap(), scene_text);

    // A PLY the scene uses, named as the output.
    let ply = d.join("mesh.ply");
    std::fs::write(
        &ply,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n-1 -1 0\n1 -1 0\n0 1 0\n3 0 1 2\n",
    )
    .unwrap();
    let ply_text = std::fs::read(&ply).unwrap();
    let with_ply = scene(
        d,
        "ply.pbrt",
        "Camera \"perspective\" \"float fov\" [ 40 ]",
        "Shape \"plymesh\" \"string filename\" \"mesh.ply\"",
    );
    fails_with(
        &["import", s(&with_ply), "-o", s(&ply)],
        &["mesh.ply", "never replaces an input"],
    );
    assert_eq!(std::fs::read(&ply).unwrap(), ply_text);

    let pkg = d.join("p.motu");
    motu_ok(&["import", s(&sc), "-o", s(&pkg)]);
    let pkg_bytes = std::fs::read(&pkg).unwrap();
    let img = d.join("img.png");
    for extra in [["-o", s(&pkg)], ["--aov", s(&pkg)], ["--stats", s(&pkg)]] {
        let mut args = vec!["render", s(&pkg), "--backend", "cpu"];
        if extra[0] != "-o" {
            args.extend(["-o", s(&img)]);
        }
        args.extend(extra);
        fails_with(&args, &["never replaces an input"]);
        assert_eq!(std::fs::read(&pkg).unwrap(), pkg_bytes);
    }
    let x = d.join("x");
    fails_with(
        &[
            "render",
            s(&pkg),
            "--backend",
            "cpu",
            "-o",
            s(&x),
            "--aov",
            s(&x),
            "--stats",
            s(&x),
        ],
        &["same file"],
    );
    assert!(!x.exists());
    // Non-regular existing outputs: a symlink and a device node stay what they are.
    let target = d.join("target.png");
    std::fs::write(&target, b"keep").unwrap();
    let link = d.join("link.png");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    fails_with(
        &["render", s(&pkg), "--backend", "cpu", "-o", s(&link)],
        &["symbolic link"],
    );
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert_eq!(std::fs::read(&target).unwrap(), b"keep");
    fails_with(
        &["render", s(&pkg), "--backend", "cpu", "-o", "/dev/null"],
        &["character device"],
    );
    fails_with(
        &["import", s(&sc), "-o", "/dev/null"],
        &["character device"],
    );
    let aov = d.join("a.aov");
    motu_ok(&[
        "render",
        s(&pkg),
        "--backend",
        "cpu",
        "-o",
        s(&d.join("a.png")),
        "--aov",
        s(&aov),
    ]);
    fails_with(
        &["compare", s(&aov), s(&aov), "--diff", s(&aov)],
        &["--diff", "never replaces an input"],
    );
    fails_with(
        &["report", s(&pkg), "--html", s(&pkg)],
        &["--html", "never replaces an input"],
    );
}

// ---- 3 ------------------------------------------------------------------------------------

#[test]
fn regression_stack_size_is_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("p.motu");
    motu_ok(&["import", s(&ok_scene(dir.path())), "-o", s(&pkg)]);
    let png = dir.path().join("o.png");
    for bad in ["0", "65536", "268435456", "4294967295"] {
        let t = std::time::Instant::now();
        fails_with(
            &["render", s(&pkg), "-o", s(&png), "--stack-size", bad],
            &["--stack-size", bad, "1..=256"],
        );
        assert!(
            t.elapsed().as_secs() < 30,
            "--stack-size {bad} was not refused up front"
        );
    }
    assert!(!png.exists());
    motu_ok(&[
        "render",
        s(&pkg),
        "-o",
        s(&png),
        "--backend",
        "cpu",
        "--stack-size",
        "256",
    ]);
}

// ---- 4 ------------------------------------------------------------------------------------

#[test]
fn regression_outputs_are_atomic_and_their_directory_checked_first() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = d.join("p.motu");
    motu_ok(&["import", s(&ok_scene(d)), "-o", s(&pkg)]);
    // A missing output directory is refused before any rendering (no "rendered" line).
    let ok_png = d.join("ok.png");
    for opt in ["-o", "--aov", "--stats"] {
        let mut args = vec!["render", s(&pkg), "--backend", "cpu"];
        let missing = d.join("no/such/dir/f");
        if opt != "-o" {
            args.extend(["-o", s(&ok_png)]);
        }
        args.extend([opt, s(&missing)]);
        let e = fails_with(&args, &[opt, "does not exist"]);
        assert!(!e.contains("rendered"), "{e}");
    }
    fails_with(
        &["report", s(&pkg), "--html", s(&d.join("no/such/r.html"))],
        &["--html", "does not exist"],
    );
    // Written outputs are complete and no temp file is left beside them.
    let (png, aov, stats, html) = (
        d.join("a.png"),
        d.join("a.aov"),
        d.join("a.json"),
        d.join("r.html"),
    );
    motu_ok(&[
        "render",
        s(&pkg),
        "--backend",
        "cpu",
        "-o",
        s(&png),
        "--aov",
        s(&aov),
        "--stats",
        s(&stats),
    ]);
    motu_ok(&["report", s(&pkg), "--html", s(&html)]);
    assert!(std::fs::read(&png).unwrap().starts_with(b"\x89PNG"));
    assert!(std::fs::read_to_string(&html).unwrap().contains("</html>"));
    serde_json::from_slice::<serde_json::Value>(&std::fs::read(&stats).unwrap()).unwrap();
    assert!(temp_files(d).is_empty(), "{:?}", temp_files(d));
    // A failing compare --diff (0×0 AOVs) writes nothing.
    let zero = d.join("zero.aov");
    let mut bytes = std::fs::read(&aov).unwrap()[..32].to_vec();
    bytes[12..20].fill(0);
    std::fs::write(&zero, &bytes).unwrap();
    let diff = d.join("diff.png");
    fails_with(
        &["compare", s(&zero), s(&zero), "--diff", s(&diff)],
        &["no pixels"],
    );
    assert!(!diff.exists());
    assert!(temp_files(d).is_empty());
}

// ---- 5 ------------------------------------------------------------------------------------

/// A scene whose debug-build import takes a while (about a second): one big trianglemesh.
fn slow_scene(dir: &Path) -> PathBuf {
    let n = 400usize;
    let mut text = String::from(
        "LookAt 0 0 5  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" [ 40 ]\nWorldBegin\n",
    );
    for k in 0..8 {
        text.push_str("Shape \"trianglemesh\" \"point P\" [");
        for j in 0..n {
            for i in 0..n {
                text.push_str(&format!("{i} {j} {k} "));
            }
        }
        text.push_str("] \"integer indices\" [");
        for j in 0..n - 1 {
            for i in 0..n - 1 {
                let a = j * n + i;
                text.push_str(&format!(
                    "{a} {} {} {} {} {} ",
                    a + 1,
                    a + n,
                    a + 1,
                    a + n + 1,
                    a + n
                ));
            }
        }
        text.push_str("]\n");
    }
    text.push_str("WorldEnd\n");
    let p = dir.join("slow.pbrt");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn regression_interrupted_import_removes_its_temp_file() {
    let dir = tempfile::tempdir().unwrap();
    let sc = slow_scene(dir.path());
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    for signal in ["INT", "TERM", "HUP"] {
        let pkg = out_dir.join("p.motu");
        let mut child = Command::new(motu_bin())
            .args(["import", s(&sc), "-o", s(&pkg), "--zstd", "19"])
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let t = std::time::Instant::now();
        while temp_files(&out_dir).is_empty() {
            assert!(
                child.try_wait().unwrap().is_none(),
                "the import ended before its temp file was seen"
            );
            assert!(t.elapsed().as_secs() < 60);
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        let kill = Command::new("kill")
            .args([&format!("-{signal}"), &child.id().to_string()])
            .status()
            .unwrap();
        assert!(kill.success());
        let out = child.wait_with_output().unwrap();
        let e = stderr(&out);
        assert!(!out.status.success(), "SIG{signal}: {e}");
        assert!(e.contains(&format!("interrupted by SIG{signal}")), "{e}");
        assert!(
            temp_files(&out_dir).is_empty(),
            "SIG{signal}: {:?}",
            temp_files(&out_dir)
        );
        assert!(!pkg.exists());
    }
}

#[test]
fn regression_stale_temp_files_removed_by_a_later_import() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = ok_scene(d);
    // Left by a killed import (pid above Linux's pid_max, so never alive), and one of a live
    // process (this test) that must be kept.
    let stale = d.join(".p.motu.4194305.Ab12Cd.motu-tmp");
    let live = d.join(format!(".p.motu.{}.Ab12Cd.motu-tmp", std::process::id()));
    std::fs::write(&stale, vec![0u8; 4096]).unwrap();
    std::fs::write(&live, b"x").unwrap();
    motu_ok(&["import", s(&sc), "-o", s(&d.join("p.motu"))]);
    assert!(!stale.exists(), "the stale temp file is still there");
    assert!(live.exists(), "a live process's temp file was removed");
}

// ---- 6 ------------------------------------------------------------------------------------

#[test]
fn regression_sigbus_on_truncated_scene_is_an_error_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let sc = slow_scene(dir.path());
    let out_dir = dir.path().join("out");
    std::fs::create_dir(&out_dir).unwrap();
    let mut child = Command::new(motu_bin())
        .args(["import", s(&sc), "-o", s(&out_dir.join("p.motu"))])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id().to_string();
    // Once the scene is mapped, stop the process, truncate the file under it, let it go on.
    let maps = format!("/proc/{pid}/maps");
    let t = std::time::Instant::now();
    while !std::fs::read_to_string(&maps).is_ok_and(|m| m.contains(s(&sc))) {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the import ended first"
        );
        assert!(t.elapsed().as_secs() < 60);
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    assert!(Command::new("kill")
        .args(["-STOP", &pid])
        .status()
        .unwrap()
        .success());
    std::fs::OpenOptions::new()
        .write(true)
        .open(&sc)
        .unwrap()
        .set_len(0)
        .unwrap();
    assert!(Command::new("kill")
        .args(["-CONT", &pid])
        .status()
        .unwrap()
        .success());
    let out = child.wait_with_output().unwrap();
    let e = stderr(&out);
    assert_eq!(out.status.code(), Some(1), "{e}");
    assert!(e.contains(&format!("bus error reading {}", s(&sc))), "{e}");
    assert!(
        temp_files(&out_dir).is_empty(),
        "{:?}",
        temp_files(&out_dir)
    );
}

// ---- 7 ------------------------------------------------------------------------------------

/// `levels` objects, each instancing the one below twice: 2^levels leaf instances.
fn exponential_dag(dir: &Path, levels: u32) -> PathBuf {
    let mut t = String::from(
        "LookAt 0 0 5  0 0 0  0 1 0\nCamera \"perspective\" \"float fov\" [ 40 ]\nFilm \"image\" \"integer xresolution\" [8] \"integer yresolution\" [8]\nWorldBegin\nObjectBegin \"l0\"\nShape \"trianglemesh\" \"point P\" [-1 -1 0 1 -1 0 0 1 0] \"integer indices\" [0 1 2]\nObjectEnd\n",
    );
    for i in 1..=levels {
        t.push_str(&format!(
            "ObjectBegin \"l{i}\"\nObjectInstance \"l{p}\"\nAttributeBegin\nTranslate 0.0001 0 0\nObjectInstance \"l{p}\"\nAttributeEnd\nObjectEnd\n",
            p = i - 1
        ));
    }
    t.push_str(&format!("ObjectInstance \"l{levels}\"\nWorldEnd\n"));
    let p = dir.join("dag.pbrt");
    std::fs::write(&p, t).unwrap();
    p
}

#[test]
fn regression_exponential_instancing_warns_and_frames_end() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let pkg = d.join("dag.motu");
    let o = motu(&[
        "import",
        s(&exponential_dag(d, 69)),
        "-o",
        s(&pkg),
        "--json",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("overflow 2^64"), "{}", stderr(&o));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(summary["warnings"].as_u64().unwrap() >= 1);
    let mut backends = vec!["cpu"];
    if gpu_available() {
        backends.push("pipeline");
        if motu_tests::has_ray_query() {
            backends.push("query");
        }
    }
    for backend in backends {
        let png = d.join(format!("{backend}.png"));
        let stats = d.join(format!("{backend}.json"));
        // The default is an error (a truncated traversal is a wrong image), and it ends.
        let t = std::time::Instant::now();
        fails_with(
            &[
                "render",
                s(&pkg),
                "-o",
                s(&png),
                "--backend",
                backend,
                "--stats",
                s(&stats),
            ],
            &["cut short", "--allow-truncated"],
        );
        assert!(!png.exists());
        assert!(
            t.elapsed().as_secs() < 300,
            "{backend}: the frame took too long"
        );
        // Allowed: written, with the count in the stats.
        let o = motu(&[
            "render",
            s(&pkg),
            "-o",
            s(&png),
            "--backend",
            backend,
            "--stats",
            s(&stats),
            "--allow-truncated",
        ]);
        assert!(o.status.success(), "{backend}: {}", stderr(&o));
        assert!(stderr(&o).contains("warning:"), "{}", stderr(&o));
        let st: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        assert!(
            st["truncated_rays"].as_u64().unwrap() > 0,
            "{backend}: {st}"
        );
    }
    if gpu_available() {
        // Streaming passes count cut rays too (one stats layout for every renderer).
        let png = d.join("stream.png");
        let stats = d.join("stream.json");
        let args = [
            "render",
            s(&pkg),
            "-o",
            s(&png),
            "--backend",
            "pipeline",
            "--stream",
            "--stream-always",
            "--stats",
            s(&stats),
        ];
        fails_with(&args, &["cut short", "--allow-truncated"]);
        assert!(!png.exists());
        let mut allowed = args.to_vec();
        allowed.push("--allow-truncated");
        let o = motu(&allowed);
        assert!(o.status.success(), "stream: {}", stderr(&o));
        let st: serde_json::Value =
            serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
        assert!(st["truncated_rays"].as_u64().unwrap() > 0, "stream: {st}");
    }
}

// ---- 8 ------------------------------------------------------------------------------------

#[test]
fn regression_compare_checks_aov_header_against_file_length() {
    let dir = tempfile::tempdir().unwrap();
    let liar = dir.path().join("liar.aov");
    let mut bytes = b"MOTUAOV\0".to_vec();
    for v in [1u32, 16384, 16384, 16, 0, 0] {
        bytes.extend_from_slice(&v.to_le_bytes());
    }
    bytes.resize(96, 0);
    std::fs::write(&liar, &bytes).unwrap();
    fails_with(
        &["compare", s(&liar), s(&liar)],
        &["liar.aov", "16384×16384", "96 bytes"],
    );
}

// ---- 9 ------------------------------------------------------------------------------------

fn ply_scene(dir: &Path, ply: &str) -> PathBuf {
    std::fs::write(dir.join("m.ply"), ply).unwrap();
    scene(
        dir,
        "ply.pbrt",
        "Camera \"perspective\" \"float fov\" [ 40 ]",
        "Shape \"plymesh\" \"string filename\" \"m.ply\"",
    )
}

const PLY_HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n";

#[test]
fn regression_ply_data_is_never_dropped_silently() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("o.motu");
    // One missing value: an error naming the PLY and the line, not values shifted across lines.
    let sc = ply_scene(
        d,
        &format!("{PLY_HEAD}element face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n"),
    );
    fails_with(
        &["import", s(&sc), "-o", s(&out)],
        &["m.ply", "line 11", "missing"],
    );
    // tristrips become triangles.
    let sc = ply_scene(
        d,
        &format!("{PLY_HEAD}element tristrips 1\nproperty list int int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n4 0 1 2 3\n"),
    );
    let v = motu_tests::motu_json(&["import", s(&sc), "-o", s(&out), "--json"]);
    let info = motu_tests::motu_json(&["info", s(&out), "--json"]);
    // The strip's 2 triangles plus the scene's own one.
    assert_eq!(info["unique_triangles"], 3, "{v} {info}");
    // Faces of 0 and 2 vertices: counted in a warning that names the file.
    let sc = ply_scene(
        d,
        &format!("{PLY_HEAD}element face 3\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3 0 1 2\n0\n2 0 1\n"),
    );
    let o = motu(&["import", s(&sc), "-o", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(
        e.contains("m.ply") && e.contains("2 face(s) with fewer than 3 vertices"),
        "{e}"
    );
    let info = motu_tests::motu_json(&["info", s(&out), "--json"]);
    assert_eq!(info["unique_triangles"], 2, "{info}");
    assert!(info["warnings"].as_u64().unwrap() >= 1);
}

// ---- 10 -----------------------------------------------------------------------------------

#[test]
fn regression_threads_are_capped_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o.motu");
    let o = motu(&[
        "import",
        s(&ok_scene(dir.path())),
        "-o",
        s(&out),
        "--threads",
        "100000",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("--threads 100000 capped at"),
        "{}",
        stderr(&o)
    );
    fails_with(
        &[
            "import",
            s(&ok_scene(dir.path())),
            "-o",
            s(&out),
            "--threads",
            "0",
        ],
        &["--threads 0"],
    );
}

// ---- 11 -----------------------------------------------------------------------------------

#[test]
fn regression_obj_errors_have_line_numbers_and_missing_mtl_fails() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("o.motu");
    let obj = d.join("bad.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\nf 1 2 9\n").unwrap();
    fails_with(
        &["import", s(&obj), "-o", s(&out)],
        &["bad.obj:5:7", "out of bounds", "9"],
    );
    let obj = d.join("mtl.obj");
    std::fs::write(
        &obj,
        "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    fails_with(
        &["import", s(&obj), "-o", s(&out)],
        &["mtl.obj:1", "gone.mtl", "--allow-missing"],
    );
    let o = motu(&["import", s(&obj), "-o", s(&out), "--allow-missing"]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn regression_inputs_that_are_not_files_are_named_as_what_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("o.motu");
    let e = fails_with(&["import", s(d), "-o", s(&out)], &["is a directory"]);
    assert!(!e.contains("os error 19"), "{e}");
    let fifo = d.join("fifo.pbrt");
    assert!(Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .unwrap()
        .success());
    let (a, b) = (d.join("loop_a.pbrt"), d.join("loop_b.pbrt"));
    std::os::unix::fs::symlink(&a, &b).unwrap();
    std::os::unix::fs::symlink(&b, &a).unwrap();
    std::fs::create_dir(d.join("subdir")).unwrap();
    for (target, what) in [
        ("subdir", "a directory"),
        ("fifo.pbrt", "a FIFO"),
        ("/dev/zero", "a character device"),
        ("loop_a.pbrt", "symbolic-link loop"),
    ] {
        for directive in ["Include", "plymesh"] {
            let world = if directive == "Include" {
                format!("Include \"{target}\"")
            } else {
                format!("Shape \"plymesh\" \"string filename\" \"{target}\"")
            };
            let sc = scene(d, "inc.pbrt", "Camera \"perspective\"", &world);
            let e = fails_with(&["import", s(&sc), "-o", s(&out)], &[what, "inc.pbrt:5:"]);
            assert!(!e.contains("missing"), "{e}");
        }
    }
}

#[test]
fn regression_bad_device_index_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let pkg = dir.path().join("p.motu");
    motu_ok(&["import", s(&ok_scene(dir.path())), "-o", s(&pkg)]);
    let png = dir.path().join("o.png");
    fails_with(
        &["render", s(&pkg), "-o", s(&png), "--device", "99"],
        &["99"],
    );
    let o = Command::new(motu_bin())
        .args(["render", s(&pkg), "-o", s(&png)])
        .env("MOTU_DEVICE", "99")
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("MOTU_DEVICE=99") || stderr(&o).contains("99"),
        "{}",
        stderr(&o)
    );
    assert!(!png.exists(), "rendered on a fallback device");
}

#[test]
fn regression_option_values_are_checked_and_named() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let sc = ok_scene(d);
    let pkg = d.join("p.motu");
    motu_ok(&["import", s(&sc), "-o", s(&pkg)]);
    let aov = d.join("a.aov");
    motu_ok(&[
        "render",
        s(&pkg),
        "--backend",
        "cpu",
        "-o",
        s(&d.join("a.png")),
        "--aov",
        s(&aov),
    ]);
    for eps in ["nan", "-1", "inf"] {
        fails_with(
            &["compare", s(&aov), s(&aov), "--depth-epsilon", eps],
            &["--depth-epsilon", eps],
        );
    }
    let e = fails_with(
        &[
            "render",
            s(&pkg),
            "--backend",
            "cpu",
            "-o",
            s(&d.join("b.png")),
            "--subset",
            "",
        ],
        &["--subset", "main"],
    );
    assert!(!e.contains("unknown element(s) :"), "{e}");
    fails_with(
        &["import", s(&sc), "-o", s(&d.join("q.motu")), "--subset", ""],
        &["--subset"],
    );
    fails_with(
        &[
            "import",
            s(&sc),
            "-o",
            s(&d.join("q.motu")),
            "--max-tlas-scratch",
            "1",
        ],
        &["--max-tlas-scratch", "256 B"],
    );
    fails_with(
        &[
            "import",
            s(&sc),
            "-o",
            s(&d.join("q.motu")),
            "--pbrt-version",
            "2",
        ],
        &["--pbrt-version", "3..=4"],
    );
    if gpu_available() {
        fails_with(
            &[
                "render",
                s(&pkg),
                "-o",
                s(&d.join("c.png")),
                "--backend",
                "pipeline",
                "--vram-budget",
                "1000TiB",
            ],
            &["--vram-budget", "1000.0 TiB", "at most"],
        );
    }
}

#[test]
fn regression_rotate_nan_or_zero_axis_and_include_cycles() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("o.motu");
    let sc = scene(d, "rot.pbrt", "Camera \"perspective\"", "Rotate 30 nan 0 1");
    fails_with(
        &["import", s(&sc), "-o", s(&out)],
        &["rot.pbrt:5:1", "finite"],
    );
    let sc = scene(d, "rot0.pbrt", "Camera \"perspective\"", "Rotate 30 0 0 0");
    let o = motu(&["import", s(&sc), "-o", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("rot0.pbrt:5:1") && stderr(&o).contains("zero axis"),
        "{}",
        stderr(&o)
    );
    // The entry file including itself is a cycle at its first repeat.
    let cyc = d.join("cycle.pbrt");
    std::fs::write(&cyc, "WorldBegin\nInclude \"cycle.pbrt\"\nWorldEnd\n").unwrap();
    fails_with(
        &["import", s(&cyc), "-o", s(&out)],
        &["cycle.pbrt:2:9", "recursive"],
    );
}

#[test]
fn regression_errors_do_not_repeat_and_logs_have_no_colour() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    // A cause printed by its own error and again by the chain was shown twice.
    let e = fails_with(&["info", s(&d.join("none.motu"))], &["none.motu"]);
    let body = e.trim_start_matches("error: ");
    for part in body.split(": ") {
        if part.len() > 12 {
            assert_eq!(body.matches(part).count(), 1, "`{part}` repeats in: {e}");
        }
    }
    // Warnings (tracing) when stderr is a pipe: no escape codes.
    let sc = scene(d, "rot0.pbrt", "Camera \"perspective\"", "Rotate 30 0 0 0");
    let o = motu(&["import", s(&sc), "-o", s(&d.join("o.motu"))]);
    assert!(stderr(&o).contains("zero axis"));
    assert!(!stderr(&o).contains('\u{1b}'), "{:?}", stderr(&o));
}
