#version 460
// Smoke test of the shader path: out[i] = in[i] * 2 + i, with the element count as a push constant.
layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Input { uint values_in[]; };
layout(std430, set = 0, binding = 1) writeonly buffer Output { uint values_out[]; };

layout(push_constant) uniform Push { uint count; } push;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= push.count) {
        return;
    }
    values_out[i] = values_in[i] * 2u + i;
}
