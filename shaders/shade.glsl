// Shading of one hit: the GPU mirror of motu-trace's shade.rs and motu_abi::shade (same rules,
// same random numbers, same texel addressing): shading normal (interpolated vertex normals),
// base colour × image texture (mip level from the pixel footprint, software bilinear over
// texels reached by device address), the frame's lights with shadow rays, and the sky term
// with ambient occlusion. Included by render_pixel.glsl after traverse.glsl.
#ifndef MOTU_SHADE_GLSL
#define MOTU_SHADE_GLSL
#include "traverse.glsl"
#include "texture.glsl"

// Secondary rays of the current pixel (added to the stats once per pixel).
uint g_secondary_rays = 0u;

float rand01(uint pixel, uint smp, uint dim) {
    uint h = hash_u32(hash_u32(hash_u32(pixel) ^ (smp * 0x9e3779b9u)) ^ dim);
    return float(h >> 8u) / 16777216.0;
}

float shininess(float roughness) {
    float a = max(roughness * roughness, 1e-3);
    return clamp(2.0 / (a * a) - 2.0, 1.0, 4096.0);
}

vec3 cosine_direction(vec3 n, float u1, float u2) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float b = n.x * n.y * a;
    vec3 t = vec3(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    vec3 bt = vec3(b, s + n.y * n.y * a, -n.y);
    float r = sqrt(u1);
    float phi = 6.28318530718 * u2;
    float z = sqrt(max(1.0 - u1, 0.0));
    return r * cos(phi) * t + r * sin(phi) * bt + z * n;
}

vec3 barycentrics(vec3 v0, vec3 v1, vec3 v2, vec3 p) {
    vec3 e0 = v1 - v0;
    vec3 e1 = v2 - v0;
    vec3 ep = p - v0;
    float d00 = dot(e0, e0);
    float d01 = dot(e0, e1);
    float d11 = dot(e1, e1);
    float d20 = dot(ep, e0);
    float d21 = dot(ep, e1);
    float den = d00 * d11 - d01 * d01;
    if (den == 0.0) {
        return vec3(1.0, 0.0, 0.0);
    }
    float b1 = (d11 * d20 - d01 * d21) / den;
    float b2 = (d00 * d21 - d01 * d20) / den;
    return vec3(1.0 - b1 - b2, b1, b2);
}

struct ShadePoint {
    vec3 p;
    vec3 ng;  // geometric normal facing the ray origin
    vec3 ns;  // shading normal, same side
    bool has_uv;
    vec2 uv;
    float uv_per_pixel;
};

vec3 load_vec3(Floats f, uint i) {
    return vec3(f.v[3u * i], f.v[3u * i + 1u], f.v[3u * i + 2u]);
}

