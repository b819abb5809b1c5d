use super::*;

const COMMON: &str = include_str!("../../../../../shaders/common.glsl");

fn define(name: &str) -> usize {
    let line = COMMON
        .lines()
        .find_map(|l| l.strip_prefix(&format!("#define {name} ")))
        .unwrap_or_else(|| panic!("common.glsl has no #define {name}"));
    line.split_whitespace()
        .next()
        .unwrap()
        .trim_end_matches('u')
        .parse()
        .unwrap()
}

/// The counters' layout is written twice (here and in common.glsl).
#[test]
fn proxy_count_layout_matches_common_glsl() {
    assert_eq!(define("PROXY_COUNT_BASE"), STAT_WORDS);
    assert_eq!(define("PROXY_KINDS"), PROXY_KINDS);
    assert_eq!(define("PROXY_OUTCOMES"), PROXY_OUTCOMES);
    assert_eq!(define("PROXY_FIELDS"), PROXY_FIELDS);
    assert_eq!(define("PROXY_COUNT_WORDS"), PROXY_COUNT_WORDS);
    assert_eq!(define("PROXY_ITEM_WORDS"), PROXY_ITEM_WORDS);
    // fill_pass's kind order.
    for (i, k) in ["CAMERA", "GUARD", "SHADOW", "AO", "BOUNCE"]
        .iter()
        .enumerate()
    {
        assert_eq!(define(&format!("PROXY_KIND_{k}")), i);
    }
}

/// A pass's counts are what each word grew by, in kind-major, outcome, field order.
#[test]
fn fill_pass_reads_kind_outcome_field_order() {
    let before = vec![1u32; PROXY_COUNT_WORDS];
    let mut now = before.clone();
    // shadow (2), miss (2), calls (1)
    now[PROXY_FIELDS * (PROXY_OUTCOMES * 2 + 2) + 1] += 7;
    // camera, open, rays
    now[0] += 3;
    let mut pass = PassStats::default();
    fill_pass(&now, &before, &mut pass);
    assert_eq!(pass.proxy_calls_shadow.miss.calls, 7);
    assert_eq!(pass.proxy_calls_camera.open.rays, 3);
    assert_eq!(pass.proxy_calls_camera.total().rays, 3);
    assert_eq!(pass.proxy_calls_ao, ProxyCalls::default());
    let mut none = PassStats::default();
    fill_pass(&[], &[], &mut none);
    assert_eq!(none.proxy_calls_camera, ProxyCalls::default());
}
