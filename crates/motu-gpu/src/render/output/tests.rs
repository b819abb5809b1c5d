use super::*;

/// The stats-word indices are written twice (Rust here, `#define STAT_*` in common.glsl):
/// this keeps them equal, and every GLSL index inside the buffer.
#[test]
fn stat_words_match_common_glsl() {
    let glsl = include_str!("../../../../../shaders/common.glsl");
    let defines: Vec<(&str, usize)> = glsl
        .lines()
        .filter_map(|l| {
            let mut it = l.strip_prefix("#define STAT_")?.split_whitespace();
            Some((it.next()?, it.next()?.parse().ok()?))
        })
        .collect();
    let index = |name: &str| {
        defines
            .iter()
            .find(|(n, _)| *n == name)
            .unwrap_or_else(|| panic!("common.glsl has no STAT_{name}"))
            .1
    };
    assert_eq!(index("TRUNCATED_RAYS"), STAT_TRUNCATED_RAYS);
    assert_eq!(index("MISSING_TEXTURES"), STAT_MISSING_TEXTURES);
    assert_eq!(index("SHADOW_RAYS"), STAT_SHADOW_RAYS);
    assert_eq!(index("TLAS_WALKS"), STAT_TLAS_WALKS);
    assert_eq!(index("MARK_WALKS"), STAT_MARK_WALKS);
    assert_eq!(index("MARK_TLAS_WALKS"), STAT_MARK_TLAS_WALKS);
    assert_eq!(index("PROXY_MEMBER_TESTS"), STAT_PROXY_MEMBER_TESTS);
    assert_eq!(index("PROXY_EXACT_TESTS"), STAT_PROXY_EXACT_TESTS);
    assert_eq!(defines.len(), STAT_WORDS, "{defines:?}");
    assert!(defines.iter().all(|&(_, i)| i < STAT_WORDS), "{defines:?}");
}

#[test]
fn a_missing_texture_read_fails_the_frame() {
    let mut counters = vec![0u32; STAT_WORDS];
    assert!(check_texture_residency(&counters).is_ok());
    counters[STAT_MISSING_TEXTURES] = 3;
    let e = check_texture_residency(&counters).unwrap_err().to_string();
    assert!(e.contains("3 texture reads"), "{e}");
}
