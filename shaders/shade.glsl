// Shading of one hit: the GPU mirror of motu-trace's shade.rs and motu_abi::shade (same rules,
// same random numbers, same texel addressing): shading normal (interpolated vertex normals),
// base colour × image texture (mip level from the pixel footprint, software bilinear over
// texels reached by device address), the frame's lights with shadow rays, and the sky term
// with ambient occlusion. Included by render_pixel.glsl after traverse.glsl.
#ifndef MOTU_SHADE_GLSL
#define MOTU_SHADE_GLSL
#include "traverse.glsl"
#include "texture.glsl"
#include "sampling.glsl"

// Secondary rays of the current pixel (added to the stats once per pixel).
uint g_secondary_rays = 0u;

// Environment map (motu_abi::env, mirrored line by line): its tables follow FrameParams in the
// frame-parameter buffer (motu-gpu render.rs ENV_OFFSET_BYTES): a header of ENV_HEADER_WORDS
// (width, height, sampleable, pad, light_from_world and world_from_light rows as vec4), the
// marginal CDF (height + 1), the conditional CDFs (height × (width + 1)), RGB radiance.
const uint64_t ENV_OFFSET_BYTES = 1024ul;
const uint ENV_HEADER_WORDS = 28u;
const float ENV_PI = 3.14159265359;

uint64_t env_base() {
    return uint64_t(push.frame) + ENV_OFFSET_BYTES;
}

