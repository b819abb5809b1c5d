#version 460
// Smoke test of buffers reached by device address (the way traversal shaders read node
// tables): dst[i] = src[i] + offset, both buffers passed as 64-bit addresses in push constants.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
layout(local_size_x = 64) in;

layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer Src { uint v[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) writeonly buffer Dst { uint v[]; };

layout(push_constant) uniform Push {
    uint64_t src_address;
    uint64_t dst_address;
    uint count;
    uint offset;
} push;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= push.count) {
        return;
    }
    Dst(push.dst_address).v[i] = Src(push.src_address).v[i] + push.offset;
}
