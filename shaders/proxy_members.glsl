// Streaming: the members of proxy boxes (clusters of instances of a non-resident BLAS,
// motu-gpu `stream/topology.rs`, `stream/member_boxes.rs`): their quantised and exact tests.
// Needs no payload, so the proxy intersection shader (pipeline/proxy_stream.rint) includes it
// as well as candidates.glsl. MOTU_STREAMED only.
#ifndef MOTU_PROXY_MEMBERS_GLSL
#define MOTU_PROXY_MEMBERS_GLSL
#include "common.glsl"

// This invocation's member tests (proxy_entry): quantised boxes tested, and exact tests (an
// instance record read). Flushed by render_pixel.glsl's stream_count_walks where the walk runs
// in the invocation that flushes (the query backend, MOTU_COUNT_MEMBER_TESTS); an any-hit
// shader's globals end with its invocation, so the pipeline backend counts none.
uint g_member_tests = 0u;
uint g_exact_tests = 0u;

// The nearest entry in [t_min, t_max] of the ray into a leaf box of a BLAS placed by
// `tlas_from_blas` (boxes from `first_box`: `fan` top boxes, then `fan` leaves per top box,
// BLAS space, transformed as member boxes are and padded by `pad` more), testing only the
// leaves of the top boxes it enters; -1 when it enters none.
float proxy_boxes_entry(uint64_t table, uint first_box, uint fan, Affine tlas_from_blas,
                        vec3 org, vec3 dir, float t_min, float t_max, float pad) {
    FloatTable bt = FloatTable(table);
    uint entered = 0u;
    float t_leaf = -1.0;
    for (uint k = 0u; k < fan + fan * fan; ++k) {
        if (k >= fan && (k - fan) % fan == 0u && (entered & (1u << ((k - fan) / fan))) == 0u) {
            k += fan - 1u;  // the leaves of a top box the ray missed
            continue;
        }
        uint o = 6u * (first_box + k);
        vec3 bmin = vec3(bt.r[o], bt.r[o + 1u], bt.r[o + 2u]);
        vec3 bmax = vec3(bt.r[o + 3u], bt.r[o + 4u], bt.r[o + 5u]);
        if (bmin.x > bmax.x) {
            continue;  // empty
        }
        Affine m = tlas_from_blas;
        vec3 c = xform_point(m, 0.5 * (bmin + bmax));
        vec3 h0 = 0.5 * (bmax - bmin);
        vec3 h = vec3(dot(abs(m.r0.xyz), h0), dot(abs(m.r1.xyz), h0), dot(abs(m.r2.xyz), h0));
        float p = 2e-3 * max(max(h.x, h.y), h.z) + pad;
        float t = slab_near(org, dir, c - h - p, c + h + p, t_min,
                            t_leaf >= 0.0 ? min(t_max, t_leaf) : t_max);
        if (t < 0.0) {
            continue;
        }
        if (k < fan) {
            entered |= 1u << k;
        } else {
            t_leaf = t;  // only a nearer leaf passes the t_max above
        }
    }
    return t_leaf;
}

// The nearest entry in [t_min, t_hi) of the ray into member instance `instance` (global
// index) of a BLAS with bounds `br` (its bounds under the member's tlas_from_blas, padded as
// the CPU pads proxy boxes, and one of the boxes inside the BLAS where it has them,
// proxy_boxes.rs); -1 when it enters none. member_boxes.rs mirrors the box's arithmetic.
float member_entry(StreamParams s, BlasRecord br, uint instance, uint first_box, uint fan,
                   vec3 org, vec3 dir, float t_min, float t_hi) {
    vec3 centre = 0.5 * (br.bounds_min + br.bounds_max);
    vec3 half_size = 0.5 * (br.bounds_max - br.bounds_min);
    InstanceRecord ir = push.instances.r[instance];
    Affine m = affine_from_array(ir.tlas_from_blas);
    vec3 c = xform_point(m, centre);
    vec3 h = vec3(dot(abs(m.r0.xyz), half_size), dot(abs(m.r1.xyz), half_size),
                  dot(abs(m.r2.xyz), half_size));
    vec3 lo = c - h;
    vec3 hi = c + h;
    // Transformed-box rounding plus the CPU's proxy padding (`padded`): conservative.
    float extent = 2.0 * max(max(h.x, h.y), h.z);
    float magnitude = max(max(max(abs(lo.x), abs(lo.y)), abs(lo.z)),
                          max(max(abs(hi.x), abs(hi.y)), abs(hi.z)));
    float pad = 1e-3 * extent + 2e-5 * magnitude;
    float t = slab_near(org, dir, lo - pad, hi + pad, t_min, t_hi);
    if (t >= 0.0 && fan != 0u) {
        t = proxy_boxes_entry(s.proxy_boxes, first_box, fan, m, org, dir, t_min, t_hi,
                              pad + 2e-5 * magnitude);
    }
    return t;
}

