// Image and Ptex textures and per-vertex attributes reached through FrameParams.shading, shared by the
// shading code (shade.glsl) and the alpha tests of non-opaque triangles (any-hit shader and
// ray-query loop). Mirrors motu_abi::shade (texel addressing and bilinear sampling).
#ifndef MOTU_TEXTURE_GLSL
#define MOTU_TEXTURE_GLSL
#include "common.glsl"

// FrameParams.shading: per-mesh attribute addresses and the texture tables (0 = none: constant
// colours and geometric normals then). Streaming rewrites the attribute addresses as meshes
// come and go (0 while a mesh is not resident; a hit is only resolved while it is).
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer ShadingRef {
    uint64_t mesh_attrs;  // per mesh record: normals address, uvs address (0: none)
    uint64_t textures;    // TextureRecord[]
    uint64_t texels;      // u32 RGBA8
    // Streaming: per texture, the address of its own mip chain (0: not resident); the records'
    // texel offsets are then 0. 0 in a full build, where every chain sits in `texels`.
    uint64_t texel_addresses;
};
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer TextureTable { TextureRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer Floats { float v[]; };

float srgb_to_linear(float v) {
    return v <= 0.04045 ? v / 12.92 : pow((v + 0.055) / 1.055, 2.4);
}

uint mip_extent(uint size, uint level) {
    return max(size >> min(level, 31u), 1u);
}

uint mip_level(float texels_per_pixel, uint mip_count) {
    if (!(texels_per_pixel > 1.0)) {
        return 0u;
    }
    return min(uint(floor(log2(texels_per_pixel))), mip_count - 1u);
}

vec4 texel_at(U32Table texels, uint base, uint w, uint h, int xi, int yi) {
    // xi in [-1, w], yi in [-1, h]: one wrap suffices (motu_abi's rem_euclid agrees there).
    uint x = uint(xi < 0 ? xi + int(w) : (xi >= int(w) ? xi - int(w) : xi));
    uint y = uint(yi < 0 ? yi + int(h) : (yi >= int(h) ? yi - int(h) : yi));
    uint t = texels.r[base + y * w + x];
    vec4 c = vec4(float(t & 0xffu), float((t >> 8u) & 0xffu), float((t >> 16u) & 0xffu),
                  float(t >> 24u)) / 255.0;
    return vec4(srgb_to_linear(c.r), srgb_to_linear(c.g), srgb_to_linear(c.b), c.a);
}

// Where texture `index`'s texels are addressed from: the shared texel array, or (streaming)
// the texture's own chain. 0: a streamed texture that is not resident. A resident mesh holds
// its textures, so that is a broken invariant: it is counted, and the frame fails rather than
// showing the material's constants as if they were the image.
uint64_t texels_of(ShadingRef sr, uint index) {
    if (sr.texel_addresses == 0ul) {
        return sr.texels;
    }
    uint64_t a = U64Table(sr.texel_addresses).r[index];
    if (a == 0ul) {
        atomicAdd(push.stats.n[STAT_MISSING_TEXTURES], 1u);
    }
    return a;
}

// motu_abi::shade::sample_texture.
vec4 sample_texture(TextureRecord tex, uint64_t texels_addr, vec2 uv, uint level) {
    level = min(level, tex.mip_count - 1u);
    uint base = tex.texel_offset;
    for (uint l = 0u; l < level; ++l) {
        base += mip_extent(tex.width, l) * mip_extent(tex.height, l);
    }
    uint w = mip_extent(tex.width, level);
    uint h = mip_extent(tex.height, level);
    if (any(isnan(uv)) || any(isinf(uv))) {
        uv = vec2(0.0);
    }
    float x = (uv.x - floor(uv.x)) * float(w) - 0.5;
    float y = (1.0 - (uv.y - floor(uv.y))) * float(h) - 0.5;
    float x0 = floor(x);
    float y0 = floor(y);
    float fx = x - x0;
    float fy = y - y0;
    int xi = int(x0);
    int yi = int(y0);
    U32Table t = U32Table(texels_addr);
    vec4 a = texel_at(t, base, w, h, xi, yi);
    vec4 b = texel_at(t, base, w, h, xi + 1, yi);
    vec4 c = texel_at(t, base, w, h, xi, yi + 1);
    vec4 d = texel_at(t, base, w, h, xi + 1, yi + 1);
    vec4 top = a + (b - a) * fx;
    vec4 bottom = c + (d - c) * fx;
    return top + (bottom - top) * fy;
}

// Ptex textures (TextureRecord.mip_count == 0): motu_abi::ptex, mirrored line by line. The
// words sit at the record's texel offset: mesh tables, face entries, triangle tables, texels.

// The face of source triangle `prim` of `source_mesh`; y: 1 on a split quad's second half.
uvec2 ptex_face(TextureRecord tex, U32Table w, uint source_mesh, uint prim) {
    uint base = tex.texel_offset;
    uint lo = 0u;
    uint hi = w.r[base];
    while (lo < hi) {
        uint mid = (lo + hi) / 2u;
        uint id = w.r[base + 1u + 2u * mid];
        if (id == source_mesh) {
            uint table = w.r[base + 2u + 2u * mid];
            if (table == PTEX_QUADS) {
                return uvec2(prim / 2u, prim % 2u);
            }
            uint e = w.r[base + table + prim];
            return uvec2(e & ~PTEX_SECOND_HALF, (e & PTEX_SECOND_HALF) != 0u ? 1u : 0u);
        }
        if (id < source_mesh) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    return uvec2(prim, 0u);
}

vec2 ptex_default_uv(vec3 b, bool second_half) {
    return second_half ? vec2(b.y, b.y + b.z) : vec2(b.y + b.z, b.z);
}

vec4 ptex_texel(U32Table w, uint at) {
    uint t = w.r[at];
    vec4 c = vec4(float(t & 0xffu), float((t >> 8u) & 0xffu), float((t >> 16u) & 0xffu),
                  float(t >> 24u)) / 255.0;
    return vec4(srgb_to_linear(c.r), srgb_to_linear(c.g), srgb_to_linear(c.b), c.a);
}

// Bilinear sample of face `face` at face uv `uv`, clamped to the face; false for a face the
// texture does not have (the material's colour then shows).
bool sample_ptex(TextureRecord tex, uint64_t words, uint face, vec2 uv, out vec4 colour) {
    colour = vec4(0.0);
    if (face >= tex.height) {
        return false;
    }
    U32Table w = U32Table(words);
    uint base = tex.texel_offset;
    uint entry = base + 1u + 2u * w.r[base] + 2u * face;
    uint at = base + w.r[entry];
    uint res = w.r[entry + 1u];
    int fw = 1 << min(res & 0xffu, 15u);
    int fh = 1 << min((res >> 8u) & 0xffu, 15u);
    if (any(isnan(uv)) || any(isinf(uv))) {
        uv = vec2(0.0);
    }
    float x = clamp(uv.x, 0.0, 1.0) * float(fw) - 0.5;
    float y = clamp(uv.y, 0.0, 1.0) * float(fh) - 0.5;
    float x0 = floor(x);
    float y0 = floor(y);
    float fx = x - x0;
    float fy = y - y0;
    int xa = clamp(int(x0), 0, fw - 1);
    int xb = clamp(int(x0) + 1, 0, fw - 1);
    int ya = clamp(int(y0), 0, fh - 1);
    int yb = clamp(int(y0) + 1, 0, fh - 1);
    vec4 a = ptex_texel(w, at + uint(ya * fw + xa));
    vec4 b = ptex_texel(w, at + uint(ya * fw + xb));
    vec4 c = ptex_texel(w, at + uint(yb * fw + xa));
    vec4 d = ptex_texel(w, at + uint(yb * fw + xb));
    vec4 top = a + (b - a) * fx;
    vec4 bottom = c + (d - c) * fx;
    colour = top + (bottom - top) * fy;
    return true;
}

// The base colour of a hit on compiled mesh `mesh` (triangle `primitive`, barycentrics `b`,
// interpolated texture coordinates `uv` where `has_uv`) under Ptex texture `tex`: the face's
// sample replaces `albedo`. LOD levels (their triangles are not the source's) keep `albedo`.
vec3 ptex_albedo(TextureRecord tex, uint64_t words, uint mesh, uint primitive, vec3 b,
                 bool has_uv, vec2 uv, vec3 albedo) {
    MeshRecord m = push.meshes.r[mesh];
    if (m.lod != 0u) {
        return albedo;
    }
    uint prim = primitive;
    if ((m.flags & FLAG_PRIMITIVE_MAP) != 0u) {
        uint64_t map = push.mesh_geo.r[mesh].indices + 12ul * uint64_t(m.triangle_count);
        prim = U32Table(map).r[primitive];
    }
    uvec2 f = ptex_face(tex, U32Table(words), m.source_mesh, prim);
    vec2 fuv = has_uv ? uv : ptex_default_uv(b, f.y != 0u);
    vec4 c;
    if (sample_ptex(tex, words, f.x, fuv, c)) {
        return c.rgb;
    }
    return albedo;
}

// Coverage of a non-opaque triangle at barycentrics `bary` (Vulkan's: weights of vertices 1
// and 2): the material's constant opacity times its alpha texture at level 0 (motu-trace's
// shade::coverage). Streaming passes (no shading tables) test the constant only.
bool alpha_passes(uint tlas, uint instance, uint geometry, uint primitive, vec2 bary) {
    InstanceRecord inst = push.instances.r[push.tlases.r[tlas].instance_base + instance];
    uint mesh = push.geometries.r[push.blases.r[inst.blas].item_base + geometry].mesh;
    MeshRecord m = push.meshes.r[mesh];
    MaterialRecord mat = push.materials.r[m.material];
    float a = mat.opacity;
    uint64_t shading = push.frame.f.shading;
    if (mat.alpha_texture != NONE_U32 && shading != 0ul && (m.flags & FLAG_HAS_UVS) != 0u) {
        ShadingRef sr = ShadingRef(shading);
        uint64_t uvs = U64Table(sr.mesh_attrs).r[2u * mesh + 1u];
        if (uvs != 0ul) {
            MeshGeo g = push.mesh_geo.r[mesh];
            U32Table idx = U32Table(g.indices);
            Floats u = Floats(uvs);
            uint i0 = idx.r[3u * primitive];
            uint i1 = idx.r[3u * primitive + 1u];
            uint i2 = idx.r[3u * primitive + 2u];
            vec2 t0 = vec2(u.v[2u * i0], u.v[2u * i0 + 1u]);
            vec2 t1 = vec2(u.v[2u * i1], u.v[2u * i1 + 1u]);
            vec2 t2 = vec2(u.v[2u * i2], u.v[2u * i2 + 1u]);
            vec2 uv = (1.0 - bary.x - bary.y) * t0 + bary.x * t1 + bary.y * t2;
            TextureRecord tex = TextureTable(sr.textures).r[mat.alpha_texture];
            uint64_t texels = texels_of(sr, mat.alpha_texture);
            if (texels != 0ul) {
                a *= sample_texture(tex, texels, uv, 0u).a;
            }
        }
    }
    return a >= ALPHA_CUTOFF;
}
#endif
