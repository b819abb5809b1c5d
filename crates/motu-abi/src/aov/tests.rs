use super::*;

#[test]
fn round_trip_and_rejects_garbage() {
    let mut a = Aov::new(3, 2);
    a.records[4] = AovRecord {
        mesh: 7,
        primitive: 9,
        t: 1.5,
        lod: 2,
        _pad: 0,
        traces: 3,
    };
    let mut bytes = Vec::new();
    a.write_to(&mut bytes).unwrap();
    assert_eq!(bytes.len(), 32 + 6 * 16);
    assert_eq!(Aov::read_from(&bytes[..]).unwrap(), a);
    assert!(matches!(
        Aov::read_from(&b"PNG....."[..]),
        Err(AovError::Io(_))
    ));
    let mut bad = bytes.clone();
    bad[0] = b'X';
    assert!(matches!(Aov::read_from(&bad[..]), Err(AovError::BadMagic)));
    assert!(Aov::read_from(&bytes[..40]).is_err());
}

#[test]
fn regression_compare_trusts_aov_header() {
    // 96 bytes claiming 16384×16384: refused from the length, before any allocation.
    let dir = std::env::temp_dir().join(format!("motu-aov-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("liar.aov");
    let mut bytes = Aov::new(4, 1).to_bytes();
    bytes[12..16].copy_from_slice(&16384u32.to_le_bytes());
    bytes[16..20].copy_from_slice(&16384u32.to_le_bytes());
    assert_eq!(bytes.len(), 96);
    std::fs::write(&p, &bytes).unwrap();
    let e = Aov::load(&p).unwrap_err().to_string();
    assert!(e.contains("16384×16384") && e.contains("96 bytes"), "{e}");
    // The streaming reader refuses it too (reads what is there, never the claimed size).
    assert!(Aov::read_from(&bytes[..]).is_err());
    // 0×0 has no pixels.
    let mut zero = Aov::new(1, 1).to_bytes();
    zero[12..20].fill(0);
    std::fs::write(&p, &zero[..32]).unwrap();
    assert!(Aov::load(&p).unwrap_err().to_string().contains("no pixels"));
    // A good file round-trips through load.
    let good = Aov::new(3, 2);
    std::fs::write(&p, good.to_bytes()).unwrap();
    assert_eq!(Aov::load(&p).unwrap(), good);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// The fuzz corpus (`pbrt-import/fuzz/corpus/aov`) replayed on stable: every input is an
/// error or a consistent AOV, never a panic or a huge allocation.
#[test]
fn aov_fuzz_corpus_replays() {
    let dir =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pbrt-import/fuzz/corpus/aov");
    let mut n = 0;
    for e in std::fs::read_dir(&dir).unwrap().flatten() {
        let data = std::fs::read(e.path()).unwrap();
        if let Ok(a) = Aov::read_from(&data[..]) {
            assert_eq!(a.records.len(), a.width as usize * a.height as usize);
        }
        n += 1;
    }
    assert!(n > 0, "the aov corpus must not be empty");
}