// The reference box member boxes are quantised against (member_boxes.rs `reference`, the
// same arithmetic): a quantised value q stands for origin + q × step, less or plus qpad.
struct QuantRef {
    vec3 origin;
    vec3 step;
    float qpad;
};

QuantRef quant_ref(PiRecord r) {
    vec3 ext = r.aabb_max - r.aabb_min;
    float cmag = max(max(max(abs(r.aabb_min.x), abs(r.aabb_min.y)), abs(r.aabb_min.z)),
                     max(max(abs(r.aabb_max.x), abs(r.aabb_max.y)), abs(r.aabb_max.z)));
    float cext = max(max(ext.x, ext.y), ext.z);
    float grow = 2e-3 * cext + 4e-5 * cmag;
    return QuantRef(r.aabb_min - grow, (ext + 2.0 * grow) * (1.0 / 255.0), 1e-5 * (cmag + cext));
}

// Whether the ray may enter member `i` (of the cluster whose words start at `first`) in
// [t_min, t_max]: it enters its quantised box, or the box is stored as ALWAYS (lo.x > hi.x).
// False only where the exact test (member_entry) would find no entry.
bool member_box_entered(U32Table words, uint first, uint i, QuantRef q, vec3 org, vec3 dir,
                        float t_min, float t_max) {
    uint w0 = words.r[first + 2u * i];
    uint w1 = words.r[first + 2u * i + 1u];
    uvec3 qlo = uvec3(w0 & 255u, (w0 >> 8u) & 255u, (w0 >> 16u) & 255u);
    uvec3 qhi = uvec3(w0 >> 24u, w1 & 255u, (w1 >> 8u) & 255u);
    g_member_tests += 1u;
    if (qlo.x > qhi.x) {
        return true;
    }
    vec3 lo = q.origin + vec3(qlo) * q.step - q.qpad;
    vec3 hi = q.origin + vec3(qhi) * q.step + q.qpad;
    return slab_near(org, dir, lo, hi, t_min, t_max) >= 0.0;
}

// The nearest entry in [t_min, t_hi) of the ray into a member instance of proxy PI `r`'s
// cluster (member_entry); T_INFINITY when it enters none. Each member's box is first tested
// quantised (member_box_entered), read contiguously from the cluster's words; only a member
// whose quantised box the ray enters reads its instance record for the exact test, so the
// result is the exact test's.
float proxy_entry(StreamParams s, PiRecord r, vec3 org, vec3 dir, float t_min, float t_hi) {
    uint blas = r.target;
    uint first = floatBitsToUint(r.child_from_parent[0]);
    uint count = floatBitsToUint(r.child_from_parent[1]);
    uint first_box = 0u;
    uint fan = 0u;
    if (s.proxy_box_index != 0ul) {
        U32Table ix = U32Table(s.proxy_box_index);
        first_box = ix.r[2u * blas];
        fan = ix.r[2u * blas + 1u];
    }
    BlasRecord br = push.blases.r[blas];
    U32Table words = U32Table(s.cluster_members);
    QuantRef q = quant_ref(r);
    float t_best = T_INFINITY;
    for (uint i = 0u; i < count; ++i) {
        float t_max = min(t_hi, t_best);
        if (!member_box_entered(words, first, i, q, org, dir, t_min, t_max)) {
            continue;  // outside the quantised box, so outside the exact one
        }
        g_exact_tests += 1u;
        float t = member_entry(s, br, words.r[first + 2u * count + i], first_box, fan, org, dir,
                               t_min, t_max);
        if (t >= 0.0) {
            t_best = min(t_best, t);
        }
    }
    return t_best;
}

// Whether proxy PI `r` may hold an entry in [t_min, t_hi] (its box, then its members'
// quantised boxes): the proxy intersection shader reports only such boxes, since for any other
// record_proxy finds nothing (every walk's range is within [t_min, t_hi]) and does nothing.
bool proxy_may_open(PiRecord r, vec3 org, vec3 dir, float t_min, float t_hi) {
    if (slab_near(org, dir, r.aabb_min, r.aabb_max, t_min, t_hi) < 0.0) {
        return false;
    }
    U32Table words = U32Table(StreamRef(push.stream).s.cluster_members);
    uint first = floatBitsToUint(r.child_from_parent[0]);
    uint count = floatBitsToUint(r.child_from_parent[1]);
    QuantRef q = quant_ref(r);
    for (uint i = 0u; i < count; ++i) {
        if (member_box_entered(words, first, i, q, org, dir, t_min, t_hi)) {
            return true;
        }
    }
    return false;
}
#endif
