// One pixel: primary ray, optional shadow ray, AOV record and colour. Shared by both backends
// (included after traverse.glsl).
#ifndef MOTU_RENDER_PIXEL_GLSL
#define MOTU_RENDER_PIXEL_GLSL
#include "camera.glsl"
#include "traverse.glsl"

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
        uint primitive = source_primitive(m, s.mesh_record, h.primitive);
        rec.xyz = uvec3(m.source_mesh, primitive, floatBitsToUint(h.t));
        rec.w = min(lod, 255u);
        if (f.view == VIEW_SHADED) {
            vec3 base = push.materials.r[m.material].base_color;
            vec3 n = dot(s.world_normal, dir) > 0.0 ? -s.world_normal : s.world_normal;
            vec3 sun = f.sun_dir_intensity.xyz;
            float ndl = dot(n, sun);
            float light = f.ambient;
            if (ndl > 0.0) {
                float visible = 1.0;
                if (f.shadows != 0u) {
                    vec3 p = org + dir * h.t;
                    LodParams sl = f.lod;
                    if (f.shadow_lod_from_primary != 0u) {
                        sl.forced_lod = int(lod);
                    }
                    g_t_min = resume.y;
                    g_empty_t = T_INFINITY;
                    TraceHit sh = traverse(f.root_tlas, shadow_offset(p, n, max(max(abs(org.x), abs(org.y)), abs(org.z)) + h.t), sun, RAY_SHADOW, sl,
                                           f.camera.pixels_per_unit_at_1, 0.0, true, traces,
                                           overflows, truncations);
                    visible = sh.t < T_INFINITY ? 0.0 : 1.0;
                    if (sh.t < T_INFINITY) {
                        g_incomplete = false;  // occluded whatever the empty instances hold
                    } else if (g_incomplete) {
                        // The primary hit is final; the shadow ray resumes where it stopped.
                        stream_pin_hit(h);
                        stream_resume(pixel,
                                      vec2(resume.x, max(resume.y, RESUME_BACKOFF * g_empty_t)));
                        stream_defer(px);
                        return;
                    }
                    g_t_min = 0.0;
                    atomicAdd(push.stats.n[STAT_SHADOW_RAYS], 1u);
                }
                light = f.ambient + f.sun_dir_intensity.w * ndl * visible;
            }
            colour = base * light;
        } else if (f.view == VIEW_IDS) {
            colour = id_colour(m.source_mesh, primitive);
        } else {
            colour = lod_colour(lod);
        }
    } else {
        colour = sky(dir);
    }
    rec.w |= min(traces, 65535u) << 16u;
    push.aov.r[pixel] = rec;
    push.rgba.r[pixel] = encode_srgb8(colour);
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
