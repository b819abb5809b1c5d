use super::*;

fn import(text: &str, allow_missing: bool) -> Result<IngestReport, String> {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("t.obj");
    std::fs::write(&p, text).unwrap();
    ingest_obj(
        &p,
        allow_missing,
        Box::new(motu_scene::InMemoryGeometry::new()),
    )
    .map(|(_, r)| r)
    .map_err(|e| e.to_string())
}

#[test]
fn regression_obj_errors_have_line_numbers() {
    let tri = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";
    let e = import(&format!("{tri}f 1 2 3\nf 1 2 9\n"), false).unwrap_err();
    assert!(e.contains("t.obj:5:7") && e.contains("index 9"), "{e}");
    let e = import(&format!("{tri}vn 0 0 1\nf 1//1 2//1 3//4\n"), false).unwrap_err();
    assert!(e.contains("t.obj:5:") && e.contains("normals"), "{e}");
    let e = import(&format!("v 0 0\n{tri}f 1 2 3\n"), false).unwrap_err();
    assert!(e.contains("t.obj:1:"), "{e}");
    let e = import(&format!("{tri}f 1 2 -7\n"), false).unwrap_err();
    assert!(e.contains("t.obj:4:"), "{e}");
    // tobj 4 overflows on these (found by the obj fuzz target): refused before it runs.
    let e = import(&format!("{tri}vt 0 0\nf 1/-3 2/1 3/1\n"), false).unwrap_err();
    assert!(
        e.contains("t.obj:5:3") && e.contains("texture coordinates"),
        "{e}"
    );
    // Polylines too: tobj resolves `l` references as a face's (the fuzz target's crash,
    // `l 1/-3`, session 21).
    let e = import(&format!("{tri}vt 0 0\nl 1/-3\n"), false).unwrap_err();
    assert!(
        e.contains("t.obj:5:3") && e.contains("texture coordinates"),
        "{e}"
    );
    let e = import(
        &format!("{tri}vn 0 0 1\nf 1//99999999999999999 2//1 3//1\n"),
        false,
    )
    .unwrap_err();
    assert!(e.contains("t.obj:5:3") && e.contains("normals"), "{e}");
    // References to an absent kind are ignored, as tobj does.
    import(&format!("{tri}f 1/5 2/5 3/5\n"), false).unwrap();
}

#[test]
fn regression_missing_mtl_is_an_error_unless_allowed() {
    let text = "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
    let e = import(text, false).unwrap_err();
    assert!(e.contains("t.obj:1") && e.contains("gone.mtl"), "{e}");
    let r = import(text, true).unwrap();
    assert!(
        r.warnings.iter().any(|w| w.contains("gone.mtl")),
        "{:?}",
        r.warnings
    );
}

/// Writes `files` (name, bytes) beside `t.obj` and imports it.
fn import_with(text: &str, files: &[(&str, &[u8])]) -> Result<IngestReport, String> {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in files {
        std::fs::write(dir.path().join(name), bytes).unwrap();
    }
    let p = dir.path().join("t.obj");
    std::fs::write(&p, text).unwrap();
    ingest_obj(&p, false, Box::new(motu_scene::InMemoryGeometry::new()))
        .map(|(_, r)| r)
        .map_err(|e| e.to_string())
}

const TRI: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\n";

#[test]
fn regression_special_file_as_mtllib_is_named_and_never_read() {
    // `/dev/zero` was read as one endless line until the allocator aborted.
    for (dev, what) in [
        ("/dev/zero", "a character device"),
        ("/dev/urandom", "a character device"),
        ("/tmp", "a directory"),
    ] {
        let e = import(&format!("mtllib {dev}\n{TRI}f 1 2 3\n"), true).unwrap_err();
        assert!(e.contains("t.obj:1") && e.contains(what), "{dev}: {e}");
        assert!(!e.contains("missing"), "{dev}: {e}");
    }
    // Found by the fuzzer: tobj takes a keyword followed by form feeds and other bytes, and
    // the name after the line's first space; the check must see the same name.
    let e = import(
        &format!("mtllib\x0c\x0c\x1f\0\x0c /dev/zero\n{TRI}f 1 2 3\n"),
        true,
    )
    .unwrap_err();
    assert!(
        e.contains("t.obj:1") && e.contains("a character device"),
        "{e}"
    );
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("lib.mtl");
    if std::process::Command::new("mkfifo")
        .arg(&fifo)
        .status()
        .is_ok_and(|s| s.success())
    {
        let p = dir.path().join("t.obj");
        std::fs::write(&p, format!("mtllib lib.mtl\n{TRI}f 1 2 3\n")).unwrap();
        let e = ingest_obj(&p, false, Box::new(motu_scene::InMemoryGeometry::new()))
            .map(|_| ())
            .unwrap_err()
            .to_string();
        assert!(e.contains("a FIFO"), "{e}");
    }
}

