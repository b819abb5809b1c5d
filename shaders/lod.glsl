// The LOD rule: mirrors motu_abi::lod::select_lod operation by operation.
#ifndef MOTU_LOD_GLSL
#define MOTU_LOD_GLSL
#include "generated/abi.glsl"

uint select_lod(LodParams p, float pixels_per_unit_at_1, float radius_local, float dir_local_len,
                float t_near, uint level_count, uint ray_kind, float u) {
    uint last = level_count > 0u ? level_count - 1u : 0u;
    if (p.forced_lod >= 0) {
        return min(uint(p.forced_lod), last);
    }
    precise float radius_world = radius_local / max(dir_local_len, 1e-20);
    precise float projected_px = (radius_world * pixels_per_unit_at_1) / max(t_near, 1e-6);
    precise float level = max(log2(p.r_max_px / max(projected_px, 1e-20)), 0.0);
    if (ray_kind == RAY_SHADOW) {
        level += p.shadow_bias;
    }
    float whole = floor(level);
    if (p.stochastic != 0u && u < level - whole) {
        whole += 1.0;
    }
    return uint(min(whole, float(last)));
}

// motu_abi::lod_instance::camera_level: a LOD instance slot's level for a camera at `world_eye`.
uint camera_lod(LodParams p, float pixels_per_unit_at_1, vec3 world_eye, LodSlotRecord slot,
                uint level_count) {
    precise vec3 d = slot.center_world - world_eye;
    precise float dist = sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
    return select_lod(p, pixels_per_unit_at_1, slot.radius_world, 1.0, dist, level_count,
                      RAY_PRIMARY, 0.0);
}
#endif
