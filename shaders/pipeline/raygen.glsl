// The body of `pipeline/trace.rgen` and its streamed variant (`pipeline/trace_stream.rgen`: MOTU_STREAMED).
// Backend `pipeline` (every ray-tracing device, the only one on the H200): raygen owns the
// explicit stack and loop (traverse.glsl); each pop traces one TLAS, reached by its device
// address. Stage rules (GL_EXT_ray_tracing): only raygen may call traceRayEXT here; the
// intersection shader may not touch the payload, the any-hit shader may (it records
// candidates and ignores them so traversal continues), the closest-hit records the triangle.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_ray_tracing : require
#include "common.glsl"

layout(location = 0) rayPayloadEXT Payload pl;
#ifdef MOTU_STREAMED
#include "pipeline/open_bound.glsl"
#endif

void backend_trace(uint tlas, vec3 org, float t_min, vec3 dir, float t_max, bool first_hit) {
    uint flags = first_hit ? gl_RayFlagsTerminateOnFirstHitEXT : gl_RayFlagsNoneEXT;
#ifdef MOTU_STREAMED
    if (push.stream != 0ul) {
        open_bound_publish(pl.stream_start, pl.open_t);  // where the proxy intersection reads it
    }
#endif
    // SBT: hit group 0 = triangles (instance SBT offset 0), 1 = programmable instances.
    traceRayEXT(accelerationStructureEXT(push.tlas_addresses.r[tlas]), flags, g_cull_mask, 0u, 0u, 0u,
                org, t_min, dir, t_max, 0);
}

#ifdef MOTU_STREAMED
#include "pipeline/proxy_count.glsl"

// Counting mode (COUNT_PROXY): the item's words, taken (left at 0).
uvec4 backend_proxy_take() {
    uint w = proxy_item_word();
    return uvec4(atomicExchange(push.stats.n[w], 0u), atomicExchange(push.stats.n[w + 1u], 0u),
                 atomicExchange(push.stats.n[w + 2u], 0u),
                 atomicExchange(push.stats.n[w + 3u], 0u));
}
#endif

#include "render_pixel.glsl"

void main() {
    if (push.stream != 0ul) {
        // Streaming passes launch a 1-D item list folded into rows of gl_LaunchSizeEXT.x.
        render_stream_item(gl_LaunchIDEXT.y * gl_LaunchSizeEXT.x + gl_LaunchIDEXT.x);
        return;
    }
#ifndef MOTU_STREAMED
    render_pixel(gl_LaunchIDEXT.xy);  // the streamed variant only runs streaming passes
#endif
}
