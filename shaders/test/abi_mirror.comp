#version 460
// Evaluates camera_primary_dir and select_lod on many inputs so a test can compare them with
// the Rust functions of motu-abi.
#extension GL_EXT_buffer_reference : require
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#include "camera.glsl"
#include "lod.glsl"
layout(local_size_x = 64) in;

struct LodCase {
    LodParams p;
    float pixels_per_unit_at_1;
    float radius_local;
    float dir_local_len;
    float t_near;
    uint level_count;
    uint ray_kind;
    float u;
    uint _pad;
};

layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer Cameras { CameraParams c[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer LodCases { LodCase c[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) writeonly buffer Dirs { vec4 d[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) writeonly buffer Levels { uint l[]; };

layout(push_constant) uniform Push {
    Cameras cameras;
    LodCases lod_cases;
    Dirs dirs;
    Levels levels;
    uint camera_count;
    uint pixels_per_camera;
    uint lod_count;
    uint _pad;
} push;

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint cam_total = push.camera_count * push.pixels_per_camera;
    if (i < cam_total) {
        CameraParams c = push.cameras.c[i / push.pixels_per_camera];
        uint k = i % push.pixels_per_camera;
        uint x = (k * 7919u) % max(c.width, 1u);
        uint y = (k * 104729u) % max(c.height, 1u);
        push.dirs.d[i] = vec4(camera_primary_dir(c, x, y, 0.5, 0.5), 0.0);
    }
    if (i < push.lod_count) {
        LodCase l = push.lod_cases.c[i];
        push.levels.l[i] = select_lod(l.p, l.pixels_per_unit_at_1, l.radius_local, l.dir_local_len,
                                      l.t_near, l.level_count, l.ray_kind, l.u);
    }
}