ShadePoint surface_point(TraceHit h, uint mesh, vec3 org, vec3 dir) {
    ShadePoint sp;
    InstanceRecord inst = push.instances.r[push.tlases.r[h.tlas].instance_base + h.instance];
    MeshRecord m = push.meshes.r[mesh];
    MeshGeo g = push.mesh_geo.r[mesh];
    U32Table idx = U32Table(g.indices);
    Floats pos = Floats(g.positions);
    uvec3 tri = uvec3(idx.r[3u * h.primitive], idx.r[3u * h.primitive + 1u],
                      idx.r[3u * h.primitive + 2u]);
    vec3 v0 = load_vec3(pos, tri.x);
    vec3 v1 = load_vec3(pos, tri.y);
    vec3 v2 = load_vec3(pos, tri.z);
    Affine object_from_world =
        compose(affine_inverse(affine_from_array(inst.tlas_from_blas)), h.tlas_from_world);
    sp.p = org + dir * h.t;
    vec3 ng = normalize(transpose_vector(object_from_world, cross(v1 - v0, v2 - v0)));
    if (dot(ng, dir) > 0.0) {
        ng = -ng;
    }
    sp.ng = ng;
    sp.ns = ng;
    sp.has_uv = false;
    sp.uv = vec2(0.0);
    sp.uv_per_pixel = 0.0;
    uint64_t shading = push.frame.f.shading;
    if (shading == 0ul) {
        return sp;
    }
    U64Table attrs = U64Table(ShadingRef(shading).mesh_attrs);
    uint64_t normals = attrs.r[2u * mesh];
    uint64_t uvs = attrs.r[2u * mesh + 1u];
    if (normals == 0ul && uvs == 0ul) {
        return sp;
    }
    vec3 b = barycentrics(v0, v1, v2, xform_point(object_from_world, sp.p));
    if (normals != 0ul && (m.flags & FLAG_HAS_NORMALS) != 0u) {
        Floats n = Floats(normals);
        vec3 n_obj = b.x * load_vec3(n, tri.x) + b.y * load_vec3(n, tri.y) + b.z * load_vec3(n, tri.z);
        vec3 ns = normalize(transpose_vector(object_from_world, n_obj));
        if (!any(isnan(ns)) && !any(isinf(ns)) && length(ns) > 0.5) {
            sp.ns = dot(ns, ng) < 0.0 ? -ns : ns;
        }
    }
    if (uvs != 0ul && (m.flags & FLAG_HAS_UVS) != 0u) {
        Floats u = Floats(uvs);
        vec2 t0 = vec2(u.v[2u * tri.x], u.v[2u * tri.x + 1u]);
        vec2 t1 = vec2(u.v[2u * tri.y], u.v[2u * tri.y + 1u]);
        vec2 t2 = vec2(u.v[2u * tri.z], u.v[2u * tri.z + 1u]);
        sp.has_uv = true;
        sp.uv = b.x * t0 + b.y * t1 + b.z * t2;
        Affine world_from_object = affine_inverse(object_from_world);
        vec3 w0 = xform_point(world_from_object, v0);
        vec3 w1 = xform_point(world_from_object, v1);
        vec3 w2 = xform_point(world_from_object, v2);
        float world_area = length(cross(w1 - w0, w2 - w0));
        vec2 d1 = t1 - t0;
        vec2 d2 = t2 - t0;
        float uv_area = abs(d1.x * d2.y - d2.x * d1.y);
        if (world_area > 0.0) {
            sp.uv_per_pixel = h.t / push.frame.f.camera.pixels_per_unit_at_1 *
                              sqrt(uv_area / world_area);
        }
    }
    return sp;
}

// Direction to the light, shadow-ray length (w) and irradiance at normal incidence; false when
// it brings nothing (motu_trace::shade::light_incidence).
bool light_incidence(LightRecord l, vec3 p, out vec4 dir_reach, out vec3 e) {
    if (l.kind == LIGHT_DISTANT) {
        dir_reach = vec4(-l.world_direction, T_INFINITY);
        e = l.radiance;
        return true;
    }
    vec3 to = l.world_position - p;
    float d2 = dot(to, to);
    if (d2 <= 0.0) {
        return false;
    }
    float dist = sqrt(d2);
    vec3 d = to / dist;
    float scale = 1.0 / d2;
    float reach = dist;
    if (l.kind == LIGHT_SPOT) {
        float c = -dot(d, l.world_direction);
        float x = clamp((c - l.cos_total) / max(l.cos_falloff - l.cos_total, 1e-6), 0.0, 1.0);
        scale *= x * x * (3.0 - 2.0 * x);
    } else if (l.kind == LIGHT_AREA) {
        reach = dist - l.cos_total;
        if (reach <= 0.0) {
            return false;
        }
    }
    if (scale <= 0.0) {
        return false;
    }
    dir_reach = vec4(d, reach);
    e = l.radiance * scale;
    return true;
}

// What shading needs of a hit, resolved while its BLAS and mesh are resident (streaming carries
// it across passes): geometric and shading normals facing the ray, textured base colour.
struct ShadeInput {
    vec3 ng;
    vec3 ns;
    vec3 albedo;
};

ShadeInput shade_input(TraceHit h, uint mesh, vec3 org, vec3 dir) {
    MaterialRecord mat = push.materials.r[push.meshes.r[mesh].material];
    ShadePoint sp = surface_point(h, mesh, org, dir);
    vec3 albedo = mat.base_color;
    if (mat.base_color_texture != NONE_U32 && sp.has_uv) {
        ShadingRef sr = ShadingRef(push.frame.f.shading);
        TextureRecord tex = TextureTable(sr.textures).r[mat.base_color_texture];
        float tpp = sp.uv_per_pixel * sqrt(float(tex.width) * float(tex.height));
        uint64_t texels = texels_of(sr, mat.base_color_texture);
        if (texels != 0ul) {
            albedo *= sample_texture(tex, texels, sp.uv, mip_level(tpp, tex.mip_count)).rgb;
        }
    }
    ShadeInput si;
    si.ng = sp.ng;
    si.ns = sp.ns;
    si.albedo = albedo;
    return si;
}

