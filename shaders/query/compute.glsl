// The body of `query/trace.comp` and its streamed variant (`query/trace_stream.comp`: MOTU_STREAMED).
// Backend `query`: the traversal loop in a compute shader with GL_EXT_ray_query (the thesis's
// form, for devices with ray queries). Candidates of programmable instances (AABBs) are
// slab-tested and recorded during rayQueryProceedEXT; the instance shader (traverse.glsl) runs
// after each query.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_ray_query : require
layout(local_size_x = 8, local_size_y = 8) in;
#include "common.glsl"

Payload pl;
// The traversal loop runs in this invocation, so candidates.glsl's member-test counters reach
// the stats words (render_pixel.glsl).
#define MOTU_COUNT_MEMBER_TESTS
#include "candidates.glsl"
#include "texture.glsl"

#ifdef MOTU_STREAMED
// Counting mode (COUNT_PROXY): proxy candidates met, and what backend_proxy_take last took.
uint g_proxy_calls = 0u;
uvec4 g_proxy_taken = uvec4(0u);

// The walks' proxy work since the last take: calls = reports (every candidate runs
// record_proxy here), quantised and exact member tests.
uvec4 backend_proxy_take() {
    uvec4 now = uvec4(g_proxy_calls, g_proxy_calls, g_member_tests, g_exact_tests);
    uvec4 d = now - g_proxy_taken;
    g_proxy_taken = now;
    return d;
}
#endif

void backend_trace(uint tlas, vec3 org, float t_min, vec3 dir, float t_max, bool first_hit) {
    rayQueryEXT rq;
    uint flags = first_hit ? gl_RayFlagsTerminateOnFirstHitEXT : gl_RayFlagsNoneEXT;
    rayQueryInitializeEXT(rq, accelerationStructureEXT(push.tlas_addresses.r[tlas]), flags, g_cull_mask,
                          org, t_min, dir, t_max);
    while (rayQueryProceedEXT(rq)) {
        if (rayQueryGetIntersectionTypeEXT(rq, false) == gl_RayQueryCandidateIntersectionAABBEXT) {
            uint instance = rayQueryGetIntersectionInstanceCustomIndexEXT(rq, false);
            uint primitive = rayQueryGetIntersectionPrimitiveIndexEXT(rq, false);
            // A proxy box's instance (SBT offset PROXY_SBT_OFFSET) names its proxy (or marks)
            // BLAS's record in the custom index (stream/tlas_encode.rs).
            bool proxy = rayQueryGetIntersectionInstanceShaderBindingTableRecordOffsetEXT(
                             rq, false) == PROXY_SBT_OFFSET;
            uint pi = proxy ? push.blases.r[instance].item_base + primitive
                            : pi_index(tlas, instance, primitive);
            PiRecord r = push.pis.r[pi];
            float t_hi = rayQueryGetIntersectionTypeEXT(rq, true) ==
                                 gl_RayQueryCommittedIntersectionTriangleEXT
                             ? rayQueryGetIntersectionTEXT(rq, true)
                             : t_max;
            vec3 o = rayQueryGetIntersectionObjectRayOriginEXT(rq, false);
            vec3 d = rayQueryGetIntersectionObjectRayDirectionEXT(rq, false);
            if (r.kind == PI_EMPTY_BLAS) {
#ifdef MOTU_STREAMED
                if (COUNT_PROXY != 0u) {
                    g_proxy_calls += 1u;
                }
#endif
                record_proxy(r, o, d, t_min, t_hi);
                continue;
            }
            float t_near = slab_near(o, d, r.aabb_min, r.aabb_max, t_min, t_hi);
            if (t_near >= 0.0) {
                record_candidate(pi, t_near);
            }
        } else if (alpha_passes(tlas, rayQueryGetIntersectionInstanceCustomIndexEXT(rq, false),
                                rayQueryGetIntersectionGeometryIndexEXT(rq, false),
                                rayQueryGetIntersectionPrimitiveIndexEXT(rq, false),
                                rayQueryGetIntersectionBarycentricsEXT(rq, false))) {
            // A non-opaque (alpha-tested) triangle whose texel covers the hit.
            rayQueryConfirmIntersectionEXT(rq);
        }
    }
    if (rayQueryGetIntersectionTypeEXT(rq, true) == gl_RayQueryCommittedIntersectionTriangleEXT) {
        pl.hit_t = rayQueryGetIntersectionTEXT(rq, true);
        pl.hit_instance = rayQueryGetIntersectionInstanceCustomIndexEXT(rq, true);
        pl.hit_geometry = rayQueryGetIntersectionGeometryIndexEXT(rq, true);
        pl.hit_primitive = rayQueryGetIntersectionPrimitiveIndexEXT(rq, true);
    }
}

#include "render_pixel.glsl"

void main() {
    if (push.stream != 0ul) {
        // Streaming passes dispatch a 1-D item list (8 × 8 items per group, groups in 2-D).
        uint group = gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x;
        render_stream_item(group * 64u + gl_LocalInvocationIndex);
        return;
    }
#ifndef MOTU_STREAMED
    render_pixel(gl_GlobalInvocationID.xy);  // the streamed variant only runs streaming passes
#endif
}
