use super::*;
use crate::stream::ProbePaths;

const COMMON: &str = include_str!("../../../../../shaders/common.glsl");

fn define(name: &str) -> u32 {
    let line = COMMON
        .lines()
        .find_map(|l| l.strip_prefix(&format!("#define {name} ")))
        .unwrap_or_else(|| panic!("common.glsl has no #define {name}"));
    let v = line
        .split_whitespace()
        .next()
        .unwrap()
        .trim_end_matches('u');
    match v.strip_prefix("0x") {
        Some(h) => u32::from_str_radix(h, 16).unwrap(),
        None => v.parse().unwrap(),
    }
}

/// `StreamParams` and its constants are written twice (here and in common.glsl): this
/// keeps the fields' order and sizes and the constants equal.
#[test]
fn stream_params_match_common_glsl() {
    assert_eq!(define("STREAM_PROBE_PASS"), STREAM_PROBE_PASS);
    assert_eq!(define("STREAM_PROBE_STOP"), STREAM_PROBE_STOP);
    assert_eq!(define("STREAM_LAST_PASS"), STREAM_LAST_PASS);
    assert_eq!(define("STREAM_NO_MARK_WALK"), STREAM_NO_MARK_WALK);
    assert_eq!(define("STREAM_OPEN_BOUND"), STREAM_OPEN_BOUND);
    let flags = [
        STREAM_PROBE_PASS,
        STREAM_PROBE_STOP,
        STREAM_LAST_PASS,
        STREAM_NO_MARK_WALK,
        STREAM_OPEN_BOUND,
    ];
    assert_eq!(flags.iter().fold(0, |a, f| a | f).count_ones(), 5);
    assert!(flags.iter().all(|&f| f < 1 << STREAM_PASS_ROWS_SHIFT));
    assert_eq!(define("STREAM_PASS_ROWS_SHIFT"), STREAM_PASS_ROWS_SHIFT);
    assert_eq!(define("STREAM_START_STAMP") + 1, STAMP_LIMIT);
    for bit in ["STREAM_GUARD_RAY", "STREAM_MARK_WALK", "STREAM_PASS_WALK"] {
        let b = define(bit);
        assert!(
            b.is_power_of_two() && b >= STAMP_LIMIT,
            "{bit} {b:#x} overlaps stamps"
        );
    }
    let body = COMMON
        .split("struct StreamParams {")
        .nth(1)
        .and_then(|s| s.split("};").next())
        .expect("common.glsl has struct StreamParams");
    let fields: Vec<(String, usize)> = body
        .lines()
        .filter_map(|l| {
            let l = l.split("//").next()?.trim();
            let (ty, name) = l.strip_suffix(';')?.split_once(' ')?;
            let size = match ty {
                "uint64_t" => 8,
                "uint" => 4,
                other => panic!("StreamParams field type {other} not mirrored"),
            };
            Some((name.trim().to_string(), size))
        })
        .collect();
    let rust = [
        ("blas_stamps", 8),
        ("walked", 8),
        ("pixel_list", 8),
        ("incomplete", 8),
        ("stamp", 4),
        ("full_count", 4),
        ("list_count", 4),
        ("blas_count", 4),
        ("requests", 8),
        ("carry", 8),
        ("cluster_members", 8),
        ("proxy_box_index", 8),
        ("proxy_boxes", 8),
        ("flags", 4),
        ("_pad", 4),
    ];
    let glsl: Vec<(&str, usize)> = fields.iter().map(|(n, s)| (n.as_str(), *s)).collect();
    assert_eq!(glsl, rust);
    assert_eq!(
        std::mem::size_of::<StreamParams>(),
        rust.iter().map(|f| f.1).sum::<usize>()
    );
}

#[test]
fn probe_flags_carry_the_pass_rows_and_passed_marks_are_one_below_the_pass() {
    assert_eq!(probe_flags(0, ProbePaths::Through), STREAM_PROBE_PASS);
    assert_eq!(
        probe_flags(3, ProbePaths::Through) >> STREAM_PASS_ROWS_SHIFT,
        3
    );
    assert_eq!(
        probe_flags(u32::MAX, ProbePaths::Through) >> STREAM_PASS_ROWS_SHIFT,
        MAX_PASS_ROWS
    );
    assert_eq!(
        probe_flags(u32::MAX, ProbePaths::Through) & STREAM_PROBE_PASS,
        STREAM_PROBE_PASS
    );
    assert_eq!(probe_flags(3, ProbePaths::Through) & STREAM_PROBE_STOP, 0);
    let stop = probe_flags(3, ProbePaths::Stop);
    assert_eq!(
        stop & (STREAM_PROBE_PASS | STREAM_PROBE_STOP),
        STREAM_PROBE_PASS | STREAM_PROBE_STOP
    );
    assert_eq!(stop >> STREAM_PASS_ROWS_SHIFT, 3);
    // Level 3 of the stamp before: above every mark of earlier passes, below this one's.
    assert!(passed_mark(4 * 7 - 1, 7));
    for level in 0..3 {
        assert!(!passed_mark(4 * 7 + level, 7));
        assert!(!passed_mark(4 * 6 + level, 7));
    }
    assert!(!passed_mark(0, 0));
}

/// The carry buffer's layout as the open bound uses it: `CARRY_WORDS` of `common.glsl` is
/// [`CARRY_BYTES`] / 4 and `CARRY_OPEN_BOUND_WORD` the last word of the streamed `Carry`, whose
/// last field is `vec4 thru` (its `w`, no pixel's state: `pipeline/open_bound.glsl`).
#[test]
fn the_open_bound_word_is_the_streamed_carrys_thru_w() {
    const RENDER_PIXEL: &str = include_str!("../../../../../shaders/render_pixel.glsl");
    assert_eq!(u64::from(define("CARRY_WORDS")) * 4, CARRY_BYTES);
    assert_eq!(define("CARRY_OPEN_BOUND_WORD") + 1, define("CARRY_WORDS"));
    let body = RENDER_PIXEL
        .split("struct Carry {")
        .nth(1)
        .and_then(|s| s.split("};").next())
        .expect("render_pixel.glsl has struct Carry");
    let fields: Vec<&str> = body
        .lines()
        .map(|l| l.split("//").next().unwrap_or("").trim())
        .filter(|l| l.ends_with(';'))
        .collect();
    assert!(
        fields
            .iter()
            .all(|f| f.starts_with("vec4 ") || f.starts_with("uvec4 ")),
        "{fields:?}"
    );
    assert_eq!(fields.len() as u64 * 16, CARRY_BYTES, "{fields:?}");
    assert_eq!(fields.last(), Some(&"vec4 thru;"));
}
