// The body of `pipeline/pi.rahit` and its streamed variant (`pipeline/pi_stream.rahit`:
// MOTU_STREAMED, proxies marked by the mark walk). Any-hit of a programmable instance: slab
// test in BLAS space, record (PI, t_near, instance) in the payload, ignore the intersection so
// traversal continues. The AABB geometry carries NO_DUPLICATE_ANY_HIT_INVOCATION, so each box
// is recorded at most once per trace.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_ray_tracing : require
#include "common.glsl"

layout(location = 0) rayPayloadInEXT Payload pl;
hitAttributeEXT float committed_t;  // pi.rint: the closest triangle committed so far
#include "candidates.glsl"

void main() {
    // Not gl_RayTmaxEXT: in any-hit that is the t the intersection shader reported (a
    // placeholder inside the ray interval), not the trace's t_max; clipping against it lost
    // every box entered beyond it (regression test: pipeline_matches_cpu_on_a_forest_package).
    uint pi = pi_index(pl.tlas, gl_InstanceCustomIndexEXT, gl_PrimitiveID);
    PiRecord r = push.pis.r[pi];
    // Never a proxy: proxy boxes have their own hit group (pipeline/proxy_stream.rahit).
    float t_near = slab_near(gl_ObjectRayOriginEXT, gl_ObjectRayDirectionEXT, r.aabb_min,
                             r.aabb_max, gl_RayTminEXT, pl.t_max);
    if (t_near >= 0.0) {
        record_candidate(pi, t_near);
    }
    ignoreIntersectionEXT;
}
