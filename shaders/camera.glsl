// Primary rays: mirrors motu_abi::camera::CameraParams::primary_dir operation by operation
// (`precise` keeps the compiler from fusing multiply-adds the Rust code does not fuse).
#ifndef MOTU_CAMERA_GLSL
#define MOTU_CAMERA_GLSL
#include "generated/abi.glsl"

vec3 camera_primary_dir(CameraParams c, uint x, uint y, float ox, float oy) {
    precise vec3 a = c.world_du * (float(x) + ox);
    precise vec3 b = c.world_dv * (float(y) + oy);
    precise vec3 d = (c.world_dir00 + a) + b;
    // glam: v * (1 / sqrt(dot(v, v))), dot as ((x*x + y*y) + z*z).
    precise float len2 = (d.x * d.x + d.y * d.y) + d.z * d.z;
    precise float inv_len = 1.0 / sqrt(len2);
    return d * inv_len;
}
#endif
