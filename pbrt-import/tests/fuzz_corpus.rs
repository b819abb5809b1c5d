//! Replays every file of the fuzz corpora (`fuzz/corpus/{parse,ply}`) through the
//! parser and the PLY reader on stable Rust: whatever the fuzzers once found must
//! stay an `Err` or an `Ok`, never a panic, hang or runaway allocation.

use std::path::{Path, PathBuf};

use pbrt_import::lexer::Lexer;
use pbrt_import::{parse_bytes, CollectSink, FileId, ParseOptions, VersionOption};

fn corpus(target: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpus")
        .join(target);
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("corpus {} unreadable: {e}", dir.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file())
        .collect();
    files.sort();
    files
}

/// A corpus file's bytes; `None` when it vanished since the listing (a fuzzer running on
/// the same corpus replaces files as it minimises them).
fn read(path: &Path) -> Option<Vec<u8>> {
    match std::fs::read(path) {
        Ok(data) => Some(data),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => panic!("{}: {e}", path.display()),
    }
}

#[test]
fn parse_corpus_replays_without_panics() {
    let files = corpus("parse");
    assert!(!files.is_empty(), "the parse corpus must not be empty");
    for path in &files {
        let Some(data) = read(path) else { continue };
        let _ = Lexer::new(&data, FileId(0)).count_tokens();
        for version in [VersionOption::V3, VersionOption::V4] {
            let opts = ParseOptions {
                version,
                ..Default::default()
            };
            // A nonexistent base directory keeps replays away from real files, like the fuzzer.
            let _ = parse_bytes(
                &data,
                Path::new("/nonexistent"),
                &opts,
                &mut CollectSink::default(),
            );
        }
    }
}

#[test]
fn ply_corpus_replays_without_panics() {
    let files = corpus("ply");
    assert!(!files.is_empty(), "the ply corpus must not be empty");
    let mut meshes = 0;
    for path in &files {
        let Some(data) = read(path) else { continue };
        if let Ok(mesh) = pbrt_import::ply::parse_ply(&data) {
            // Whatever the reader accepts must be internally consistent.
            let n = mesh.positions.len();
            assert!(
                mesh.indices.iter().all(|&i| (i as usize) < n),
                "{}",
                path.display()
            );
            assert_eq!(mesh.indices.len() % 3, 0, "{}", path.display());
            meshes += 1;
        }
    }
    assert!(meshes > 0, "the seed PLY files must still parse");
}

/// Issue 49's PLY seeds: a body holding more faces than declared is an error (it was dropped),
/// ASCII or binary; a binary body ending in a newline is still read.
#[test]
fn ply_corpus_more_faces_than_declared_are_errors() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus/ply");
    for (name, ok) in [
        ("regression-ascii-more-faces-than-declared", false),
        ("regression-binary-more-faces-than-declared", false),
        ("regression-binary-trailing-newline", true),
    ] {
        let data = std::fs::read(dir.join(name)).unwrap();
        let r = pbrt_import::ply::parse_ply(&data);
        assert_eq!(
            r.is_ok(),
            ok,
            "{name}: {:?}",
            r.err().map(|e| e.to_string())
        );
    }
}
