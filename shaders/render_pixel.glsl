// One pixel: primary ray, optional shadow ray, AOV record and colour. Shared by both backends
// (included after traverse.glsl).
#ifndef MOTU_RENDER_PIXEL_GLSL
#define MOTU_RENDER_PIXEL_GLSL
#include "camera.glsl"
#include "traverse.glsl"
#include "shade.glsl"

// Resolved hit: mesh record and world geometric normal (not face-forwarded).
struct Surface {
    uint mesh_record;
    vec3 world_normal;
};

Surface resolve(TraceHit h) {
    InstanceRecord inst = push.instances.r[push.tlases.r[h.tlas].instance_base + h.instance];
    uint mesh = push.geometries.r[push.blases.r[inst.blas].item_base + h.geometry].mesh;
    Surface s;
    s.mesh_record = mesh;
    MeshGeo g = push.mesh_geo.r[mesh];
    U32Table idx = U32Table(g.indices);
    Positions pos = Positions(g.positions);
    uint i0 = idx.r[3u * h.primitive];
    uint i1 = idx.r[3u * h.primitive + 1u];
    uint i2 = idx.r[3u * h.primitive + 2u];
    vec3 v0 = vec3(pos.v[3u * i0], pos.v[3u * i0 + 1u], pos.v[3u * i0 + 2u]);
    vec3 v1 = vec3(pos.v[3u * i1], pos.v[3u * i1 + 1u], pos.v[3u * i1 + 2u]);
    vec3 v2 = vec3(pos.v[3u * i2], pos.v[3u * i2 + 1u], pos.v[3u * i2 + 2u]);
    vec3 n_object = cross(v1 - v0, v2 - v0);
    Affine object_from_world =
        compose(affine_inverse(affine_from_array(inst.tlas_from_blas)), h.tlas_from_world);
    s.world_normal = normalize(transpose_vector(object_from_world, n_object));
    return s;
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

// A pixel's state carried across streaming passes (48 bytes; zeroed at the frame's start): the
// primary ray's best hit resolved while its BLAS was resident (so the BLAS may go), and which
// ray is open since which pass.
struct Carry {
    vec4 hit;   // x: best t (T_INFINITY: none), yzw: world geometric normal
    uvec4 rec;  // source mesh, primitive, LOD level, material
    uvec4 st;   // x: 0 fresh, 1 primary open, 2 shadow open; y: stamp its ray started; z: traces
};
layout(buffer_reference, std430, buffer_reference_align = 16) buffer CarryTable { Carry r[]; };

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
    if (c.st.x == 1u) {
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
        rec = uvec4(c.rec.x, c.rec.y, floatBitsToUint(c.hit.x), min(c.rec.z, 255u));
        vec3 n = dot(c.hit.yzw, dir) > 0.0 ? -c.hit.yzw : c.hit.yzw;
        float ndl = max(dot(n, f.sun_dir_intensity.xyz), 0.0);
        colour = f.view == VIEW_IDS   ? id_colour(c.rec.x, c.rec.y)
                 : f.view == VIEW_LOD ? lod_colour(c.rec.z)
                                      : push.materials.r[c.rec.w].base_color *
                                            (f.ambient + f.sun_dir_intensity.w * ndl);
    }
    rec.w |= min(c.st.z, 65535u) << 16u;
    push.aov.r[pixel] = rec;
    push.rgba.r[pixel] = encode_srgb8(colour);
}

// Streaming: an open pixel keeps its state and goes on the next pass's list; it writes only its
// fallback.
void stream_defer(uvec2 px, uint pixel, Carry c) {
    stream_write_fallback(px, pixel, c);
    StreamParams s = StreamRef(push.stream).s;
    CarryTable(s.carry).r[pixel] = c;
    IncompleteList l = IncompleteList(s.incomplete);
    uint k = atomicAdd(l.count, 1u);
    l.r[k] = px.x | (px.y << 16u);
}

