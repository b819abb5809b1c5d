use super::*;

#[test]
fn std430_layout_matches_rust_layout() {
    for def in structs() {
        let (offsets, size) = std430_layout(&def);
        for ((_, name, rust), glsl) in def.fields.iter().zip(&offsets) {
            assert_eq!(
                rust, glsl,
                "{}.{name}: Rust offset {rust}, std430 {glsl}",
                def.name
            );
        }
        assert_eq!(
            size, def.size,
            "{}: Rust size {} vs std430 {size}",
            def.name, def.size
        );
        assert_eq!(
            def.size % 16,
            0,
            "{} should be a 16-byte multiple",
            def.name
        );
    }
}

#[test]
fn committed_glsl_is_up_to_date() {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shaders/generated/abi.glsl");
    let want = abi_glsl();
    if std::env::var_os("MOTU_UPDATE_GLSL").is_some() {
        std::fs::create_dir_all(path.parent().unwrap()).unwrap();
        std::fs::write(&path, &want).unwrap();
    }
    let have = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        have == want,
        "{} is stale: run MOTU_UPDATE_GLSL=1 cargo test -p motu-abi",
        path.display()
    );
}
