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

/// The parallel tone map gives the sequential one's bytes and exposure to the bit, on images
/// with dark, black and clipping pixels and a size no multiple of its tasks (a bad sum order
/// or a skipped remainder would show).
#[test]
fn parallel_auto_exposure_equals_the_sequential_one_bit_for_bit() {
    let mut state = 0x9e37_79b9u32;
    let mut next = move || {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        state
    };
    for (pixels, dark) in [
        (640 * 360 + 7, false),
        (10_001, true),
        (3, false),
        (0, false),
    ] {
        let words: Vec<u32> = (0..pixels)
            .map(|i| {
                let r = next();
                let scale = if dark { 1e-5 } else { 4.0 };
                let c = [r & 1023, (r >> 10) & 1023, (r >> 20) & 1023]
                    .map(|v| v as f32 / 1023.0 * scale * (i % 5) as f32);
                motu_abi::shade::encode_rgb9e5(c)
            })
            .collect();
        let mut seq: Vec<u8> = bytemuck::cast_slice(&words).to_vec();
        let mut par = seq.clone();
        let ev_seq = motu_abi::shade::resolve_auto_exposure(&mut seq);
        let ev_par = resolve_auto_exposure_parallel(&mut par);
        assert_eq!(ev_seq.to_bits(), ev_par.to_bits(), "{pixels} pixels");
        assert!(seq == par, "{pixels} pixels: tone-mapped bytes differ");
        if pixels > 100 {
            assert_ne!(ev_seq, 0.0, "the image should hold light");
        }
    }
}
