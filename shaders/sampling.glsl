// The per-pixel sample sequence (motu_abi::sampling, mirrored line by line): Owen-scrambled
// Sobol points in 2D pairs, integer arithmetic only, so the CPU and the GPU draw the same
// numbers bit for bit. Self-contained (the mirror test includes it alone).
#ifndef MOTU_SAMPLING_GLSL
#define MOTU_SAMPLING_GLSL

const uint SAMPLE_INDEX_BITS = 20u;

uint sampling_hash(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

uvec2 sobol_pair(uint index) {
    uvec2 p = uvec2(0u);
    uint v = 1u << 31u;
    uint bit = 0u;
    for (uint i = index; i != 0u; i >>= 1u) {
        if ((i & 1u) != 0u) {
            p.x ^= 1u << (31u - bit);
            p.y ^= v;
        }
        v ^= v >> 1u;
        bit += 1u;
    }
    return p;
}

uint nested_uniform_scramble(uint x, uint seed) {
    uint v = bitfieldReverse(x) + seed;
    v ^= v * 0x6c50b47cu;
    v ^= v * 0xb82f1e52u;
    v ^= v * 0xc7afe638u;
    v ^= v * 0x8d22f6e6u;
    return bitfieldReverse(v);
}

uint sample_bits(uint pixel, uint smp, uint dim) {
    uint index = smp & ((1u << SAMPLE_INDEX_BITS) - 1u);
    uint vertex = smp >> SAMPLE_INDEX_BITS;
    uint pair = dim >> 1u;
    uint seed = sampling_hash(sampling_hash(pixel) ^ sampling_hash(pair ^ (vertex * 0x00010193u)));
    uvec2 p = sobol_pair(nested_uniform_scramble(index, seed));
    bool even = (dim & 1u) == 0u;
    return nested_uniform_scramble(even ? p.x : p.y,
                                   sampling_hash(seed ^ (even ? 0x68bc21ebu : 0x02e5be93u)));
}

float sample01(uint pixel, uint smp, uint dim) {
    return float(sample_bits(pixel, smp, dim) >> 8u) / 16777216.0;
}
#endif
