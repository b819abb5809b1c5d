// One pixel: primary ray, optional shadow ray, AOV record and colour. Shared by both backends
// (included after traverse.glsl).
#ifndef MOTU_RENDER_PIXEL_GLSL
#define MOTU_RENDER_PIXEL_GLSL
#include "camera.glsl"
#include "traverse.glsl"
#include "shade.glsl"

// The mesh record of a hit.
uint hit_mesh(TraceHit h) {
    InstanceRecord inst = push.instances.r[push.tlases.r[h.tlas].instance_base + h.instance];
    return push.geometries.r[push.blases.r[inst.blas].item_base + h.geometry].mesh;
}

// The hit's primitive as hit records name it: a cluster of a partitioned mesh maps its own
// triangle to the source mesh's through its primitive map, which follows its indices in the
// mesh buffer (motu-gpu's MeshGpu).
uint source_primitive(MeshRecord m, uint mesh_record, uint primitive) {
    if ((m.flags & FLAG_PRIMITIVE_MAP) == 0u) {
        return primitive;
    }
    uint64_t map = push.mesh_geo.r[mesh_record].indices + 12ul * uint64_t(m.triangle_count);
    return U32Table(map).r[primitive];
}

// A pixel's state (176 bytes): carried across streaming passes (zeroed at the frame's start),
// a local in the full build, which runs the same steps without ever deferring. Per sample: the
// primary ray's best hit so far, resolved for shading while its BLAS was resident (so the BLAS
// may go), then its secondary rays (lights, then AO) in windows (shade.glsl
// SECONDARY_WINDOW): each ray of a window traced again in later passes while a structure it has
// not walked may hold an occluder, the window's terms added in ray order once all are done.
// With `--bounces N` each vertex's secondary rays are followed by its bounce ray (state 4), a
// closest-hit ray deferred like the primary ray while an open structure lies in front of its
// best hit, whose final hit is the next vertex (hit, rec, ns, albedo then describe it).
struct Carry {
    vec4 hit;     // current sample: x best t (T_INFINITY: none), yzw geometric normal facing the ray
    vec4 ns;      // xyz shading normal (same side); w the secondary window's masks (exact float)
    vec4 albedo;  // xyz textured base colour; w (streamed, states 3 and 6): the speculative window's
                  // start stamp (uintBitsToFloat)
    uvec4 rec;    // current sample: source mesh, primitive, LOD level, material
    uvec4 aov;    // sample 0's AOV record (without the trace count)
    vec4 sum;     // xyz: colours of the finished samples
    vec4 cur;     // xyz: the current sample's colour so far; w: AO rays found open
    // x: 0 fresh, 1 primary open, 2 secondary rays open, 3 primary open with its secondary
    // rays traced ahead from its best hit so far (streamed: see SPECULATIVE below); y: stamp of
    // the pass the open ray (or window; state 3: the primary) started in; z: traces; w: sample |
    // the window's first secondary ray << 16; 4 (bounces): the bounce ray open, its best hit so
    // far in hit/rec/ns/albedo; 5: the sample's path ended; 6 (streamed): as 4, with its
    // vertex's secondary rays traced ahead from that best hit (albedo.w: their window's start
    // stamp, as 3)
    uvec4 st;
#ifdef MOTU_STREAMED
    // Streamed only (full builds keep the path in locals, their SPIR-V unchanged):
    vec4 path_org;  // xyz: the current vertex's incoming ray's origin; w: the vertex (exact float)
    vec4 path_dir;  // xyz: its direction; w: the LOD of the vertex the bounce ray left (bits)
    vec4 thru;      // xyz: the path's throughput; w: no pixel's (CARRY_OPEN_BOUND_WORD)
#endif
};
layout(buffer_reference, std430, buffer_reference_align = 16) buffer CarryTable { Carry r[]; };

#ifdef MOTU_STREAMED
// A pixel's carried state, read and written field by field without thru.w: the word
// CARRY_OPEN_BOUND_WORD of common.glsl, which another launch item may be writing as its open
// bound (pipeline/open_bound.glsl). Full builds keep whole-struct copies (their SPIR-V as it was).
Carry carry_load(uint pixel) {
    CarryTable t = CarryTable(StreamRef(push.stream).s.carry);
    Carry c;
    c.hit = t.r[pixel].hit;
    c.ns = t.r[pixel].ns;
    c.albedo = t.r[pixel].albedo;
    c.rec = t.r[pixel].rec;
    c.aov = t.r[pixel].aov;
    c.sum = t.r[pixel].sum;
    c.cur = t.r[pixel].cur;
    c.st = t.r[pixel].st;
    c.path_org = t.r[pixel].path_org;
    c.path_dir = t.r[pixel].path_dir;
    c.thru = vec4(t.r[pixel].thru.x, t.r[pixel].thru.y, t.r[pixel].thru.z, 0.0);
    return c;
}

