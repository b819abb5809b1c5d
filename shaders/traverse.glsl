// The traversal-shader core shared by both backends (thesis ch. 4: the "traversal loop" and
// the "instance shader"), emulated on today's APIs with an explicit stack.
//
// Contract: before including this file, a backend declares `Payload pl` (rayPayloadEXT in the
// pipeline backend) and defines
//     void backend_trace(uint tlas, vec3 org, float t_min, vec3 dir, float t_max, bool first_hit)
// and, streamed (MOTU_STREAMED), `uvec4 backend_proxy_take()`: the proxy work of the walks
// since its last call (calls, reports, quantised and exact member tests; counting mode only)
// which walks TLAS `tlas` (its address is push.tlas_addresses.r[tlas]) with the ray already
// in that TLAS's space, t in [t_min, t_max], and fills `pl`: the closest triangle hit (hit_*) and
// up to PI_CAPACITY programmable-instance candidates after (pl.t_floor, pl.floor_pi) in
// (t_near, pi) order (the first ones; `truncated` set when more were found). Streaming proxy
// boxes are no candidates: the walk itself keeps the nearest open one (pl.open_t, open_blas).
//
// Semantics mirror motu-trace (the CPU oracle): rays move between spaces by affine 3×4
// matrices without renormalising the direction, so every t is a world distance; entries whose
// t_near >= best t are skipped; candidates are pushed farthest first so the nearest pops
// next; a LOD selector picks its level with select_lod at the candidate's t_near.
#ifndef MOTU_TRAVERSE_GLSL
#define MOTU_TRAVERSE_GLSL
#include "common.glsl"
#include "lod.glsl"

// Entries of the explicit stack; overflow drops the entry and is counted in the stats buffer.
layout(constant_id = 0) const uint STACK_SIZE = 16u;
// TLAS walks one traverse() may make (bounds a frame on exponential instancing); a ray cut
// short sets g_truncated, counted per pixel in STAT_TRUNCATED_RAYS.
layout(constant_id = 1) const uint MAX_TRACES_PER_RAY = 4096u;
bool g_truncated = false;

// One pending TLAS walk: 64 bytes.
struct Entry {
    Affine tlas_from_world;
    float t_near;
    uint tlas;
    uint lod;       // level of the innermost selector on the path, NONE_U32 if none
    float t_floor;  // -1, or the re-walk floor after a truncated candidate list
    uint floor_pi;  // with t_floor: the farthest candidate kept by the truncated walk
};

// Streaming state of the current ray (carried hits, see motu-gpu's stream module): a pass walks
// what is resident now against the pixel's best hit carried from earlier passes. A
// non-resident BLAS in front of the best hit is *open* unless it was resident in a pass since
// this ray started (`walked` ≥ g_start): that pass walked it, so its hits are already carried.
bool g_streaming = false;
// The kind of the ray being traced (STREAM_HIT_*): or-ed into the request word of the
// resident BLAS holding its hit.
uint g_hit_kind = STREAM_HIT_CAMERA;
bool g_guard = false;   // a guard-band ray (prefetch probe): marks only
bool g_probe = false;   // a probe pass of the next frame: marks, never defers nor writes
// A probe ray of a pass-mark row (StreamParams.flags' pass rows): its mark walk runs even when
// its hit is final, and marks what it passes as passed only (STREAM_PASS_WALK).
bool g_probe_pass_marks = false;
// A probe ray of this pixel met an open structure in front of its hit: the pixel goes on the
// pass's incomplete list (its only write), so the next probe round traces it alone.
bool g_probe_open = false;
// STREAM_PROBE_STOP: a probe ray left open ends its pixel's path (closest-hit links only).
bool g_probe_stop = false;
// The last stream_still_open call of a probe ray found it open (reset by the caller).
bool g_probe_link_open = false;
uint g_stamp = 0u;      // this pass's stamp
uint g_start = 0u;      // the stamp of the pass this ray (primary or shadow) started in
float g_best_t = T_INFINITY;  // the carried best hit's t (culls this walk)
// The nearest open structure: the pixel's request for the next pass.
float g_empty_t = T_INFINITY;
uint g_empty_id = NONE_U32;
// Where the ray ends (shadow rays towards a point light); T_INFINITY otherwise.
float g_t_max = T_INFINITY;
#ifdef MOTU_STREAMED
// The current walk is a ray's *mark walk*: after the first walk found the pass's hit, a second
// walk over PI and proxy boxes only (CULL_MASK_MARK_WALK, no triangle tested) marks the
// structures in front of that hit, open or (probe passes, through the marks BLASes) resident
// and passed. Marked during the first walk, they were judged against the closest hit *so far*
// in the hardware's order, and most of them lay behind the ray's hit: the host built them
// ahead for nothing, crowding out what later frames need (issue 14 item 6). Only rays that stay
// open (their nearest open structure is their request, found by the first walk) and guard rays
// take it, probe rays included only when open: marking what every probe ray passed as seen kept
// more resident than the next frames used (BENCHMARKS.md). Probe rays of pass-mark rows
// (g_probe_pass_marks) take it too when final, marking what they pass as *passed* only: the
// host refreshes those BLASes' LRU age without keeping them (g_pass_walk). The marks are hints
// for building ahead and keeping, never needed for correctness, so a mark walk cut short
// truncates nothing.
bool g_mark_walk = false;
bool g_pass_walk = false;  // this mark walk is a final ray's pass-mark walk
// This invocation's mark walks and their TLAS walks (STAT_MARK_WALKS, STAT_MARK_TLAS_WALKS).
uint g_mark_walks = 0u;
uint g_mark_tlas_walks = 0u;
// The pass is its frame's last (STREAM_LAST_PASS): no secondary rays are traced ahead.
bool g_last_pass = false;
// No mark walks this pass (STREAM_NO_MARK_WALK): nothing is built after it.
bool g_no_mark_walk = false;
// Counting mode (COUNT_PROXY): the kind of the ray being traced (PROXY_KIND_*).
uint g_count_kind = PROXY_KIND_CAMERA;

