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
mod tests;
