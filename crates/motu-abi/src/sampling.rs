//! The per-pixel sample sequence every renderer draws its random numbers from: Owen-scrambled
//! Sobol points in 2D pairs (Burley 2020, "Practical Hash-based Owen Scrambling"), identical on
//! the GPU (`shaders/sampling.glsl`, line by line; integer arithmetic only, so the numbers are
//! equal bit for bit and a rerun repeats them).
//!
//! A sample's dimensions come in pairs (`dim / 2`: the primary ray's jitter or a bounce's
//! direction is pair 0, ambient-occlusion or environment ray `k` pair `1 + k`). Each pair is the
//! first two Sobol dimensions, a (0, 2)-sequence: the first 2^m samples of a pixel are
//! stratified over every elementary interval of area 2^-m. Each pixel, pair and path vertex
//! gets its own scrambling seed: the sample index is shuffled by a nested uniform scramble
//! (decorrelating pairs, which would otherwise all be the same sequence), and each coordinate is
//! Owen-scrambled. The error of an N-sample estimate of a smooth integrand then falls about as
//! N^-1 (N^-1.5 for Owen scrambling of smooth functions) rather than the hash's N^-0.5.

/// Bits of a renderer's sample word that number the sample; the bits above number the path
/// vertex (`sample | bounce << 20`, docs/shading.md).
pub const SAMPLE_INDEX_BITS: u32 = 20;

/// A uniform number in [0, 1) for pixel `pixel`, sample word `sample` (index in the low
/// [`SAMPLE_INDEX_BITS`], path vertex above) and dimension `dim`: 24 bits, exact in `f32`.
pub fn sample01(pixel: u32, sample: u32, dim: u32) -> f32 {
    (sample_bits(pixel, sample, dim) >> 8) as f32 / (1u32 << 24) as f32
}

/// The 32 scrambled bits behind [`sample01`].
pub fn sample_bits(pixel: u32, sample: u32, dim: u32) -> u32 {
    let index = sample & ((1 << SAMPLE_INDEX_BITS) - 1);
    let vertex = sample >> SAMPLE_INDEX_BITS;
    let pair = dim >> 1;
    let seed = hash_u32(hash_u32(pixel) ^ hash_u32(pair ^ vertex.wrapping_mul(0x0001_0193)));
    let shuffled = nested_uniform_scramble(index, seed);
    let (x, y) = sobol_pair(shuffled);
    let (v, salt) = if dim & 1 == 0 {
        (x, 0x68bc_21eb)
    } else {
        (y, 0x02e5_be93)
    };
    nested_uniform_scramble(v, hash_u32(seed ^ salt))
}

/// The first two Sobol dimensions of point `index` (the van der Corput sequence and the one of
/// the polynomial x + 1), as 32-bit fractions.
pub fn sobol_pair(index: u32) -> (u32, u32) {
    let (mut x, mut y) = (0u32, 0u32);
    let mut v = 1u32 << 31;
    let mut i = index;
    let mut bit = 0;
    while i != 0 {
        if i & 1 != 0 {
            x ^= 1 << (31 - bit);
            y ^= v;
        }
        v ^= v >> 1;
        i >>= 1;
        bit += 1;
    }
    (x, y)
}

/// An Owen scramble of `x`'s bits from the most significant down (each bit flipped by a hash
/// of the bits above it): Laine and Karras's permutation on the reversed bits, Burley's
/// constants.
pub fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
    let mut v = x.reverse_bits().wrapping_add(seed);
    v ^= v.wrapping_mul(0x6c50_b47c);
    v ^= v.wrapping_mul(0xb82f_1e52);
    v ^= v.wrapping_mul(0xc7af_e638);
    v ^= v.wrapping_mul(0x8d22_f6e6);
    v.reverse_bits()
}

/// The PCG output hash (Jarzynski and Olano 2020) seeding the scrambles.
pub fn hash_u32(v: u32) -> u32 {
    let state = v.wrapping_mul(747_796_405).wrapping_add(2_891_336_453);
    let word = ((state >> ((state >> 28) + 4)) ^ state).wrapping_mul(277_803_737);
    (word >> 22) ^ word
}

#[cfg(test)]
mod tests {
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
}
