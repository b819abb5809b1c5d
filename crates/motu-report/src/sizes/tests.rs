use super::*;

#[test]
fn fit_recovers_a_line_and_reports_its_error() {
    let pts: Vec<(u64, u64)> = [1u64, 4, 16, 64, 1000, 100_000]
        .iter()
        .map(|&n| (n, 500 + 90 * n))
        .collect();
    let (line, err) = fit_linear(&pts);
    assert!((line.bytes_per_item - 90.0).abs() < 1e-6, "{line:?}");
    assert!((line.base_bytes - 500.0).abs() < 1e-3, "{line:?}");
    assert!(err < 1e-9);
    // The H200's shape: a header-dominated start, linear from 64 items.
    let h200 = [
        (1, 1408),
        (4, 2432),
        (16, 3328),
        (64, 7680),
        (256, 25216),
        (4096, 377344),
    ];
    let (line, err) = fit_linear(&h200);
    assert_eq!(line.eval(1), 1408);
    assert_eq!(line.eval(10), 2880);
    assert!(err < 0.02, "{err} {line:?}");
    let (_, err) = fit_linear(&[(256, 100), (512, 100), (1024, 400)]);
    assert!(err > 0.1, "a bent curve has error: {err}");
}