// Samples 1 .. spp - 1 of a shaded pixel (jittered primary rays; sample 0, the pixel centre,
// gave the hit record and `first`); streaming passes shade one sample (see shade.glsl).
vec3 shade_samples(vec3 first, uvec2 px, uint pixel, inout uint traces, inout uint overflows,
                   inout uint truncations) {
    FrameParams f = push.frame.f;
    if (f.spp <= 1u || g_streaming) {
        return first;
    }
    vec3 sum = first;
    for (uint smp = 1u; smp < f.spp; ++smp) {
        vec3 org = f.camera.world_eye;
        vec3 dir = camera_primary_dir(f.camera, px.x, px.y, rand01(pixel, smp, 0u),
                                      rand01(pixel, smp, 1u));
        TraceHit h = traverse(f.root_tlas, org, dir, RAY_PRIMARY, f.lod,
                              f.camera.pixels_per_unit_at_1, pixel_dither(px.x, px.y), false,
                              traces, overflows, truncations);
        if (h.t < T_INFINITY) {
            Surface s = resolve(h);
            MeshRecord m = push.meshes.r[s.mesh_record];
            uint lod = h.lod == NONE_U32 ? m.lod : h.lod;
            sum += shade_hit(h, s.mesh_record, org, dir, pixel, smp, lod, traces, overflows,
                             truncations);
        } else {
            sum += shaded_background(dir);
        }
    }
    return sum / float(f.spp);
}

