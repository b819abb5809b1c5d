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

// A resumed ray starts a hair before where the last pass stopped.
#define RESUME_BACKOFF 0.99999

void stream_resume(uint pixel, vec2 t) {
    ResumeTable(StreamRef(push.stream).s.resume).r[pixel] = t;
}

// Streaming: an incomplete pixel goes on the next pass's list and writes nothing.
void stream_defer(uvec2 px) {
    IncompleteList l = IncompleteList(StreamRef(push.stream).s.incomplete);
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
        g_t_min = 0.0;
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
    // Streaming: where this pixel's rays resume (0 on the frame's first pass).
    vec2 resume = vec2(0.0);
    if (g_streaming) {
        resume = ResumeTable(StreamRef(push.stream).s.resume).r[pixel];
    }
    g_t_min = resume.x;
    TraceHit h = traverse(f.root_tlas, org, dir, RAY_PRIMARY, f.lod, f.camera.pixels_per_unit_at_1,
                          pixel_dither(px.x, px.y), false, traces, overflows, truncations);
    if (g_incomplete) {
        // Shading and shadow rays would be wasted: the pixel is re-shot next pass, from just
        // before its nearest empty instance (its shadow ray from the start).
        stream_pin_hit(h);
        stream_resume(pixel, vec2(max(resume.x, RESUME_BACKOFF * min(g_empty_t, h.t)), 0.0));
        stream_defer(px);
        return;
    }
    g_t_min = 0.0;
    vec3 colour;
    uvec4 rec = uvec4(AOV_MISS, 0u, 0u, 0u);
    if (h.t < T_INFINITY) {
        Surface s = resolve(h);
        MeshRecord m = push.meshes.r[s.mesh_record];
        uint lod = h.lod == NONE_U32 ? m.lod : h.lod;
        rec.xyz = uvec3(m.source_mesh, h.primitive, floatBitsToUint(h.t));
        rec.w = min(lod, 255u);
        if (f.view == VIEW_SHADED) {
            g_secondary_rays = 0u;
            g_secondary_incomplete = false;
            colour = shade_hit(h, s.mesh_record, org, dir, pixel, 0u, lod, traces, overflows,
                               truncations);
            if (g_secondary_incomplete) {
                // The primary hit is final; its secondary rays are traced again next pass.
                stream_pin_hit(h);
                stream_resume(pixel, vec2(resume.x, 0.0));
                stream_defer(px);
                return;
            }
            colour = shade_samples(colour, px, pixel, traces, overflows, truncations);
            if (g_secondary_rays != 0u) {
                atomicAdd(push.stats.n[STAT_SHADOW_RAYS], g_secondary_rays);
            }
        } else if (f.view == VIEW_IDS) {
            colour = id_colour(m.source_mesh, h.primitive);
        } else {
            colour = lod_colour(lod);
        }
    } else if (f.view == VIEW_SHADED) {
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
    push.rgba.r[pixel] = f.view == VIEW_SHADED ? tone_map(colour, f.exposure_scale)
                                               : encode_srgb8(colour);
    if (overflows != 0u) {
        atomicAdd(push.stats.n[STAT_STACK_OVERFLOWS], overflows);
    }
    if (truncations != 0u) {
        atomicAdd(push.stats.n[STAT_PI_LIST_OVERFLOWS], truncations);
    }
}
void render_pixel(uvec2 px) {
    g_streaming = false;
    g_t_min = 0.0;
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
    g_incomplete = false;
    g_empty_t = T_INFINITY;
    g_t_min = 0.0;
    g_mark = 2u * s.stamp + (guard ? 0u : 1u);
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
