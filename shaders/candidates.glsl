// Candidate recording, shared by the pipeline backend's any-hit shader and the query
// backend's rayQueryProceedEXT loop. Expects `Payload pl` declared by the includer.
#ifndef MOTU_CANDIDATES_GLSL
#define MOTU_CANDIDATES_GLSL
#include "common.glsl"

// Records a candidate in the payload, keeping the PI_CAPACITY first in (t_near, pi) order
// after the floor (called from any-hit or from the ray-query loop).
void record_candidate(uint pi, float t_near) {
    if (!candidate_before(pl.t_floor, pl.floor_pi, t_near, pi)) {
        return;
    }
    if (pl.count < PI_CAPACITY) {
        pl.c[pl.count] = PiCandidate(pi, t_near);
        pl.count += 1u;
        return;
    }
    pl.truncated = 1u;
    uint far_i = 0u;
    for (uint i = 1u; i < PI_CAPACITY; ++i) {
        if (candidate_before(pl.c[far_i].t_near, pl.c[far_i].pi, pl.c[i].t_near, pl.c[i].pi)) {
            far_i = i;
        }
    }
    if (candidate_before(t_near, pi, pl.c[far_i].t_near, pl.c[far_i].pi)) {
        pl.c[far_i] = PiCandidate(pi, t_near);
    }
}

// The global PI index of primitive `primitive` of instance `instance` of TLAS `tlas`.
uint pi_index(uint tlas, uint instance, uint primitive) {
    uint blas = push.instances.r[push.tlases.r[tlas].instance_base + instance].blas;
    return push.blases.r[blas].item_base + primitive;
}
#endif
