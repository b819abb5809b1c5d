use super::*;

#[test]
fn same_seed_same_stream_and_streams_differ() {
    let a: Vec<u64> = (0..8)
        .map({
            let mut r = SplitMix64::new(7);
            move |_| r.next_u64()
        })
        .collect();
    let b: Vec<u64> = (0..8)
        .map({
            let mut r = SplitMix64::new(7);
            move |_| r.next_u64()
        })
        .collect();
    assert_eq!(a, b);
    assert_ne!(derive_seed(7, &[1, 2]), derive_seed(7, &[2, 1]));
    assert_ne!(derive_seed(7, &[1]), derive_seed(8, &[1]));
}

#[test]
fn floats_in_range_and_roughly_uniform() {
    let mut r = SplitMix64::new(42);
    let n = 10_000;
    let mut sum = 0.0;
    for _ in 0..n {
        let x = r.range(2.0, 4.0);
        assert!((2.0..4.0).contains(&x));
        sum += x;
        assert!(r.below(5) < 5);
    }
    let mean = sum / f64::from(n);
    assert!((mean - 3.0).abs() < 0.05, "mean {mean}");
    let v = r.unit_vector();
    let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
    assert!((len - 1.0).abs() < 1e-9);
}
