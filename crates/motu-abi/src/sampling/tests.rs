use super::*;

#[test]
fn sobol_pair_is_a_0_2_sequence() {
    // Every block of 2^m points puts one point in each elementary interval of area 2^-m.
    for m in 0..=8u32 {
        let n = 1u32 << m;
        for a in 0..=m {
            let b = m - a;
            let mut seen = vec![false; n as usize];
            for i in 0..n {
                let (x, y) = sobol_pair(i);
                let cx = if a == 0 { 0 } else { x >> (32 - a) };
                let cy = if b == 0 { 0 } else { y >> (32 - b) };
                let cell = (cx << b | cy) as usize;
                assert!(!seen[cell], "m {m} a {a}: two points in cell {cell}");
                seen[cell] = true;
            }
        }
    }
}

#[test]
fn scrambled_samples_stay_stratified_per_pixel() {
    // The scrambles are bijections that keep the net: the first 16 samples of any pixel
    // and pair still fall one in each 4x4 cell.
    for pixel in [0u32, 1, 77, 123_456] {
        for pair in 0..4u32 {
            for vertex in [0u32, 1, 3] {
                let mut seen = [false; 16];
                for i in 0..16u32 {
                    let s = i | vertex << SAMPLE_INDEX_BITS;
                    let x = sample_bits(pixel, s, 2 * pair) >> 30;
                    let y = sample_bits(pixel, s, 2 * pair + 1) >> 30;
                    let cell = (x * 4 + y) as usize;
                    assert!(!seen[cell], "pixel {pixel} pair {pair} vertex {vertex}");
                    seen[cell] = true;
                }
            }
        }
    }
}

#[test]
fn pixels_pairs_and_vertices_are_decorrelated() {
    assert_ne!(sample01(1, 5, 0), sample01(2, 5, 0));
    assert_ne!(sample01(1, 5, 0), sample01(1, 5, 2));
    assert_ne!(
        sample01(1, 5, 0),
        sample01(1, 5 | 1 << SAMPLE_INDEX_BITS, 0)
    );
    // Over many pixels, sample 3's numbers are uniform and pairs uncorrelated.
    let n = 8192u32;
    let (mut mean, mut cross) = (0.0f64, 0.0f64);
    for p in 0..n {
        let (a, b) = (sample01(p, 3, 0) as f64, sample01(p, 3, 2) as f64);
        mean += a;
        cross += (a - 0.5) * (b - 0.5);
    }
    mean /= n as f64;
    cross /= n as f64;
    assert!((mean - 0.5).abs() < 0.01, "{mean}");
    assert!(cross.abs() < 0.01, "{cross}");
}

#[test]
fn integration_error_falls_faster_than_random() {
    // ∫∫ x·y over the unit square (1/4), per pixel with 16 and 256 samples: the mean
    // error over pixels falls by far more than the 4x of independent random numbers.
    let err = |n: u32| {
        let mut e = 0.0f64;
        for p in 0..64u32 {
            let s: f64 = (0..n)
                .map(|i| sample01(p, i, 2) as f64 * sample01(p, i, 3) as f64)
                .sum();
            e += (s / n as f64 - 0.25).abs();
        }
        e / 64.0
    };
    let (e16, e256) = (err(16), err(256));
    assert!(e256 * 8.0 < e16, "error at 16 spp {e16}, at 256 spp {e256}");
}
