// The traversal-shader core shared by both backends (thesis ch. 4: the "traversal loop" and
// the "instance shader"), emulated on today's APIs with an explicit stack.
//
// Contract: before including this file, a backend declares `Payload pl` (rayPayloadEXT in the
// pipeline backend) and defines
//     void backend_trace(uint tlas, vec3 org, float t_min, vec3 dir, float t_max, bool first_hit)
// which walks TLAS `tlas` (its address is push.tlas_addresses.r[tlas]) with the ray already
// in that TLAS's space, t in [t_min, t_max], and fills `pl`: the closest triangle hit (hit_*) and
// up to PI_CAPACITY programmable-instance candidates with t_near > pl.t_floor (the nearest
// ones; `truncated` set when more were found).
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
};

// Streaming state of the current ray (the paper's `trav_valid`, inverted): set by the backend
// entry point; traverse() marks what it walks and flags rays that met a non-resident structure
// in front of their best hit.
bool g_streaming = false;
bool g_incomplete = false;
uint g_mark = 0u;  // stamp value written by this ray (StreamParams)
// Nearest empty instance met so far: only empties at or before it are needed now. Behind the
// nearest one the ray's outcome is unknown until it is built (it may occlude them), so they
// are only prefetch candidates; the next pass finds them again if they matter. Costs a pass
// per depth layer on a cold start.
float g_empty_t = T_INFINITY;
// Where the ray starts (0 outside streaming). A deferred ray has no hit before its nearest
// empty instance (none in front of it, and no resident one hit), so its next pass resumes
// there: structures it already passed may be evicted without costing it anything.
float g_t_min = 0.0;

// Records `id` as visible in this pass (read first: most marks are repeats, and an atomic on
// the root's slot from every ray would serialise).
void stream_mark_as(uint64_t table, uint id, uint mark) {
    StampTable t = StampTable(table);
    if (t.r[id] < mark) {
        atomicMax(t.r[id], mark);
    }
}

void stream_mark(uint64_t table, uint id) {
    stream_mark_as(table, id, g_mark);
}

// An empty instance at `t_near`: the nearest so far is needed now (and counted, so the host
// builds the most requested first when not all fit); one behind it is marked for prefetching
// only (built after the frame if it fits without evicting this frame's set). `request` is its
// index in the requests table.
void stream_mark_empty(uint64_t table, uint id, uint request, float t_near) {
    if (t_near <= g_empty_t) {
        g_empty_t = t_near;
        stream_mark(table, id);
        if ((g_mark & 1u) != 0u) {
            atomicAdd(StampTable(StreamRef(push.stream).s.requests).r[request], 1u);
        }
    } else {
        stream_mark_as(table, id, g_mark & ~1u);
    }
}

struct TraceHit {
    float t;  // T_INFINITY: miss
    uint tlas;
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
    stack[0] = Entry(affine_identity(), 0.0, root_tlas, NONE_U32, -1.0);
    uint sp = 1u;
    TraceHit hit;
    hit.t = T_INFINITY;
    hit.lod = NONE_U32;
    uint traces_at_start = traces;
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
        if (g_streaming) {
            stream_mark(StreamRef(push.stream).s.tlas_stamps, e.tlas);
        }
        pl.tlas = e.tlas;
        pl.count = 0u;
        pl.t_floor = e.t_floor;
        pl.t_max = hit.t;
        pl.truncated = 0u;
        pl.hit_t = -1.0;
        backend_trace(e.tlas, xform_point(e.tlas_from_world, org), g_t_min,
                      xform_vector(e.tlas_from_world, dir), hit.t, first_hit);
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
        // Candidates that can still beat the best hit, farthest first (insertion sort).
        uint order[PI_CAPACITY];
        uint n = 0u;
        float t_kept_max = -1.0;
        for (uint i = 0u; i < pl.count; ++i) {
            float t = pl.c[i].t_near;
            t_kept_max = max(t_kept_max, t);
            if (t >= hit.t) {
                continue;
            }
            uint j = n;
            while (j > 0u && pl.c[order[j - 1u]].t_near < t) {
                order[j] = order[j - 1u];
                j -= 1u;
            }
            order[j] = i;
            n += 1u;
        }
        if (pl.truncated != 0u) {
            // Candidates beyond the kept ones were dropped: walk this TLAS again later for
            // those only (t_near > the farthest kept one).
            truncations += 1u;
            if (t_kept_max < hit.t) {
                if (sp < STACK_SIZE) {
                    stack[sp] = Entry(e.tlas_from_world, t_kept_max, e.tlas, e.lod, t_kept_max);
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
            PiCandidate cd = pl.c[order[k]];
            PiRecord pi = push.pis.r[cd.pi];
            if (pi.kind == PI_EMPTY_BLAS) {
                // A non-resident triangle BLAS in front of the best hit: this ray cannot
                // complete in this pass; mark the BLAS for building and keep walking to find
                // the other structures the next pass needs.
                if (g_streaming) {
                    stream_mark_empty(StreamRef(push.stream).s.blas_stamps, pi.target, pi.target,
                                      cd.t_near);
                    g_incomplete = true;
                }
                continue;
            }
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
            if (g_streaming && push.tlas_addresses.r[tlas] == 0ul) {
                // A non-resident child TLAS (empty instance).
                StreamParams sp = StreamRef(push.stream).s;
                stream_mark_empty(sp.tlas_stamps, tlas, sp.blas_count + tlas, cd.t_near);
                g_incomplete = true;
                continue;
            }
            stack[sp] = Entry(child_from_world, cd.t_near, tlas, lod, -1.0);
            sp += 1u;
        }
    }
    if (g_streaming && hit.t < T_INFINITY) {
        // Resident triangle BLASes are walked by the hardware without a shader callback: the
        // one hit is the one marked (see stream.rs on what this means for eviction). Seen, not
        // needed: a ray that ends up incomplete pins its hit with stream_pin_hit.
        stream_mark_as(StreamRef(push.stream).s.blas_stamps, hit_blas(hit), g_mark & ~1u);
    }
    return hit;
}

// A deferred ray's best hit so far is what it falls back on next pass: needed, so the host
// keeps it resident while building the ray's empty instances.
void stream_pin_hit(TraceHit hit) {
    if (g_streaming && hit.t < T_INFINITY) {
        stream_mark(StreamRef(push.stream).s.blas_stamps, hit_blas(hit));
    }
}

#endif
