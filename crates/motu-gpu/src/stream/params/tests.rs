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
    let flags = [
        STREAM_PROBE_PASS,
        STREAM_PROBE_STOP,
        STREAM_LAST_PASS,
        STREAM_NO_MARK_WALK,
    ];
    assert_eq!(flags.iter().fold(0, |a, f| a | f).count_ones(), 4);
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