void render_pixel_impl(uvec2 px) {
    FrameParams f = push.frame.f;
    uint width = f.camera.width;
    if (px.x >= width || px.y >= f.camera.height) {
        return;
    }
    uint pixel = px.y * width + px.x;
    vec3 org = f.camera.world_eye;
    vec3 dir = camera_primary_dir(f.camera, px.x, px.y, 0.5, 0.5);
    uint traces = 0u;
    uint overflows = 0u;
    uint truncations = 0u;
    g_truncated = false;
    Carry c;
    c.hit = vec4(T_INFINITY, 0.0, 0.0, 0.0);
    c.rec = uvec4(0u);
    c.st = uvec4(1u, g_stamp, 0u, 0u);
    if (g_streaming) {
        Carry old = CarryTable(StreamRef(push.stream).s.carry).r[pixel];
        if (old.st.x != 0u) {
            c = old;
        }
        traces = c.st.z;
    }
    // The full build's primary hit, for the full shading model (streaming shades from the
    // carried record: its BLAS may be gone by the time the pixel is final).
    TraceHit h;
    h.t = T_INFINITY;
    uint h_mesh = NONE_U32;
    if (c.st.x == 1u) {
        g_best_t = c.hit.x;
        g_start = c.st.y;
        g_empty_t = T_INFINITY;
        h = traverse(f.root_tlas, org, dir, RAY_PRIMARY, f.lod,
                              f.camera.pixels_per_unit_at_1, pixel_dither(px.x, px.y), false,
                              traces, overflows, truncations);
        if (h.tlas != NONE_U32) {
            // Resolved now, while its BLAS and meshes are resident.
            Surface s = resolve(h);
            h_mesh = s.mesh_record;
            MeshRecord m = push.meshes.r[s.mesh_record];
            c.hit = vec4(h.t, s.world_normal);
            c.rec = uvec4(m.source_mesh, source_primitive(m, s.mesh_record, h.primitive),
                          h.lod == NONE_U32 ? m.lod : h.lod, m.material);
        }
        // A cut-short walk (stack overflow, trace cap) cannot finish in a later pass either:
        // the pixel ends here and is counted as truncated.
        bool cut = g_truncated || overflows != 0u;
        if (!cut && stream_still_open(c.hit.x)) {
            // Shading and shadow rays wait until the primary hit is final.
            c.st.z = traces;
            stream_defer(px, pixel, c);
            return;
        }
        c.st.xy = uvec2(2u, g_stamp);
    }
    vec3 colour;
    uvec4 rec = uvec4(AOV_MISS, 0u, 0u, 0u);
    if (c.hit.x < T_INFINITY) {
        uint lod = c.rec.z;
        rec.xyz = uvec3(c.rec.x, c.rec.y, floatBitsToUint(c.hit.x));
        rec.w = min(lod, 255u);
        if (f.view == VIEW_SHADED && !g_streaming) {
            // Materials, textures, shading normals, the scene's lights and sky (shade.glsl).
            g_secondary_rays = 0u;
            colour = shade_hit(h, h_mesh, org, dir, pixel, 0u, lod, traces, overflows,
                               truncations);
            colour = shade_samples(colour, px, pixel, traces, overflows, truncations);
            if (g_secondary_rays != 0u) {
                atomicAdd(push.stats.n[STAT_SHADOW_RAYS], g_secondary_rays);
            }
        } else if (f.view == VIEW_SHADED) {
            // Streaming: base colour and the key light with one shadow ray, from the carried
            // record.
            vec3 base = push.materials.r[c.rec.w].base_color;
            vec3 world_normal = c.hit.yzw;
            vec3 n = dot(world_normal, dir) > 0.0 ? -world_normal : world_normal;
            vec3 sun = f.sun_dir_intensity.xyz;
            float ndl = dot(n, sun);
            float light = f.ambient;
            if (ndl > 0.0) {
                float visible = 1.0;
                if (f.shadows != 0u) {
                    vec3 p = org + dir * c.hit.x;
                    LodParams sl = f.lod;
                    if (f.shadow_lod_from_primary != 0u) {
                        sl.forced_lod = int(lod);
                    }
                    g_best_t = T_INFINITY;
                    g_start = c.st.y;
                    g_empty_t = T_INFINITY;
                    TraceHit sh = traverse(f.root_tlas, shadow_offset(p, n, max(max(abs(org.x), abs(org.y)), abs(org.z)) + c.hit.x), sun, RAY_SHADOW, sl,
                                           f.camera.pixels_per_unit_at_1, 0.0, true, traces,
                                           overflows, truncations);
                    visible = sh.t < T_INFINITY ? 0.0 : 1.0;
                    // Occluded is final whatever the open structures hold.
                    if (sh.t == T_INFINITY && !g_truncated && overflows == 0u &&
                        stream_still_open(T_INFINITY)) {
                        c.st.z = traces;
                        stream_defer(px, pixel, c);
                        return;
                    }
                    atomicAdd(push.stats.n[STAT_SHADOW_RAYS], 1u);
                }
                light = f.ambient + f.sun_dir_intensity.w * ndl * visible;
            }
            colour = base * light;
        } else if (f.view == VIEW_IDS) {
            colour = id_colour(c.rec.x, c.rec.y);
        } else {
            colour = lod_colour(lod);
        }
    } else if (f.view == VIEW_SHADED && !g_streaming) {
        g_secondary_rays = 0u;
        colour = shade_samples(shaded_background(dir), px, pixel, traces, overflows, truncations);
        if (g_secondary_rays != 0u) {
            atomicAdd(push.stats.n[STAT_SHADOW_RAYS], g_secondary_rays);
        }
    } else {
        colour = sky(dir);
    }
    rec.w |= min(traces, 65535u) << 16u;
    push.aov.r[pixel] = rec;
    push.rgba.r[pixel] = f.view == VIEW_SHADED && !g_streaming
                             ? tone_map(colour, f.exposure_scale)
                             : encode_srgb8(colour);
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
void render_pixel(uvec2 px) {
    g_streaming = false;
    g_guard = false;
    render_pixel_impl(px);
}

// Streaming work item `i` of a pass: an image pixel (written unless incomplete) or a
// guard-band pixel outside the image (primary ray only: it marks what the camera is about to
// see, for prefetching, and writes nothing).
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
    g_stamp = s.stamp;
    g_best_t = T_INFINITY;
    g_start = s.stamp;
    g_empty_t = T_INFINITY;
    if (!guard) {
        render_pixel_impl(uvec2(x, y));
        return;
    }
    vec3 dir = normalize(c.world_dir00 + c.world_du * (float(x) + 0.5) +
                         c.world_dv * (float(y) + 0.5));
    uint traces = 0u;
    uint overflows = 0u;
    uint truncations = 0u;
    FrameParams f = push.frame.f;
    traverse(f.root_tlas, c.world_eye, dir, RAY_PRIMARY, f.lod, c.pixels_per_unit_at_1, 0.5,
             false, traces, overflows, truncations);
}
#endif