// Counting mode: adds a ray that ended with `hit_t` (`hit_found`: a triangle of this trace) and
// what its walks cost (`d`: backend_proxy_take) to its kind's and outcome's counters. Open as
// stream_still_open judges it; closed: a hit (this trace's or the carried one) or occluded;
// miss: neither.
void proxy_count_ray(uvec4 d, float hit_t, bool hit_found, bool first_hit) {
    bool open = !g_guard && g_empty_t < hit_t && !(first_hit && hit_found);
    bool closed = !open && (hit_found || g_best_t < g_t_max);
    uint outcome = open ? 0u : (closed ? 1u : 2u);
    uint w = PROXY_COUNT_BASE + PROXY_FIELDS * (PROXY_OUTCOMES * g_count_kind + outcome);
    atomicAdd(push.stats.n[w], 1u);
    for (uint f = 0u; f < 4u; ++f) {
        if (d[f] != 0u) {
            atomicAdd(push.stats.n[w + 1u + f], d[f]);
        }
    }
}
#endif

// Records `id` at `level` in this pass.
void stream_mark_as(uint64_t table, uint id, uint level) {
    stream_mark(table, id, 4u * g_stamp + level);
}

// After a walk: whether an open structure lies in front of the best hit `best_t`; if so its
// nearest is requested (needed, counted so the host builds the most requested first). A probe
// pass requests the same but goes on as if the ray were final (it prefetches, never defers).
bool stream_still_open(float best_t) {
    if (!g_streaming || g_guard || g_empty_t >= best_t) {
        return false;
    }
    StreamParams s = StreamRef(push.stream).s;
    stream_mark_as(s.blas_stamps, g_empty_id, STREAM_NEEDED);
    if (StampTable(s.walked).r[g_empty_id] == s.stamp) {
        // Resident, met in a stale TLAS's proxy (motu-gpu stream/piece_order.rs): open until
        // that TLAS is rebuilt, nothing to build. Its request word holds the kinds of ray
        // whose closest hit it held (HIT_*), which a count would corrupt.
        g_probe_open = g_probe_open || g_probe;
        g_probe_link_open = g_probe;
        return !g_probe;
    }
    StampTable requests = StampTable(s.requests);
    atomicAdd(requests.r[g_empty_id], 1u);
    if (g_hit_kind == STREAM_HIT_CAMERA && requests.r[g_empty_id] < STREAM_REQUEST_CAMERA) {
        // A camera ray waits for it: built ahead of what only secondary rays wait for.
        atomicOr(requests.r[g_empty_id], STREAM_REQUEST_CAMERA);
    }
    g_probe_open = g_probe_open || g_probe;
    g_probe_link_open = g_probe;
    return !g_probe;
}

struct TraceHit {
    float t;  // T_INFINITY: miss
    uint tlas;  // NONE_U32: no hit closer than the carried one (streaming) or none at all
    uint instance;
    uint geometry;
    uint primitive;
    uint lod;
    Affine tlas_from_world;
};

uint hit_blas(TraceHit hit) {
    return push.instances.r[push.tlases.r[hit.tlas].instance_base + hit.instance].blas;
}

