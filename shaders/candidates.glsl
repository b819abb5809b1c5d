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

#ifdef MOTU_STREAMED
#include "proxy_members.glsl"

// Streaming: the ray (in the walked TLAS's space = the proxy BLAS's, which is instanced with
// identity) entered proxy PI `r`'s box, which stands for up to PROXY_CLUSTER_INSTANCES
// instances of non-resident BLAS `r.target` (or, in a marks BLAS, of a resident one), before
// `t_hi` (the trace's t_max or the closest triangle committed so far). Done here, during the
// hardware walk, rather than as a PI candidate: a ray crossing N proxy boxes took
// ⌈N / PI_CAPACITY⌉ re-walks of the whole TLAS for them. The first walk keeps the nearest
// member entry of an open BLAS in the payload (open_t, open_blas: the ray's request if it stays
// in front of the walk's hit) and marks nothing; the mark walk (traverse.glsl), whose t_max is
// the first walk's hit and which tests no triangle, marks every BLAS it enters open (seen for
// guard rays, and for a resident BLAS met through its TLAS's marks BLAS in a probe pass).
void record_proxy(PiRecord r, vec3 org, vec3 dir, float t_min, float t_hi) {
    if (push.stream == 0ul) {
        return;  // proxies exist only in streamed skeletons
    }
    float t_box = slab_near(org, dir, r.aabb_min, r.aabb_max, t_min, t_hi);
    if (t_box < 0.0) {
        return;
    }
    bool mark_walk = (pl.stream_start & STREAM_MARK_WALK) != 0u;
    if (!mark_walk && t_box >= pl.open_t) {
        // The first walk keeps only the nearest open entry, and no member of this box is
        // entered before the box: its member tests (proxy_entry) would change nothing. An open
        // ray's walk meets every box to its far end, most behind its nearest open one.
        return;
    }
    StreamParams s = StreamRef(push.stream).s;
    uint blas = r.target;
    bool guard = (pl.stream_start & STREAM_GUARD_RAY) != 0u;
    if (guard && !mark_walk) {
        return;  // a guard ray only marks, in its mark walk
    }
    uint walked = StampTable(s.walked).r[blas];
    // Only mark walks of probe passes meet marks BLASes (resident: walked this pass).
    bool resident = walked == s.stamp;
    if (!guard && !resident && walked >= (pl.stream_start & STREAM_START_STAMP)) {
        return;  // walked by this ray in an earlier pass: resolved
    }
    uint mark = 4u * s.stamp + (guard || resident ? STREAM_SEEN : STREAM_OPEN);
    if ((pl.stream_start & STREAM_PASS_WALK) != 0u) {
        // A final probe ray's pass-mark walk: only resident BLASes it passes, as passed.
        if (!resident) {
            return;
        }
        mark = 4u * s.stamp - 1u;
    }
    if (mark_walk && StampTable(s.blas_stamps).r[blas] >= mark) {
        return;  // another ray marked it already: the member tests would change nothing
    }
    float t = proxy_entry(s, r, org, dir, t_min, mark_walk ? t_hi : min(t_hi, pl.open_t));
    if (t >= t_hi) {
        return;
    }
    if (!mark_walk) {
        if (t < pl.open_t) {
            pl.open_t = t;
            pl.open_blas = blas;
        }
        return;
    }
    stream_mark(s.blas_stamps, blas, mark);
}
#else
// Full builds have no proxies: only streamed skeletons do, and only the streamed shaders
// (MOTU_STREAMED) trace them.
void record_proxy(PiRecord r, vec3 org, vec3 dir, float t_min, float t_hi) {}
#endif

// The global PI index of primitive `primitive` of instance `instance` of TLAS `tlas`.
uint pi_index(uint tlas, uint instance, uint primitive) {
    uint blas = push.instances.r[push.tlases.r[tlas].instance_base + instance].blas;
    return push.blases.r[blas].item_base + primitive;
}
#endif