// The secondary rays of one sample's hit (motu_trace::shade::shade_hit): the frame's lights with
// shadow rays, then the sky term with `ao_samples` ambient-occlusion rays, numbered in that
// order. render_pixel.glsl traces them one at a time through its one traverse() call site
// (issue 15: every inlined call site of the traversal loop, and every value live across its
// traceRayEXT, costs each TLAS hop; per-ray state is recomputed here rather than kept live).

// Outcomes of a secondary ray.
const uint RAY_CLEAR = 0u;
const uint RAY_OCCLUDED = 1u;
// Streaming only: nothing resident occludes it, but a structure not walked since the ray's start
// stamp lies within its reach: the ray is traced again next pass.
const uint RAY_OPEN = 2u;

// Where the secondary rays of a hit at distance `t` along (org, dir) start (geometric normal
// `ng` facing the ray).
vec3 secondary_start(vec3 org, vec3 dir, float t, vec3 ng) {
    vec3 p = org + dir * t;
    float reach = max(max(abs(org.x), abs(org.y)), abs(org.z)) + t;
    return shadow_offset(p, ng, reach);
}

// Light `i`'s unshadowed term at p = org + dir·t and its shadow ray (xyz direction, w reach);
// false when the light brings nothing there.
bool light_term(uint i, ShadeInput si, uint material, vec3 org, vec3 dir, float t,
                out vec4 shadow_ray, out vec3 term) {
    vec3 e;
    if (!light_incidence(push.frame.f.lights[i], org + dir * t, shadow_ray, e)) {
        return false;
    }
    vec3 ldir = shadow_ray.xyz;
    float ndl = dot(si.ns, ldir);
    if (ndl <= 0.0 || dot(si.ng, ldir) <= 0.0) {
        return false;
    }
    MaterialRecord mat = push.materials.r[material];
    vec3 diffuse = si.albedo * (1.0 - mat.metallic);
    vec3 f0 = vec3(0.04) + (si.albedo - vec3(0.04)) * mat.metallic;
    float s = shininess(mat.roughness);
    float spec_norm = (s + 8.0) / (8.0 * 3.14159265359);
    vec3 hv = normalize(ldir - dir);
    float spec = spec_norm * pow(max(dot(si.ns, hv), 0.0), s);
    term = (diffuse / 3.14159265359 + f0 * spec) * e * ndl;
    return true;
}

// AO ray `k` of sample `smp`: a cosine-weighted direction about the shading normal (xyz) and
// the AO reach (w); false when it points below the surface (it brings nothing).
bool ao_ray(ShadeInput si, uint pixel, uint smp, uint k, out vec4 traced) {
    vec3 d = cosine_direction(si.ns, rand01(pixel, smp, 2u + 2u * k),
                              rand01(pixel, smp, 3u + 2u * k));
    traced = vec4(d, push.frame.f.ao_distance);
    return dot(d, si.ng) > 0.0;
}

// The sample's secondary rays: the lights' shadow rays, then its AO rays.
uint secondary_ray_count() {
    return min(push.frame.f.light_count, uint(MAX_LIGHTS)) + push.frame.f.ao_samples;
}

// What secondary ray `ray` needs: a trace (true: direction in xyz, reach in w of `traced`), or
// none (false), `clear` then saying whether it counts as unoccluded (a light with shadows off,
// its `term`) or brings nothing (a light facing away, an AO direction below the surface).
bool secondary_ray(ShadeInput si, uint material, vec3 org, vec3 dir, float t, uint pixel,
                   uint smp, uint ray, out vec4 traced, out bool clear, out vec3 term) {
    uint nl = min(push.frame.f.light_count, uint(MAX_LIGHTS));
    clear = false;
    traced = vec4(0.0);
    term = vec3(0.0);
    if (ray < nl) {
        if (!light_term(ray, si, material, org, dir, t, traced, term)) {
            return false;
        }
        if (push.frame.f.shadows != 0u) {
            return true;
        }
        clear = true;
        return false;
    }
    return ao_ray(si, pixel, smp, ray - nl, traced);
}

