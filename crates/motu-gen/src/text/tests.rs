use super::*;

fn fixed(x: f64, d: u32) -> String {
    let mut v = Vec::new();
    push_fixed(&mut v, x, d);
    String::from_utf8(v).unwrap_or_default()
}

#[test]
fn fixed_matches_std_formatting_after_trimming() {
    let cases = [
        0.0,
        -0.0,
        1.0,
        -1.0,
        0.5,
        -0.25,
        1234.5678,
        -9876.54321,
        1e-7,
        -1e-7,
        0.1,
        2.0 / 3.0,
        123456789.125,
        1e15,
    ];
    for &x in &cases {
        for d in [0u32, 1, 3, 4, 6, 9] {
            let ours = fixed(x, d);
            let mut std = format!("{x:.*}", d as usize);
            if std.contains('.') {
                std = std.trim_end_matches('0').trim_end_matches('.').to_string();
            }
            if std == "-0" {
                std = "0".to_string();
            }
            // Rounding ties may differ (we round half away from zero after
            // scaling); the parsed values must agree to the last decimal.
            let a: f64 = ours.parse().unwrap_or(f64::NAN);
            let b: f64 = std.parse().unwrap_or(f64::NAN);
            assert!(
                (a - b).abs() <= 1.0 / POW10[d as usize] + 1e-12 * x.abs(),
                "{x} d={d}: {ours} vs {std}"
            );
            assert!(!ours.starts_with("-0") || ours.starts_with("-0."), "{ours}");
            assert!(!ours.ends_with('0') || !ours.contains('.'), "{ours}");
        }
    }
    assert_eq!(fixed(-0.00001, 3), "0");
    assert_eq!(fixed(12.5, 3), "12.5");
    assert_eq!(fixed(-3.0, 6), "-3");
    assert_eq!(fixed(0.000123, 6), "0.000123");
}

#[test]
fn integers() {
    for n in [0u64, 7, 10, 99, 12345, u64::MAX] {
        let mut v = Vec::new();
        push_u64(&mut v, n);
        assert_eq!(String::from_utf8(v).unwrap_or_default(), n.to_string());
    }
}