void carry_store(uint pixel, Carry c) {
    CarryTable t = CarryTable(StreamRef(push.stream).s.carry);
    t.r[pixel].hit = c.hit;
    t.r[pixel].ns = c.ns;
    t.r[pixel].albedo = c.albedo;
    t.r[pixel].rec = c.rec;
    t.r[pixel].aov = c.aov;
    t.r[pixel].sum = c.sum;
    t.r[pixel].cur = c.cur;
    t.r[pixel].st = c.st;
    t.r[pixel].path_org = c.path_org;
    t.r[pixel].path_dir = c.path_dir;
    t.r[pixel].thru.x = c.thru.x;  // component stores: thru.w is not this pixel's
    t.r[pixel].thru.y = c.thru.y;
    t.r[pixel].thru.z = c.thru.z;
}
#endif

// Streaming fallback (`--stream-fallback coarse`, motu-gpu stream/budget.rs): what an open
// pixel shows if its frame stops before its structures arrive. Primary ray open: the bounds of
// its nearest open BLAS (entry distance, LOD AOV_LOD_FALLBACK, hatched); shadow ray open: its
// final hit lit as if unshadowed. Written on every deferral (later passes overwrite it); the
// host keeps it only when fallback is on, else the pixel is unfinished.
void stream_write_fallback(uvec2 px, uint pixel, Carry c) {
    FrameParams f = push.frame.f;
    vec3 dir = camera_primary_dir(f.camera, px.x, px.y, 0.5, 0.5);
    bool hatch = ((px.x + px.y) & 4u) != 0u;
    uvec4 rec;
    vec3 colour;
#ifdef MOTU_STREAMED
    if ((c.st.x == 1u || c.st.x == 3u) && (c.st.w & 0xffffu) == 0u) {  // 3: rays ahead
#else
    if (c.st.x == 1u && (c.st.w & 0xffffu) == 0u) {
#endif
        uint mesh = push.geometries.r[push.blases.r[g_empty_id].item_base].mesh;
        MeshRecord m = push.meshes.r[mesh];
        rec = uvec4(m.source_mesh, NONE_U32, floatBitsToUint(g_empty_t), AOV_LOD_FALLBACK);
        if (f.view == VIEW_LOD) {
            colour = hatch ? vec3(1.0, 0.1, 0.55) : vec3(0.12);
        } else {
            colour = f.view == VIEW_IDS
                         ? id_colour(m.source_mesh, NONE_U32)
                         : push.materials.r[m.material].base_color *
                               (f.ambient + 0.5 * f.sun_dir_intensity.w);
            colour *= hatch ? 0.6 : 1.0;
        }
    } else {
        // Sample 0's record (final once its secondary rays or later samples run); colour: the
        // samples finished so far, else the current hit lit as if unshadowed.
        rec = c.aov;
        uint smp = c.st.w & 0xffffu;
        vec3 n = dot(c.hit.yzw, dir) > 0.0 ? -c.hit.yzw : c.hit.yzw;
        float ndl = max(dot(n, f.sun_dir_intensity.xyz), 0.0);
        if (f.view == VIEW_IDS) {
            colour = rec.x == AOV_MISS ? sky(dir) : id_colour(rec.x, rec.y);
        } else if (f.view == VIEW_LOD) {
            colour = rec.x == AOV_MISS ? sky(dir) : lod_colour(rec.w);
#ifdef MOTU_STREAMED
        } else if (c.st.x >= 4u || c.path_org.w > 0.0) {
            colour = c.sum.xyz / float(smp + 1u);  // a path's light so far (bounces)
#endif
        } else if (smp > 0u) {
            colour = c.sum.xyz / float(smp);
        } else if (rec.x == AOV_MISS) {
            colour = shaded_background(dir);
        } else {
            colour = c.albedo.xyz * (f.ambient + f.sun_dir_intensity.w * ndl);
        }
    }
    rec.w |= min(c.st.z, 65535u) << 16u;
    push.aov.r[pixel] = rec;
    push.rgba.r[pixel] = f.view == VIEW_SHADED ? tone_map(colour, f.exposure_scale)
                                              : encode_srgb8(colour);
}

// Puts pixel `px` on the pass's incomplete list (packed x | y << 16); streamed, with the
// structure it waits for (`blocker`, NONE_U32: none named) in the list's second half.
#ifdef MOTU_STREAMED
void stream_list_incomplete(uvec2 px, uint blocker) {
#else
void stream_list_incomplete(uvec2 px) {
#endif
    IncompleteList l = IncompleteList(StreamRef(push.stream).s.incomplete);
    uint k = atomicAdd(l.count, 1u);
    l.r[k] = px.x | (px.y << 16u);
#ifdef MOTU_STREAMED
    CameraParams cam = push.frame.f.camera;
    l.r[cam.width * cam.height + k] = blocker;
#endif
}

// Streaming: an open pixel keeps its state and goes on the next pass's list; it writes only its
// fallback. Streamed, a pixel whose closest-hit ray (primary, state 1 or 3; bounce, state 4)
// is open names that ray's nearest open structure: until it is resident the ray stays open
// (whatever else is built lies behind that structure's entry, so no hit of it can close the
// ray), so a frame's last pass leaves the pixel as it is (motu-gpu stream/passes.rs). A pixel
// waiting on secondary rays only names none (an occluder built behind a ray's nearest open
// structure may finish it).
void stream_defer(uvec2 px, uint pixel, Carry c) {
    stream_write_fallback(px, pixel, c);
#ifdef MOTU_STREAMED
    carry_store(pixel, c);
#else
    CarryTable(StreamRef(push.stream).s.carry).r[pixel] = c;
#endif
#ifdef MOTU_STREAMED
    bool closest = c.st.x == 1u || c.st.x == 3u || c.st.x == 4u || c.st.x == 6u;
    stream_list_incomplete(px, closest ? g_empty_id : NONE_U32);
#else
    stream_list_incomplete(px);
#endif
}

#ifdef MOTU_STREAMED
// Adds this invocation's walks to the pass's counters: `walks` TLAS walks of its rays' walks,
// and its mark walks (STAT_TLAS_WALKS, STAT_MARK_WALKS, STAT_MARK_TLAS_WALKS).
void stream_count_walks(uint walks) {
    if (walks != 0u) {
        atomicAdd(push.stats.n[STAT_TLAS_WALKS], walks);
    }
    if (g_mark_walks != 0u) {
        atomicAdd(push.stats.n[STAT_MARK_WALKS], g_mark_walks);
        atomicAdd(push.stats.n[STAT_MARK_TLAS_WALKS], g_mark_tlas_walks);
    }
#ifdef MOTU_COUNT_MEMBER_TESTS
    if (g_member_tests != 0u) {
        atomicAdd(push.stats.n[STAT_PROXY_MEMBER_TESTS], g_member_tests);
        atomicAdd(push.stats.n[STAT_PROXY_EXACT_TESTS], g_exact_tests);
    }
#endif
}

// The secondary rays traced ahead from an open ray's best hit so far (SPECULATIVE): an open
// ray in state `open_state` (1: primary, 4: bounce) starts them in state `ahead` (3, 6), from
// `emission`, their window starting in this pass; true while any is left to trace.
bool trace_ahead(inout Carry c, uint open_state, uint ahead, vec3 emission, uint smp) {
    if (c.st.x == open_state) {
        c.cur = vec4(emission, 0.0);
        c.ns.w = 0.0;
        c.albedo.w = uintBitsToFloat(g_stamp);
        c.st.x = ahead;
        c.st.w = smp;
    }
    return (c.st.w >> 16u) < secondary_ray_count();
}
#endif

// The frame's sample `smp` in the pixel's sequence (a progressive frame starts at
// `first_sample`): what the random numbers are drawn with; `smp` itself counts the frame's
// samples.
uint seq_sample(uint smp) {
    return smp + push.frame.f.first_sample;
}

// Primary ray of sample `smp`: the pixel centre for the sequence's sample 0 (it gives the AOV
// record), jittered after.
vec3 sample_dir(uvec2 px, uint pixel, uint smp) {
    CameraParams cam = push.frame.f.camera;
    uint g = seq_sample(smp);
    if (g == 0u) {
        return camera_primary_dir(cam, px.x, px.y, 0.5, 0.5);
    }
    return camera_primary_dir(cam, px.x, px.y, rand01(pixel, g, 0u), rand01(pixel, g, 1u));
}

// The pixel's rays in order (each sample's primary ray, then its secondary rays), traced through
// ONE traverse() call site: the traversal loop is inlined once per render path, and what stays
// live across its traceRayEXT is the Carry and a few words (issue 15: with a call site per ray
// kind and the shading state live across each, TLAS hops cost ~1.3x more on the H200). A
// guard-band probe (streaming) traces its primary ray along `guard_dir` and stops.
void render_pixel_impl(uvec2 px, bool guard, vec3 guard_dir) {
    uint width = push.frame.f.camera.width;
    if (!guard && (px.x >= width || px.y >= push.frame.f.camera.height)) {
        return;
    }
    uint pixel = px.y * width + px.x;
    vec3 org = push.frame.f.camera.world_eye;
    bool shaded = !guard && push.frame.f.view == VIEW_SHADED;
    // The albedo view resolves the primary hit's textured base colour as shading does.
    bool resolve = shaded || (!guard && push.frame.f.view == VIEW_ALBEDO);
    uint spp = shaded ? max(push.frame.f.spp, 1u) : 1u;
    uint traces = 0u;
    uint overflows = 0u;
    uint truncations = 0u;
    g_truncated = false;
    g_secondary_rays = 0u;
    Carry c;
    c.hit = vec4(T_INFINITY, 0.0, 0.0, 0.0);
    c.ns = vec4(0.0);
    c.albedo = vec4(0.0);
    c.rec = uvec4(0u);
    c.aov = uvec4(AOV_MISS, 0u, 0u, 0u);
    c.sum = vec4(0.0);
    c.cur = vec4(0.0);
    c.st = uvec4(1u, g_stamp, 0u, 0u);
#ifdef MOTU_STREAMED
    c.path_org = vec4(org, 0.0);
    c.path_dir = vec4(0.0);
    c.thru = vec4(1.0);
#endif
    if (g_streaming && !guard && !g_probe) {
#ifdef MOTU_STREAMED
        Carry old = carry_load(pixel);
#else
        Carry old = CarryTable(StreamRef(push.stream).s.carry).r[pixel];
#endif
        if (old.st.x != 0u) {
            c = old;
        }
        traces = c.st.z;
    }
#ifdef MOTU_STREAMED
    uint traces_before = traces;  // the carried count: this pass's walks are what it adds
#endif
    bool open = false;
    // Diffuse bounces (state 4 of Carry.st.x: the bounce ray is next, 5: the path ended): the
    // current vertex's incoming ray (p_org, p_dir; the camera ray at vertex 0), the vertex's
    // index and the path's throughput (streaming: kept in the Carry across passes, with the
    // LOD the bounce ray left from). A vertex's secondary rays draw their numbers from sample
    // smp | bounce << 20, so vertex 0 is the sample as without bounces.
#ifdef MOTU_STREAMED
    uint bounce = uint(c.path_org.w);
    vec3 p_org = c.path_org.xyz;
    vec3 p_dir = c.path_dir.xyz;
    vec3 thru = c.thru.xyz;
    uint bounce_lod = floatBitsToUint(c.path_dir.w);
#else
    uint bounce = 0u;
    vec3 p_org = org;
    vec3 p_dir = vec3(0.0);
    vec3 thru = vec3(1.0);
#endif
#ifdef MOTU_STREAMED
    // This pass's next secondary ray to look at in the current window (rays before it were
    // traced or settled in this pass).
    uint cursor = 0u;
    // SPECULATIVE secondary rays (state 3): a primary ray left open (a structure it has not
    // walked lies in front of its best hit) most often keeps that hit, so its secondary rays are
    // traced from it now, against what is resident now, instead of a pass after the primary ray
    // is final (when what they need may have been evicted for the primary's structure: one
    // more pass a frame whenever a frame's rays need more than the room). They are traced in
    // every pass the pixel is open, after its primary ray, so they walk everything resident
    // since their window started, as any deferred ray does; a closer primary hit drops them.
    // `spec`: this invocation's primary ray stayed open and the window's rays come next.
    bool spec = false;
    uint primary_empty_id = 0u;  // the primary ray's nearest open structure (fallback)
    float primary_empty_t = T_INFINITY;
#endif
    while (true) {
        uint smp = c.st.w & 0xffffu;
        vec3 dir = guard ? guard_dir : sample_dir(px, pixel, smp);
#ifdef MOTU_STREAMED
        bool primary = (c.st.x == 1u || c.st.x == 3u) && !spec;
#else
        bool primary = c.st.x == 1u;
#endif
        bool bouncing = false;
        ShadeInput si;
        si.ng = c.hit.yzw;
        si.ns = c.ns.xyz;
        si.albedo = c.albedo.xyz;
#ifdef MOTU_STREAMED
        uint first = c.st.w >> 16u;  // the current window's first secondary ray
        // The current vertex's incoming ray and random-number sample (as in full builds).
        vec3 v_org = bounce > 0u ? p_org : org;
        vec3 v_dir = bounce > 0u ? p_dir : dir;
        uint v_smp = seq_sample(smp) | (bounce << 20u);
        // State 6: the bounce ray open with its vertex's secondary rays traced ahead (as 3).
        bouncing = (c.st.x == 4u || c.st.x == 6u) && !spec;
        // The ray to trace: origin, direction, reach (w).
        vec3 r_org = org;
        vec4 r_dir = vec4(dir, T_INFINITY);
        bool sample_done = c.st.x == 5u;
        uint ray_bit = 0u;
        if (primary) {
            g_best_t = c.hit.x;
        } else if (bouncing) {
            // The bounce ray, against its best hit so far (none when it started).
            r_org = p_org;
            r_dir = vec4(p_dir, T_INFINITY);
            g_best_t = c.hit.x;
        } else if (!sample_done) {
            // The window's masks: done (bits 0-7), clear (bits 8-15).
            uint masks = uint(c.ns.w);
            uint n = secondary_ray_count();
            uint end = min(first + SECONDARY_WINDOW, n);
            bool found = false;
            for (uint k = max(cursor, first); k < end; ++k) {
                uint bit = 1u << (k - first);
                if ((masks & bit) != 0u) {
                    continue;
                }
                bool clear;
                vec3 term;
                if (secondary_ray(si, c.rec.w, v_org, v_dir, c.hit.x, pixel, v_smp, k, r_dir, clear,
                                  term)) {
                    found = true;
                    cursor = k;
                    ray_bit = bit;
                    break;
                }
                masks |= bit | (clear ? bit << 8u : 0u);
            }
            c.ns.w = float(masks);
            if (found) {
                r_org = secondary_start(v_org, v_dir, c.hit.x, si.ng);
            } else if ((masks & 0xffu) != (1u << (end - first)) - 1u) {
                open = true;  // some ray of the window is still open: traced again next pass
                break;
            } else {
                vec3 colour = c.cur.xyz;
                uint ao_open = uint(c.cur.w);
                secondary_window_done(first, masks >> 8u, si, c.rec.w, v_org, v_dir, c.hit.x, pixel,
                                      v_smp, colour, ao_open);
                c.cur = vec4(colour, float(ao_open));
                c.ns.w = 0.0;
                cursor = 0u;
                if (end < n) {
                    // The next window starts now.
                    if (spec) {
                        c.albedo.w = uintBitsToFloat(g_stamp);
                        c.st.w = smp | (end << 16u);
                    } else {
                        c.st.yw = uvec2(g_stamp, smp | (end << 16u));
                    }
                    continue;
                }
                if (spec) {
                    // Every window done ahead: the sample ends once its primary hit is final
                    // (an empty window at `n` then adds its terms, below).
                    c.st.w = smp | (n << 16u);
                    open = true;
                    break;
                }
                c.sum.xyz += thru * (c.cur.xyz + sky_term(si, c.rec.w, uint(c.cur.w)));
                vec3 bounce_dir;
                vec3 weight;
                if (bounce < push.frame.f.bounces &&
                    bounce_ray(si, c.rec.w, pixel, seq_sample(smp) | ((bounce + 1u) << 20u), bounce_dir,
                               weight)) {
                    // The path goes on: its bounce ray starts now, with no hit yet.
                    p_org = secondary_start(v_org, v_dir, c.hit.x, si.ng);
                    p_dir = bounce_dir;
                    thru *= weight;
                    bounce += 1u;
                    bounce_lod = c.rec.z;
                    c.hit.x = T_INFINITY;
                    c.st.xy = uvec2(4u, g_stamp);
                    continue;
                }
                sample_done = true;
            }
            g_best_t = T_INFINITY;
        }
#else
        uint ray = c.st.w >> 16u;
        // The current vertex's incoming ray and random-number sample.
        vec3 v_org = bounce > 0u ? p_org : org;
        vec3 v_dir = bounce > 0u ? p_dir : dir;
        uint v_smp = seq_sample(smp) | (bounce << 20u);
        bouncing = c.st.x == 4u;
        // The ray to trace: origin, direction, reach (w).
        vec3 r_org = org;
        vec4 r_dir = vec4(dir, T_INFINITY);
        bool sample_done = c.st.x == 5u;
        if (primary) {
            g_best_t = c.hit.x;
        } else if (bouncing) {
            r_org = p_org;
            r_dir = vec4(p_dir, T_INFINITY);
            g_best_t = T_INFINITY;
        } else if (!sample_done) {
            vec3 colour = c.cur.xyz;
            if (next_secondary_ray(si, c.rec.w, v_org, v_dir, c.hit.x, pixel, v_smp, ray, colour,
                                   r_dir)) {
                r_org = secondary_start(v_org, v_dir, c.hit.x, si.ng);
                c.st.w = smp | (ray << 16u);
            } else {
                c.sum.xyz += thru * (colour + sky_term(si, c.rec.w, uint(c.cur.w)));
                vec3 bounce_dir;
                vec3 weight;
                if (bounce < push.frame.f.bounces &&
                    bounce_ray(si, c.rec.w, pixel, seq_sample(smp) | ((bounce + 1u) << 20u), bounce_dir,
                               weight)) {
                    // The path goes on: its bounce ray is traced next.
                    p_org = secondary_start(v_org, v_dir, c.hit.x, si.ng);
                    p_dir = bounce_dir;
                    thru *= weight;
                    bounce += 1u;
                    c.st.x = 4u;
                    continue;
                }
                sample_done = true;
            }
            c.cur.xyz = colour;
            g_best_t = T_INFINITY;
        }
#endif
        if (!sample_done) {
            g_start = c.st.y;
#ifdef MOTU_STREAMED
            if (spec) {
                g_start = floatBitsToUint(c.albedo.w);
            }
#endif
            g_empty_t = T_INFINITY;
            g_t_max = r_dir.w;
            LodParams lodp = push.frame.f.lod;
            if (!primary && push.frame.f.shadow_lod_from_primary != 0u) {
#ifdef MOTU_STREAMED
                // A bounce ray's best hit so far is in c.rec: it leaves from bounce_lod's vertex.
                lodp.forced_lod = int(bouncing ? bounce_lod : c.rec.z);
#else
                lodp.forced_lod = int(c.rec.z);
#endif
            }
            float lod_u = primary ? (guard ? 0.5 : pixel_dither(px.x, px.y)) : 0.0;
            g_hit_kind = guard     ? STREAM_HIT_GUARD
                         : primary ? STREAM_HIT_CAMERA
                         : bouncing ? STREAM_HIT_BOUNCE
                                    : STREAM_HIT_OCCLUSION;
#ifdef MOTU_STREAMED
            if (COUNT_PROXY != 0u) {
                g_count_kind = guard      ? PROXY_KIND_GUARD
                               : primary  ? PROXY_KIND_CAMERA
                               : bouncing ? PROXY_KIND_BOUNCE
                               : cursor < min(push.frame.f.light_count, uint(MAX_LIGHTS))
                                   ? PROXY_KIND_SHADOW
                                   : PROXY_KIND_AO;
            }
#endif
            TraceHit h = traverse(push.frame.f.root_tlas, r_org, r_dir.xyz,
                                  primary ? RAY_PRIMARY : RAY_SHADOW, lodp,
                                  push.frame.f.camera.pixels_per_unit_at_1, lod_u,
                                  !primary && !bouncing, traces, overflows, truncations);
            g_t_max = T_INFINITY;
            // A cut-short walk (stack overflow, trace cap) cannot finish in a later pass either:
            // the pixel ends here and is counted as truncated.
            bool cut = g_truncated || overflows != 0u;
            if (guard) {
#ifdef MOTU_STREAMED
                stream_count_walks(traces - traces_before);
#endif
                return;  // a probe marks what it passed, nothing else
            }
#ifdef MOTU_STREAMED
            if (bouncing) {
                g_secondary_rays += 1u;
                if (h.tlas != NONE_U32) {
                    // A closer hit: resolved now, while its BLAS and meshes are resident.
                    uint mesh = hit_mesh(h);
                    MeshRecord m = push.meshes.r[mesh];
                    c.hit.x = h.t;
                    c.rec = uvec4(m.source_mesh, source_primitive(m, mesh, h.primitive),
                                  h.lod == NONE_U32 ? m.lod : h.lod, m.material);
                    ShadeInput hs = shade_input(h, mesh, p_org, p_dir);
                    c.hit.yzw = hs.ng;
                    c.ns.xyz = hs.ns;
                    c.albedo.xyz = hs.albedo;
                    if (c.st.x == 6u) {
                        c.st.x = 4u;  // a closer hit: the rays traced ahead from the old one go
                    }
                }
                g_probe_link_open = false;
                if (!cut && stream_still_open(c.hit.x)) {
                    // As a primary ray's (SPECULATIVE): the next vertex's secondary rays are
                    // traced ahead from the bounce's best hit so far, against what is resident
                    // now, instead of a pass after the bounce is final (what they need may be
                    // evicted by then for the bounce's structure: in-frame returns).
                    if (c.hit.x < T_INFINITY && !g_last_pass && !g_probe) {
                        primary_empty_id = g_empty_id;
                        primary_empty_t = g_empty_t;
                        if (trace_ahead(c, 4u, 6u, vec3(0.0), smp)) {
                            spec = true;
                            continue;
                        }
                    }
                    open = true;  // the next vertex waits until the bounce's hit is final
                    break;
                }
                if (g_probe_stop && g_probe_link_open) {
                    break;  // a probe: the path goes on in the next round (STREAM_PROBE_STOP)
                }
                if (c.hit.x >= T_INFINITY) {
                    c.st.x = 5u;  // escaped: the path ends (see the full build's branch)
                    continue;
                }
                if (c.st.x == 6u) {
                    // Final, the hit they were traced ahead from: the secondary rays go on
                    // from where they are, from their window's start.
                    c.st.xy = uvec2(2u, floatBitsToUint(c.albedo.w));
                    continue;
                }
                // Final: the next vertex's secondary rays start now, from their first window.
                c.cur = vec4(0.0);
                c.ns.w = 0.0;
                c.st.xyw = uvec3(2u, g_stamp, smp);
                continue;
            }
            if (!primary) {
                g_secondary_rays += 1u;
                uint masks = uint(c.ns.w);
                if (h.t < r_dir.w) {
                    masks |= ray_bit;  // occluded: final whatever the open structures hold
                } else if (cut || !stream_still_open(r_dir.w)) {
                    masks |= ray_bit | (ray_bit << 8u);  // clear
                }
                // Else open: traced again next pass from the window's start stamp, while the
                // window's other rays go on now.
                c.ns.w = float(masks);
                cursor += 1u;
                continue;
            }
#else
            if (bouncing) {
                g_secondary_rays += 1u;
                if (h.tlas == NONE_U32) {
                    // Escaped: the environment's light reached every vertex through its
                    // sampled rays, so the path ends without adding it again.
                    c.st.x = 5u;
                    continue;
                }
                // The bounce's hit is the next vertex: resolved, then its secondary rays.
                uint mesh = hit_mesh(h);
                MeshRecord m = push.meshes.r[mesh];
                c.hit.x = h.t;
                c.rec = uvec4(m.source_mesh, source_primitive(m, mesh, h.primitive),
                              h.lod == NONE_U32 ? m.lod : h.lod, m.material);
                ShadeInput hs = shade_input(h, mesh, p_org, p_dir);
                c.hit.yzw = hs.ng;
                c.ns.xyz = hs.ns;
                c.albedo.xyz = hs.albedo;
                c.cur = vec4(0.0);
                c.st.xw = uvec2(2u, smp);
                continue;
            }
            if (!primary) {
                g_secondary_rays += 1u;
                uint outcome = RAY_CLEAR;
                if (h.t < r_dir.w) {
                    outcome = RAY_OCCLUDED;  // final whatever the open structures hold
                } else if (!cut && stream_still_open(r_dir.w)) {
                    open = true;  // traced again next pass, from its start stamp
                    break;
                }
                vec3 colour = c.cur.xyz;
                uint ao_open = uint(c.cur.w);
                secondary_ray_done(outcome, ray, si, c.rec.w, v_org, v_dir, c.hit.x, pixel, v_smp,
                                   colour, ao_open);
                c.cur = vec4(colour, float(ao_open));
                c.st.yw = uvec2(g_stamp, smp | ((ray + 1u) << 16u));
                continue;
            }
#endif
            if (h.tlas != NONE_U32) {
                // Resolved now, while its BLAS and meshes are resident.
                uint mesh = hit_mesh(h);
                MeshRecord m = push.meshes.r[mesh];
                c.hit.x = h.t;
                c.rec = uvec4(m.source_mesh, source_primitive(m, mesh, h.primitive),
                              h.lod == NONE_U32 ? m.lod : h.lod, m.material);
#ifdef MOTU_STREAMED
                if (c.st.x == 3u) {
                    c.st.x = 1u;  // a closer hit: the rays traced ahead from the old one go
                }
#endif
                if (resolve) {
                    ShadeInput hs = shade_input(h, mesh, org, dir);
                    c.hit.yzw = hs.ng;
                    c.ns.xyz = hs.ns;
                    c.albedo.xyz = hs.albedo;
                }
            }
#ifdef MOTU_STREAMED
            g_probe_link_open = false;
#endif
            if (!cut && stream_still_open(c.hit.x)) {
#ifdef MOTU_STREAMED
                if (shaded && c.hit.x < T_INFINITY) {
                    primary_empty_id = g_empty_id;
                    primary_empty_t = g_empty_t;
                }
                // Not in the frame's last pass: the pixel stays open whatever they find.
                if (shaded && c.hit.x < T_INFINITY && !g_last_pass) {
                    // Trace the secondary rays ahead from this hit, starting now.
                    vec3 emission = push.materials.r[c.rec.w].emission;
                    if (trace_ahead(c, 1u, 3u, emission, smp)) {
                        spec = true;
                        continue;
                    }
                }
#endif
                open = true;  // shading waits until the primary hit is final
                break;
            }
#ifdef MOTU_STREAMED
            if (g_probe_stop && g_probe_link_open) {
                break;  // a probe: the path goes on in the next round (STREAM_PROBE_STOP)
            }
#endif
            if (smp == 0u && c.hit.x < T_INFINITY) {
                c.aov = uvec4(c.rec.x, c.rec.y, floatBitsToUint(c.hit.x), min(c.rec.z, 255u));
            }
            if (!shaded) {
                break;
            }
#ifdef MOTU_STREAMED
            if (c.st.x == 3u) {
                // Final, the hit it was traced ahead from: its secondary rays go on from where
                // they are, from their window's start.
                c.st.xy = uvec2(2u, floatBitsToUint(c.albedo.w));
                continue;
            }
#endif
            if (c.hit.x < T_INFINITY) {
                // The sample's secondary rays come next.
                c.cur = vec4(push.materials.r[c.rec.w].emission, 0.0);
#ifdef MOTU_STREAMED
                c.ns.w = 0.0;  // the first window's masks
#endif
                c.st.xyw = uvec3(2u, g_stamp, smp);
                continue;
            }
            c.sum.xyz += shaded_background(dir);
        }
        if (smp + 1u >= spp) {
            break;
        }
        // The next sample's primary ray starts now.
        c.hit = vec4(T_INFINITY, 0.0, 0.0, 0.0);
        c.st.xyw = uvec3(1u, g_stamp, smp + 1u);
        bounce = 0u;
        thru = vec3(1.0);
    }
#ifdef MOTU_STREAMED
    stream_count_walks(traces - traces_before);
#endif
    if (g_probe) {
        // A probe of the next frame marks what its rays met; a pixel that needs a structure
        // not resident is listed for the next probe round (after the prefetch built it).
        if (g_probe_open && !guard) {
#ifdef MOTU_STREAMED
            stream_list_incomplete(px, NONE_U32);
#else
            stream_list_incomplete(px);
#endif
        }
        return;
    }
    if (g_secondary_rays != 0u) {
        atomicAdd(push.stats.n[STAT_SHADOW_RAYS], g_secondary_rays);
    }
    if (open) {
        c.st.z = traces;
#ifdef MOTU_STREAMED
        c.path_org = vec4(p_org, float(bounce));
        c.path_dir = vec4(p_dir, uintBitsToFloat(bounce_lod));
        c.thru = vec4(thru, 0.0);
        if (c.st.x == 3u || c.st.x == 6u) {
            g_empty_id = primary_empty_id;  // the fallback and blocker: the closest-hit ray's
            g_empty_t = primary_empty_t;
        }
#endif
        stream_defer(px, pixel, c);
        return;
    }
    vec3 colour;
    uvec4 rec = c.aov;
    if (shaded) {
        colour = spp > 1u ? c.sum.xyz / float(spp) : c.sum.xyz;
    } else if (rec.x == AOV_MISS) {
        colour = sky(camera_primary_dir(push.frame.f.camera, px.x, px.y, 0.5, 0.5));
    } else if (push.frame.f.view == VIEW_IDS) {
        colour = id_colour(rec.x, rec.y);
    } else if (push.frame.f.view == VIEW_ALBEDO) {
        colour = c.albedo.xyz;
    } else {
        colour = lod_colour(rec.w);
    }
    rec.w |= min(traces, 65535u) << 16u;
    push.aov.r[pixel] = rec;
    push.rgba.r[pixel] = shaded ? tone_map(colour, push.frame.f.exposure_scale) : encode_srgb8(colour);
    if (overflows != 0u) {
        atomicAdd(push.stats.n[STAT_STACK_OVERFLOWS], overflows);
    }
    if (truncations != 0u) {
        atomicAdd(push.stats.n[STAT_PI_LIST_OVERFLOWS], truncations);
    }
    if (overflows != 0u || g_truncated) {
        atomicAdd(push.stats.n[STAT_TRUNCATED_RAYS], 1u);
    }
}
// The full-build entry: g_streaming is the constant false here, so the drivers fold the
// streaming code out of this inlined copy of the traversal loop (one copy shared with the
// streaming entry, branching on push.stream, was 8% slower on the H200; BENCHMARKS.md).
void render_pixel(uvec2 px) {
    g_streaming = false;
    g_guard = false;
    g_probe = false;
    g_probe_pass_marks = false;
    render_pixel_impl(px, false, vec3(0.0));
}

// Streaming work item `i` of a pass: an image pixel (written unless incomplete) or a
// guard-band pixel outside the image (primary ray only: it marks what the camera is about to
// see, for prefetching, and writes nothing). In a probe pass (STREAM_PROBE_PASS, the next
// frame's camera) each pixel's rays all run against what is resident and only mark.
void render_stream_item(uint i) {
    StreamParams s = StreamRef(push.stream).s;
    if (i >= s.full_count + s.list_count) {
        return;
    }
    CameraParams c = push.frame.f.camera;
    int x;
    int y;
    if (i < s.full_count) {
        x = int(i % c.width);
        y = int(i / c.width);
    } else {
        uint v = U32Table(s.pixel_list).r[i - s.full_count];
        x = int(v & 0xffffu) - GUARD_BIAS;
        y = int(v >> 16u) - GUARD_BIAS;
    }
    bool guard = x < 0 || y < 0 || x >= int(c.width) || y >= int(c.height);
    g_streaming = true;
    g_guard = guard;
    g_probe = (s.flags & STREAM_PROBE_PASS) != 0u;
    uint pass_rows = s.flags >> STREAM_PASS_ROWS_SHIFT;
    g_probe_pass_marks = g_probe && !guard && pass_rows != 0u && uint(y) % pass_rows == 0u;
    g_probe_open = false;
    g_probe_stop = g_probe && (s.flags & STREAM_PROBE_STOP) != 0u;
#ifdef MOTU_STREAMED
    g_last_pass = (s.flags & STREAM_LAST_PASS) != 0u;
    g_no_mark_walk = (s.flags & STREAM_NO_MARK_WALK) != 0u;
    g_mark_walks = 0u;
    g_mark_tlas_walks = 0u;
    // Every first walk tests triangles and proxies; what the rays pass (the marks BLASes
    // included) is marked by the mark walk that follows it (traverse.glsl).
    g_cull_mask = CULL_MASK_WALK;
#else
    g_cull_mask = g_probe ? CULL_MASK_PROBE : CULL_MASK_WALK;
#endif
    g_stamp = s.stamp;
    g_best_t = T_INFINITY;
    g_start = s.stamp;
    g_empty_t = T_INFINITY;
    vec3 guard_dir = vec3(0.0);
    if (guard) {
        guard_dir = normalize(c.world_dir00 + c.world_du * (float(x) + 0.5) +
                              c.world_dv * (float(y) + 0.5));
    }
    render_pixel_impl(uvec2(x, y), guard, guard_dir);
}
#endif
