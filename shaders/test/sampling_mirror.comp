#version 460
// Evaluates sample_bits (sampling.glsl) on many inputs so a test can compare them with
// motu_abi::sampling bit for bit.
#extension GL_EXT_buffer_reference : require
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#include "sampling.glsl"
layout(local_size_x = 64) in;

layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer Cases { uvec4 c[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) writeonly buffer Bits { uint b[]; };

layout(push_constant) uniform Push {
    Cases cases;  // x pixel, y sample word, z dimension
    Bits bits;
    uint count;
    uint _pad;
} push;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i < push.count) {
        uvec4 c = push.cases.c[i];
        push.bits.b[i] = sample_bits(c.x, c.y, c.z);
    }
}