TraceHit traverse(uint root_tlas, vec3 org, vec3 dir, uint ray_kind, LodParams lodp, float pixels_per_unit_at_1,
                  float lod_u, bool first_hit, inout uint traces, inout uint overflows,
                  inout uint truncations) {
    Entry stack[STACK_SIZE];
    stack[0] = Entry(affine_identity(), 0.0, root_tlas, NONE_U32, -1.0, 0u);
    uint sp = 1u;
    TraceHit hit;
    hit.t = g_streaming ? min(g_best_t, g_t_max) : g_t_max;
    hit.tlas = NONE_U32;
    hit.lod = NONE_U32;
    uint traces_at_start = traces;
#ifdef MOTU_STREAMED
    // Walk 0 is the ray's walk, walk 1 its mark walk (see g_mark_walk): the same loop, so the
    // traversal is inlined once.
    uint walk_cull_mask = g_cull_mask;
    bool count_first_hit = first_hit;
    if (COUNT_PROXY != 0u && g_streaming) {
        backend_proxy_take();  // nothing of an earlier ray's is left; counted from here
    }
    uvec3 walk_counts = uvec3(0u);  // traces, overflows, truncations of the first walk
    bool walk_truncated = false;
    for (uint walk = 0u; walk < 2u; ++walk) {
#endif
    while (sp > 0u) {
        sp -= 1u;
        Entry e = stack[sp];
        if (e.t_near >= hit.t) {
            continue;
        }
        if (traces - traces_at_start >= MAX_TRACES_PER_RAY) {
            g_truncated = true;
            break;
        }
        traces += 1u;
        pl.tlas = e.tlas;
        pl.count = 0u;
        pl.t_floor = e.t_floor;
        pl.floor_pi = e.floor_pi;
        pl.t_max = hit.t;
        pl.truncated = 0u;
        pl.hit_t = -1.0;
        pl.open_t = T_INFINITY;
        pl.stream_start = g_start | (g_guard ? STREAM_GUARD_RAY : 0u);
#ifdef MOTU_STREAMED
        pl.stream_start |= g_mark_walk ? STREAM_MARK_WALK : 0u;
        pl.stream_start |= g_pass_walk ? STREAM_PASS_WALK : 0u;
#endif
        backend_trace(e.tlas, xform_point(e.tlas_from_world, org), 0.0,
                      xform_vector(e.tlas_from_world, dir), hit.t, first_hit);
        if (pl.open_t < g_empty_t) {
            // The walk met a non-resident BLAS in front of its hits (candidates.glsl
            // `record_proxy`): the nearest is the pixel's request if it stays open.
            g_empty_t = pl.open_t;
            g_empty_id = pl.open_blas;
        }
        if (pl.hit_t >= 0.0 && pl.hit_t < hit.t) {
            hit.t = pl.hit_t;
            hit.tlas = e.tlas;
            hit.instance = pl.hit_instance;
            hit.geometry = pl.hit_geometry;
            hit.primitive = pl.hit_primitive;
            hit.lod = e.lod;
            hit.tlas_from_world = e.tlas_from_world;
            if (first_hit) {
                break;
            }
        }
        // A box list (TlasRecord.box_list_instances, a full build's split root): the TLAS's
        // last instances are AABB instances left out of the hardware walk, whose few PIs are
        // slab-tested here as the any-hit shader would, on the TLAS's first walk only (a
        // re-walk finds what the hardware list truncated, which never holds these).
        PiCandidate boxes[BOX_LIST_CAPACITY];
        uint nb = 0u;
        if (e.t_floor < 0.0) {
            TlasRecord tr = push.tlases.r[e.tlas];
            if (tr.box_list_instances != 0u) {
                vec3 o = xform_point(e.tlas_from_world, org);
                vec3 d = xform_vector(e.tlas_from_world, dir);
                uint end = tr.instance_base + tr.instance_count;
                for (uint i = end - tr.box_list_instances; i < end; ++i) {
                    BlasRecord br = push.blases.r[push.instances.r[i].blas];
                    for (uint p = br.item_base; p < br.item_base + br.item_count; ++p) {
                        PiRecord r = push.pis.r[p];
                        float t = slab_near(o, d, r.aabb_min, r.aabb_max, 0.0, hit.t);
                        if (t >= 0.0 && nb < BOX_LIST_CAPACITY) {
                            boxes[nb] = PiCandidate(p, t);
                            nb += 1u;
                        }
                    }
                }
            }
        }
        // Candidates that can still beat the best hit, farthest first (insertion sort); an
        // index below PI_CAPACITY is the walk's pl.c[i], above it boxes[i - PI_CAPACITY].
#define CANDIDATE(i) ((i) < PI_CAPACITY ? pl.c[(i)] : boxes[(i) - PI_CAPACITY])
        uint order[PI_CAPACITY + BOX_LIST_CAPACITY];
        uint n = 0u;
        float t_kept_max = -1.0;
        uint pi_kept_max = 0u;
        for (uint i = 0u; i < pl.count; ++i) {
            float t = pl.c[i].t_near;
            if (i == 0u || candidate_before(t_kept_max, pi_kept_max, t, pl.c[i].pi)) {
                t_kept_max = t;
                pi_kept_max = pl.c[i].pi;
            }
            if (t >= hit.t) {
                continue;
            }
            uint j = n;
            while (j > 0u && CANDIDATE(order[j - 1u]).t_near < t) {
                order[j] = order[j - 1u];
                j -= 1u;
            }
            order[j] = i;
            n += 1u;
        }
        for (uint b = 0u; b < nb; ++b) {
            float t = boxes[b].t_near;
            uint j = n;
            while (j > 0u && CANDIDATE(order[j - 1u]).t_near < t) {
                order[j] = order[j - 1u];
                j -= 1u;
            }
            order[j] = PI_CAPACITY + b;
            n += 1u;
        }
        if (pl.truncated != 0u) {
            // Candidates beyond the kept ones were dropped: walk this TLAS again later for
            // those only (after the farthest kept one in (t_near, pi) order, ties included).
            truncations += 1u;
            if (t_kept_max < hit.t) {
                if (sp < STACK_SIZE) {
                    stack[sp] = Entry(e.tlas_from_world, t_kept_max, e.tlas, e.lod, t_kept_max,
                                      pi_kept_max);
                    sp += 1u;
                } else {
                    overflows += 1u;
                }
            }
        }
        if (n == 0u) {
            continue;
        }
        for (uint k = 0u; k < n; ++k) {
            PiCandidate cd = CANDIDATE(order[k]);
            // Never a proxy (PI_EMPTY_BLAS): those are handled during the walk.
            PiRecord pi = push.pis.r[cd.pi];
            if (sp >= STACK_SIZE) {
                overflows += 1u;
                continue;
            }
            // The PI's AABB BLAS is instanced with identity (validated): BLAS space = TLAS space.
            Affine child_from_world =
                compose(affine_from_array(pi.child_from_parent), e.tlas_from_world);
            uint tlas = pi.target;
            uint lod = e.lod;
            if (pi.kind == PI_LOD_SELECTOR) {
                LodSelectorRecord sel = push.selectors.r[pi.target];
                float dir_len = length(xform_vector(child_from_world, dir));
                uint level = select_lod(lodp, pixels_per_unit_at_1, sel.radius, dir_len,
                                        cd.t_near, sel.level_count, ray_kind, lod_u);
                tlas = push.lod_levels.r[sel.level_base + level];
                lod = level;
            }
            stack[sp] = Entry(child_from_world, cd.t_near, tlas, lod, -1.0, 0u);
            sp += 1u;
        }
#undef CANDIDATE
    }
#ifdef MOTU_STREAMED
        if (g_mark_walk) {
            // What the mark walk counted is not the ray's: the first walk's counts stand.
            g_mark_tlas_walks += traces - traces_at_start;
            traces = walk_counts.x;
            overflows = walk_counts.y;
            truncations = walk_counts.z;
            g_truncated = walk_truncated;
            break;
        }
        // Open: a structure in front of the hit may hold a nearer one (an occluded shadow ray
        // is final whatever lies in front of its occluder).
        bool open = g_empty_t < hit.t && !(first_hit && hit.tlas != NONE_U32);
        if (!g_streaming || g_truncated || overflows != 0u || g_no_mark_walk ||
            !(g_guard || open || g_probe_pass_marks)) {
            break;  // final, or cut short: nothing to mark
        }
        walk_counts = uvec3(traces, overflows, truncations);
        walk_truncated = g_truncated;
        traces_at_start = traces;
        g_mark_walk = true;
        g_mark_walks += 1u;
        g_pass_walk = !(g_guard || open);
        g_cull_mask = CULL_MASK_MARK_WALK | (g_probe ? CULL_MASK_MARKS : 0u);
        first_hit = false;
        stack[0] = Entry(affine_identity(), 0.0, root_tlas, NONE_U32, -1.0, 0u);
        sp = 1u;
    }
    g_mark_walk = false;
    g_pass_walk = false;
    g_cull_mask = walk_cull_mask;
    if (COUNT_PROXY != 0u && g_streaming) {
        proxy_count_ray(backend_proxy_take(), hit.t, hit.tlas != NONE_U32, count_first_hit);
    }
#endif
    if (g_streaming && hit.tlas != NONE_U32) {
        // Resident triangle BLASes are walked by the hardware without a shader callback: the
        // one hit is what refreshes its BLAS's LRU age (see the stream module). The kind of
        // ray is or-ed into its request word (a resident BLAS is never requested): the host
        // splits the frame's working set by kind (`working_set_camera_bytes`, ...).
        StreamParams s = StreamRef(push.stream).s;
        uint b = hit_blas(hit);
        stream_mark_as(s.blas_stamps, b, STREAM_SEEN);
        StampTable kinds = StampTable(s.requests);
        if ((kinds.r[b] & g_hit_kind) == 0u) {
            atomicOr(kinds.r[b], g_hit_kind);
        }
    }
    return hit;
}

#endif