// From secondary ray `ray` on: the first one that needs a trace (its direction in xyz, its
// reach in w; true), adding the terms of the lights that need none (shadows off) to `colour`
// and skipping lights that bring nothing and AO directions below the surface. False when no
// ray is left (`ray` = the ray count). Full builds only: `secondary_ray` in a loop, its light
// branch written out because the loop's shape is what full builds were timed with on the H200
// (see SECONDARY_WINDOW); the AO direction is `ao_ray` in both.
bool next_secondary_ray(ShadeInput si, uint material, vec3 org, vec3 dir, float t, uint pixel,
                        uint smp, inout uint ray, inout vec3 colour, out vec4 traced) {
    uint nl = min(push.frame.f.light_count, uint(MAX_LIGHTS));
    uint n = nl + push.frame.f.ao_samples;
    bool shadows = push.frame.f.shadows != 0u;
    for (; ray < n; ++ray) {
        if (ray < nl) {
            vec3 term;
            if (light_term(ray, si, material, org, dir, t, traced, term)) {
                if (shadows) {
                    return true;
                }
                colour += term;
            }
        } else if (ao_ray(si, pixel, smp, ray - nl, traced)) {
            return true;
        }
    }
    return false;
}

// A traced secondary ray `ray` ended `outcome`: a clear light ray adds its term to `colour`,
// a clear AO ray counts in `ao_open`.
void secondary_ray_done(uint outcome, uint ray, ShadeInput si, uint material, vec3 org,
                        vec3 dir, float t, inout vec3 colour, inout uint ao_open) {
    if (outcome != RAY_CLEAR) {
        return;
    }
    if (ray < min(push.frame.f.light_count, uint(MAX_LIGHTS))) {
        vec4 shadow_ray;
        vec3 term;
        if (light_term(ray, si, material, org, dir, t, shadow_ray, term)) {
            colour += term;
        }
    } else {
        ao_open += 1u;
    }
}

// Secondary rays run in windows of SECONDARY_WINDOW rays: a pass traces every ray of the window
// that is not done (streaming: one a non-resident structure may occlude is traced again next
// pass while the others finish, so a sample's shadow and AO rays wait on each other's builds in
// the same pass rather than one after another), and the window's clear rays are added in ray
// order once all are done, so the colour is the full build's whatever pass each finished in.
// The window's state is two masks (done, clear << 8) kept in Carry.ns.w as an exact float.
// Only the streamed variant of the trace shaders (MOTU_STREAMED) uses windows: in one shared
// with full builds, the window loop's shape cost every full-build ray (H200, island 0.05 at
// 1280×720: +2.5% a frame shaded, +1.7% in the ids view), so those keep the sequential loop.
const uint SECONDARY_WINDOW = 8u;

// The window of rays from `first` is done: its clear rays (bits of `clear`), in ray order, add
// their light terms to `colour` and count AO rays in `ao_open`.
void secondary_window_done(uint first, uint clear, ShadeInput si, uint material, vec3 org,
                           vec3 dir, float t, inout vec3 colour, inout uint ao_open) {
    for (uint i = 0u; i < SECONDARY_WINDOW; ++i) {
        if ((clear & (1u << i)) != 0u) {
            secondary_ray_done(RAY_CLEAR, first + i, si, material, org, dir, t, colour, ao_open);
        }
    }
}

// The sky term of a sample whose secondary rays are all done (`ao_open` of them clear).
vec3 sky_term(ShadeInput si, uint material, uint ao_open) {
    MaterialRecord mat = push.materials.r[material];
    vec3 diffuse = si.albedo * (1.0 - mat.metallic);
    vec3 f0 = vec3(0.04) + (si.albedo - vec3(0.04)) * mat.metallic;
    float ao = 1.0;
    if (push.frame.f.ao_samples > 0u) {
        ao = float(ao_open) / float(push.frame.f.ao_samples);
    }
    return (diffuse + f0) * push.frame.f.sky.rgb * ao;
}

// What a primary ray that hits nothing shows in the shaded view.
vec3 shaded_background(vec3 dir) {
    return push.frame.f.sky.w != 0.0 ? push.frame.f.sky.rgb : sky(dir);
}

// Exposure and the sRGB transfer (motu_abi::shade::tone_map).
uint tone_map(vec3 c, float exposure_scale) {
    return encode_srgb8(c * exposure_scale);
}
#endif