// The largest i < n with cdf[first + i] <= u (motu_abi::env::find_interval).
uint env_find(FloatTable t, uint first, uint n, float u) {
    uint lo = 0u;
    uint hi = n + 1u;
    while (lo < hi) {
        uint mid = (lo + hi) / 2u;
        if (t.r[first + mid] <= u) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return min(max(lo, 1u) - 1u, n - 1u);
}

// Rows at word `at` (three vec4) times v.
vec3 env_mat_vec(FloatTable t, uint at, vec3 v) {
    vec3 r0 = vec3(t.r[at], t.r[at + 1u], t.r[at + 2u]);
    vec3 r1 = vec3(t.r[at + 4u], t.r[at + 5u], t.r[at + 6u]);
    vec3 r2 = vec3(t.r[at + 8u], t.r[at + 9u], t.r[at + 10u]);
    return vec3(r0.x * v.x + r0.y * v.y + r0.z * v.z, r1.x * v.x + r1.y * v.y + r1.z * v.z,
                r2.x * v.x + r2.y * v.y + r2.z * v.z);
}

vec3 env_texel(FloatTable t, uint w, uint h, uint col, uint row) {
    uint at = ENV_HEADER_WORDS + h + 1u + h * (w + 1u) + 3u * (row * w + col);
    return vec3(t.r[at], t.r[at + 1u], t.r[at + 2u]);
}

// A direction drawn from the map's distribution (Environment::sample): world direction,
// radiance and density per solid angle; false where the map has no light or at a pole.
bool env_sample(float u0, float u1, out vec3 dir, out vec3 radiance, out float pdf) {
    U32Table hdr = U32Table(env_base());
    FloatTable t = FloatTable(env_base());
    dir = vec3(0.0, 1.0, 0.0);
    radiance = vec3(0.0);
    pdf = 0.0;
    if (hdr.r[2] == 0u) {
        return false;
    }
    uint w = hdr.r[0];
    uint h = hdr.r[1];
    uint marg = ENV_HEADER_WORDS;
    uint row = env_find(t, marg, h, u1);
    float m0 = t.r[marg + row];
    float m1 = t.r[marg + row + 1u];
    float dv = (u1 - m0) / (m1 - m0);
    uint cb = marg + h + 1u + row * (w + 1u);
    uint col = env_find(t, cb, w, u0);
    float c0 = t.r[cb + col];
    float c1 = t.r[cb + col + 1u];
    float du = (u0 - c0) / (c1 - c0);
    float pdf_uv = float(h) * (m1 - m0) * (float(w) * (c1 - c0));
    float v = (float(row) + dv) / float(h);
    float u = (float(col) + du) / float(w);
    float theta = v * ENV_PI;
    float phi = u * 2.0 * ENV_PI;
    float sin_theta = sin(theta);
    if (!(pdf_uv > 0.0 && sin_theta > 0.0)) {
        return false;
    }
    vec3 l = vec3(sin_theta * cos(phi), sin_theta * sin(phi), cos(theta));
    dir = normalize(env_mat_vec(t, 16u, l));
    radiance = env_texel(t, w, h, col, row);
    pdf = pdf_uv / (2.0 * ENV_PI * ENV_PI * sin_theta);
    return true;
}

// Radiance arriving from world direction d, bilinear between texel centres
// (Environment::radiance_towards): what an escaping camera ray shows.
vec3 env_radiance(vec3 d) {
    U32Table hdr = U32Table(env_base());
    FloatTable t = FloatTable(env_base());
    uint w = hdr.r[0];
    uint h = hdr.r[1];
    vec3 l = env_mat_vec(t, 4u, normalize(d));
    float theta = acos(clamp(l.z, -1.0, 1.0));
    float phi = atan(l.y, l.x);
    if (phi < 0.0) {
        phi += 2.0 * ENV_PI;
    }
    float x = phi / (2.0 * ENV_PI) * float(w) - 0.5;
    float y = clamp(theta / ENV_PI * float(h) - 0.5, 0.0, float(h - 1u));
    float x0 = floor(x);
    float y0 = floor(y);
    float fx = x - x0;
    float fy = y - y0;
    int xi = int(x0);
    uint c0 = uint(((xi % int(w)) + int(w)) % int(w));
    uint c1 = uint((((xi + 1) % int(w)) + int(w)) % int(w));
    uint r0 = uint(y0);
    uint r1 = min(r0 + 1u, h - 1u);
    vec3 a = env_texel(t, w, h, c0, r0);
    vec3 b = env_texel(t, w, h, c1, r0);
    vec3 c = env_texel(t, w, h, c0, r1);
    vec3 e = env_texel(t, w, h, c1, r1);
    vec3 top = a + (b - a) * fx;
    vec3 bottom = c + (e - c) * fx;
    return top + (bottom - top) * fy;
}

// The pixel's Owen-scrambled Sobol sequence (sampling.glsl; motu_abi::shade::rand01).
float rand01(uint pixel, uint smp, uint dim) {
    return sample01(pixel, smp, dim);
}

float shininess(float roughness) {
    float a = max(roughness * roughness, 1e-3);
    return clamp(2.0 / (a * a) - 2.0, 1.0, 4096.0);
}

vec3 cosine_direction(vec3 n, float u1, float u2) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    precise float a = -1.0 / (s + n.z);
    precise float b = n.x * n.y * a;
    precise vec3 t = vec3(1.0 + s * n.x * n.x * a, s * b, -s * n.x);
    precise vec3 bt = vec3(b, s + n.y * n.y * a, -n.y);
    float r = sqrt(u1);
    float phi = 6.28318530718 * u2;
    float z = sqrt(max(1.0 - u1, 0.0));
    precise vec3 d = (r * cos(phi) * t + r * sin(phi) * bt) + z * n;
    return d;
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
    vec3 bary;  // barycentrics of the hit (vertex weights 0, 1, 2): Ptex face uvs
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
    precise vec3 p = org + dir * h.t;
    sp.p = p;
    precise vec3 e1 = v1 - v0;
    precise vec3 e2 = v2 - v0;
    precise vec3 n_obj = vec3(e1.y * e2.z - e1.z * e2.y, e1.z * e2.x - e1.x * e2.z,
                              e1.x * e2.y - e1.y * e2.x);
    precise vec3 n_world = transpose_vector(object_from_world, n_obj);
    precise float len2 = (n_world.x * n_world.x + n_world.y * n_world.y) + n_world.z * n_world.z;
    precise vec3 ng = n_world * (1.0 / sqrt(len2));
    if (dot(ng, dir) > 0.0) {
        ng = -ng;
    }
    sp.ng = ng;
    sp.ns = ng;
    sp.bary = barycentrics(v0, v1, v2, xform_point(object_from_world, sp.p));
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
    vec3 b = sp.bary;
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
    if (mat.base_color_texture != NONE_U32 && push.frame.f.shading != 0ul) {
        ShadingRef sr = ShadingRef(push.frame.f.shading);
        TextureRecord tex = TextureTable(sr.textures).r[mat.base_color_texture];
        if (tex.mip_count == 0u) {
            uint64_t words = texels_of(sr, mat.base_color_texture);
            if (words != 0ul) {
                albedo = ptex_albedo(tex, words, mesh, h.primitive, sp.bary, sp.has_uv, sp.uv,
                                     albedo);
            }
        } else if (sp.has_uv) {
            float tpp = sp.uv_per_pixel * sqrt(float(tex.width) * float(tex.height));
            uint64_t texels = texels_of(sr, mat.base_color_texture);
            if (texels != 0ul) {
                albedo *= sample_texture(tex, texels, sp.uv, mip_level(tpp, tex.mip_count)).rgb;
            }
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
    precise vec3 p = org + dir * t;
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
// the AO reach (w); false when it points below the surface (it brings nothing). With an
// environment map it is a direction drawn from the map (env_sample) reaching to infinity.
bool ao_ray(ShadeInput si, uint pixel, uint smp, uint k, out vec4 traced) {
    float u0 = rand01(pixel, smp, 2u + 2u * k);
    float u1 = rand01(pixel, smp, 3u + 2u * k);
    if (push.frame.f.environment != 0u) {
        vec3 d;
        vec3 radiance;
        float pdf;
        bool some = env_sample(u0, u1, d, radiance, pdf);
        traced = vec4(d, T_INFINITY);
        return some && dot(d, si.ng) > 0.0 && dot(d, si.ns) > 0.0;
    }
    vec3 d = cosine_direction(si.ns, u0, u1);
    traced = vec4(d, push.frame.f.ao_distance);
    return dot(d, si.ng) > 0.0;
}

// What environment ray `k` of sample `smp` brings when clear: the map's radiance through the
// material (diffuse and the specular lobe, as a light), cosine over density, averaged over
// the sample's `ao_samples` rays (motu_trace::shade::environment_term).
vec3 environment_term(ShadeInput si, uint material, vec3 dir, uint pixel, uint smp, uint k) {
    vec3 d;
    vec3 radiance;
    float pdf;
    if (!env_sample(rand01(pixel, smp, 2u + 2u * k), rand01(pixel, smp, 3u + 2u * k), d,
                    radiance, pdf)) {
        return vec3(0.0);
    }
    float ndl = dot(si.ns, d);
    if (ndl <= 0.0 || dot(si.ng, d) <= 0.0) {
        return vec3(0.0);
    }
    MaterialRecord mat = push.materials.r[material];
    vec3 diffuse = si.albedo * (1.0 - mat.metallic);
    vec3 f0 = vec3(0.04) + (si.albedo - vec3(0.04)) * mat.metallic;
    float s = shininess(mat.roughness);
    float spec_norm = (s + 8.0) / (8.0 * 3.14159265359);
    vec3 hv = normalize(d - dir);
    float spec = spec_norm * pow(max(dot(si.ns, hv), 0.0), s);
    return (diffuse / 3.14159265359 + f0 * spec) * radiance *
           (ndl / (pdf * float(push.frame.f.ao_samples)));
}

// The diffuse bounce from a vertex (motu_trace::shade::bounce_direction): a cosine-weighted
// direction about the shading normal drawn with the next vertex's sample `next_smp` in
// dimensions 0 and 1 (which secondary rays never use); `weight` multiplies the path's
// throughput (the diffuse albedo: Lambert's f·cos/pdf). False below the surface or where the
// surface has no diffuse part.
bool bounce_ray(ShadeInput si, uint material, uint pixel, uint next_smp, out vec3 d,
                out vec3 weight) {
    MaterialRecord mat = push.materials.r[material];
    weight = si.albedo * (1.0 - mat.metallic);
    d = cosine_direction(si.ns, rand01(pixel, next_smp, 0u), rand01(pixel, next_smp, 1u));
    return dot(d, si.ng) > 0.0 && max(max(weight.x, weight.y), weight.z) > 0.0;
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
// a clear AO ray counts in `ao_open` (an environment ray adds its term).
void secondary_ray_done(uint outcome, uint ray, ShadeInput si, uint material, vec3 org,
                        vec3 dir, float t, uint pixel, uint smp, inout vec3 colour,
                        inout uint ao_open) {
    if (outcome != RAY_CLEAR) {
        return;
    }
    uint nl = min(push.frame.f.light_count, uint(MAX_LIGHTS));
    if (ray < nl) {
        vec4 shadow_ray;
        vec3 term;
        if (light_term(ray, si, material, org, dir, t, shadow_ray, term)) {
            colour += term;
        }
    } else if (push.frame.f.environment != 0u) {
        colour += environment_term(si, material, dir, pixel, smp, ray - nl);
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
                           vec3 dir, float t, uint pixel, uint smp, inout vec3 colour,
                           inout uint ao_open) {
    for (uint i = 0u; i < SECONDARY_WINDOW; ++i) {
        if ((clear & (1u << i)) != 0u) {
            secondary_ray_done(RAY_CLEAR, first + i, si, material, org, dir, t, pixel, smp,
                               colour, ao_open);
        }
    }
}

// The sky term of a sample whose secondary rays are all done (`ao_open` of them clear); with
// an environment map its rays added their terms already (without rays: the map's mean).
vec3 sky_term(ShadeInput si, uint material, uint ao_open) {
    if (push.frame.f.environment != 0u && push.frame.f.ao_samples > 0u) {
        return vec3(0.0);
    }
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
    if (push.frame.f.environment != 0u) {
        return env_radiance(dir);
    }
    return push.frame.f.sky.w != 0.0 ? push.frame.f.sky.rgb : sky(dir);
}

// Linear RGB as shared-exponent RGB9E5 (motu_abi::shade::encode_rgb9e5, line by line).
uint encode_rgb9e5(vec3 c) {
    const float MAX_RGB9E5 = 65408.0;
    c = vec3(c.x > 0.0 ? min(c.x, MAX_RGB9E5) : 0.0, c.y > 0.0 ? min(c.y, MAX_RGB9E5) : 0.0,
             c.z > 0.0 ? min(c.z, MAX_RGB9E5) : 0.0);
    float m = max(max(c.x, c.y), c.z);
    if (m <= 0.0) {
        return 0u;
    }
    int floor_log2 = int((floatBitsToUint(m) >> 23u) & 0xffu) - 127;
    int e = max(floor_log2, -16) + 16;
    float denom = exp2(float(e - 15 - 9));
    if (floor(m / denom + 0.5) >= 512.0) {
        e += 1;
        denom *= 2.0;
    }
    uvec3 q = min(uvec3(floor(c / denom + 0.5)), uvec3(511u));
    return q.x | (q.y << 9u) | (q.z << 18u) | (uint(e) << 27u);
}

// Exposure and the sRGB transfer (motu_abi::shade::tone_map); under auto exposure the linear
// colour as RGB9E5, tone-mapped on the host once the image's exposure is known.
uint tone_map(vec3 c, float exposure_scale) {
    if (push.frame.f.auto_exposure != 0u) {
        return encode_rgb9e5(c);
    }
    return encode_srgb8(c * exposure_scale);
}
#endif