#[test]
fn regression_obj_non_finite_vertices_and_short_faces_have_lines() {
    let e = import(&format!("{TRI}v nan 0 0\nf 1 2 3\n"), false).unwrap_err();
    assert!(
        e.contains("t.obj:4:3") && e.contains("not a finite number"),
        "{e}"
    );
    let e = import(&format!("{TRI}v 1e400 0 0\nf 1 2 3\n"), false).unwrap_err();
    assert!(e.contains("t.obj:4:3") && e.contains("1e400"), "{e}");
    for face in ["f 1", "f 1 2"] {
        let e = import(&format!("{TRI}{face}\n"), false).unwrap_err();
        assert!(
            e.contains("t.obj:4:1") && e.contains("at least 3 vertices"),
            "{e}"
        );
    }
}

#[test]
fn regression_short_mtl_colour_is_an_error_not_a_tobj_panic() {
    // Found by the obj fuzz target: tobj 4 unwraps a colour of fewer than three numbers.
    for kd in ["Kd", "Kd 1", "Kd 0.5 0.5"] {
        let d = tempfile::tempdir().unwrap();
        std::fs::write(d.path().join("m.mtl"), format!("newmtl red\n{kd}\n")).unwrap();
        let obj = d.path().join("a.obj");
        std::fs::write(
            &obj,
            "mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl red\nf 1 2 3\n",
        )
        .unwrap();
        let (line, why) = scan_mtl(&d.path().join("m.mtl")).expect("refused");
        assert_eq!(line, 2, "{why}");
        assert!(why.contains("three numbers"), "{why}");
    }
}

#[test]
fn regression_bad_mtl_and_undefined_usemtl_are_named() {
    let obj = format!("mtllib m.mtl\n{TRI}usemtl red\nf 1 2 3\nusemtl blue\nf 1 2 3\n");
    let e = import_with(
        &obj,
        &[("m.mtl", b"newmtl red\nKd 1 0 0\n\xff\xfe\x00\x01\n")],
    )
    .unwrap_err();
    assert!(e.contains("m.mtl:3") && e.contains("binary data"), "{e}");
    let e = import_with(&obj, &[("m.mtl", b"newmtl red\nKd nan 0 0\n")]).unwrap_err();
    assert!(
        e.contains("m.mtl:2") && e.contains("not a finite number"),
        "{e}"
    );
    let r = import_with(&obj, &[("m.mtl", b"newmtl red\nKd 1 0 0\n")]).unwrap();
    assert!(
        r.warnings
            .iter()
            .any(|w| w.contains("t.obj:7") && w.contains("\"blue\"") && w.contains("1 such")),
        "{:?}",
        r.warnings
    );
}

/// The fuzz corpus (`pbrt-import/fuzz/corpus/obj`) replayed on stable: errors, never panics.
#[test]
fn obj_fuzz_corpus_replays() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pbrt-import/fuzz/corpus/obj");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap().flatten() {
        let data = std::fs::read(e.path()).unwrap();
        // As the fuzz target: after `#--mtl--`, the bytes are `input.mtl` beside the OBJ.
        const MARK: &[u8] = b"#--mtl--\n";
        let (obj, mtl) = match data.windows(MARK.len()).position(|w| w == MARK) {
            Some(i) => (&data[..i], &data[i + MARK.len()..]),
            None => (&data[..], &[][..]),
        };
        let text = String::from_utf8_lossy(obj).into_owned();
        let _ = import_with(&text, &[("input.mtl", mtl)]);
        let _ = import(&text, true);
        let _ = import(&text, false);
        n += 1;
    }
    assert!(n > 0, "the obj corpus must not be empty");
}
