// Shared declarations of both traversal backends: the hierarchy tables reached by device
// address (push constants), the frame parameters, the traversal payload and small helpers
// (id hash, palettes, sRGB, shadow-ray offset) mirrored from the CPU renderer (motu-trace).
#ifndef MOTU_COMMON_GLSL
#define MOTU_COMMON_GLSL
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#include "generated/abi.glsl"

// Candidates one TLAS walk can record before the list is truncated (the remainder is found by
// a re-walk of the same TLAS, see traverse.glsl): a specialisation constant, set for every
// stage to what the scene's TLASes can meet (motu-gpu `scene::pi_capacity`, 1..=8), since
// every payload byte costs every trace.
layout(constant_id = 2) const uint PI_CAPACITY = 8u;

#define VIEW_SHADED 0u
#define VIEW_IDS 1u
#define VIEW_LOD 2u
#define VIEW_HEATMAP 3u
#define VIEW_ALBEDO 4u  // the primary hit's textured base colour (the denoiser's guide)

// Indices of the stats buffer (u32 counters, reset every frame).
#define STAT_STACK_OVERFLOWS 0
#define STAT_PI_LIST_OVERFLOWS 1
#define STAT_SHADOW_RAYS 2
#define STAT_HITS 3
#define STAT_TRUNCATED_RAYS 4
#define STAT_MISSING_TEXTURES 5
// Streamed passes only (MOTU_STREAMED; motu-gpu stream PassStats): TLAS walks of the rays'
// walks, mark walks, and the TLAS walks of those mark walks.
#define STAT_TLAS_WALKS 6
#define STAT_MARK_WALKS 7
#define STAT_MARK_TLAS_WALKS 8
// Streamed passes (candidates.glsl `proxy_entry`, proxy_members.glsl): member boxes tested
// (quantised), and exact member tests (an instance record read) among them. The query backend
// always counts them; the pipeline backend, whose tests run in intersection and any-hit
// shaders, in counting mode only (COUNT_PROXY; by ray kind, motu-gpu `stream/proxy_count.rs`).
#define STAT_PROXY_MEMBER_TESTS 9
#define STAT_PROXY_EXACT_TESTS 10

#define T_INFINITY 3.0e38

// Counting mode of the streamed shaders (motu-gpu `StreamOptions::count_proxy_calls`,
// `MOTU_PROXY_TESTS=count`): where a pass's proxy work goes, per ray kind and outcome. A
// specialisation constant, so a pipeline made without it has no counting code left to run;
// full builds never declare it. With it, the stats buffer the shaders write is a longer one
// (motu-gpu `stream/proxy_count.rs`): after the STAT_* words, PROXY_COUNT_WORDS counters
// (kind-major, then outcome, then field), then PROXY_ITEM_WORDS words per launch item where the
// pipeline's proxy intersection and any-hit shaders, which cannot reach the payload, add up
// what the item's current ray costs until raygen (traverse.glsl) takes them.
#ifdef MOTU_STREAMED
layout(constant_id = 3) const uint COUNT_PROXY = 0u;
#endif
#define PROXY_COUNT_BASE 11u    // = Rust STAT_WORDS
// Kinds: camera (primary), guard, shadow (light), AO, bounce. Outcomes: open (a structure it
// has not walked lies in front of its best hit), closed (hit, or occluded), miss (clear).
#define PROXY_KIND_CAMERA 0u
#define PROXY_KIND_GUARD 1u
#define PROXY_KIND_SHADOW 2u
#define PROXY_KIND_AO 3u
#define PROXY_KIND_BOUNCE 4u
#define PROXY_KINDS 5u
#define PROXY_OUTCOMES 3u
// Fields: rays, intersection-shader calls (query: proxy candidates), reports (any-hit calls;
// query: = calls), quantised member tests, exact member tests.
#define PROXY_FIELDS 5u
#define PROXY_COUNT_WORDS 75u
#define PROXY_ITEM_WORDS 4u


// Streaming (motu-gpu's stream module): a programmable instance of this kind stands for a
// non-resident triangle BLAS (`target`) in its TLAS's proxy BLAS; meeting it in front of the
// best hit leaves the ray open until a pass walks that BLAS.
#define PI_EMPTY_BLAS 2u
// The instance SBT offset of a streamed TLAS's proxy and marks instances (motu-vk
// `InstanceHit::Proxy`: hit group 2), whose custom index is their BLAS's record.
#define PROXY_SBT_OFFSET 2u
// Packed pixel coordinates of a pass's pixel list are biased by this (guard-band pixels lie
// outside the image).
#define GUARD_BIAS 4096
// Levels of a BLAS stamp (`4 × stamp + level`, atomicMax keeps the highest): seen (guard band,
// or the hit of a walk), open (some pixel still needs it), needed (some pixel's nearest open).
#define STREAM_SEEN 0u
#define STREAM_OPEN 1u
#define STREAM_NEEDED 2u
// Kinds of ray a resident BLAS's hits came from, or-ed per pass into its request word (the
// host splits the frame's working set by them).
#define STREAM_HIT_CAMERA 1u
#define STREAM_HIT_GUARD 2u
#define STREAM_HIT_OCCLUSION 4u
#define STREAM_HIT_BOUNCE 8u
// Request word bit of a non-resident BLAS some camera ray's nearest open structure is (the
// low bits count the rays): the host builds these first (`stream/demand.rs`).
#define STREAM_REQUEST_CAMERA 0x80000000u
// Payload.stream_start bit of a guard-band ray (stamps stay below 2^29, STREAM_START_STAMP).
#define STREAM_GUARD_RAY 0x80000000u
// Payload.stream_start bit of a streamed ray's *mark walk* (traverse.glsl, MOTU_STREAMED): the
// second walk that marks what lies in front of the first walk's hit.
#define STREAM_MARK_WALK 0x40000000u
// Payload.stream_start bit of a *pass-mark walk*: a probe ray's mark walk taken although its
// hit is final (StreamParams.flags' pass rows): it marks the resident BLASes it enters at
// 4 × stamp - 1 (level 3 of the stamp before: below every mark of this pass, and written by
// nothing else), which the host reads as "passed": an LRU refresh, never a keep
// (stream/probe.rs).
#define STREAM_PASS_WALK 0x20000000u
#define STREAM_START_STAMP 0x1fffffffu
// StreamParams.flags: a prefetch probe of the next frame's camera (render_pixel.glsl): every
// pixel's rays, primary and secondary, run to the end against what is resident, marking what
// they meet open (the nearest needed and counted) and writing nothing else.
#define STREAM_PROBE_PASS 1u
// StreamParams.flags of a probe pass (StreamOptions::probe_paths `stop`): a probe ray of a
// closest-hit link (primary, bounce) whose nearest open structure lies in front of its resident
// hit ends its pixel's path there, instead of sending that hit's secondary rays and bounce from
// a point the frame's rays may never leave from; the next probe round goes on once it is built.
#define STREAM_PROBE_STOP 2u
// StreamParams.flags >> STREAM_PASS_ROWS_SHIFT: N > 0: in a probe pass, the pixels of every
// N-th row also take a pass-mark walk (STREAM_PASS_WALK). Whole rows: a launch's subgroups are
// runs of one row, so sampling within rows would cost every subgroup the whole walk.
#define STREAM_PASS_ROWS_SHIFT 8u
// StreamParams.flags of a frame's last pass (motu-gpu stream/passes.rs: its pass cap or build
// budget ends the frame after it): a pixel left open stays unfinished, so an open primary ray
// traces no secondary rays ahead (SPECULATIVE in render_pixel.glsl), which only a later pass
// of the same frame could use.
#define STREAM_LAST_PASS 4u
// StreamParams.flags of a last pass after which nothing is built (the frame's build budget is
// spent): no ray takes a mark walk (traverse.glsl), whose marks only steer that build.
#define STREAM_NO_MARK_WALK 8u
// StreamParams.flags, pipeline backend: the proxy intersection shader reads the current walk's
// nearest open entry so far (pipeline/open_bound.glsl), so an open ray's proxy boxes behind it
// test no member. Each walk starts from T_INFINITY as before: trace51's start from the ray's
// nearest open entry over its earlier walks (g_empty_t) changed residency on the probe-rounds
// fixture, deterministically (calls53: instance records 51,810 -> 53,126, the bound alone
// 51,810). Off: the intersection shader tests up to the committed triangle (motu-gpu
// StreamOptions::open_bound, comparisons).
#define STREAM_OPEN_BOUND 16u
// The carry buffer (StreamParams.carry): CARRY_WORDS u32 a pixel (render_pixel.glsl `Carry`,
// Rust CARRY_BYTES). Word CARRY_OPEN_BOUND_WORD of a slot (Carry.thru.w) is no part of any
// pixel's state (never read nor written as one): during a pipeline pass, slot i's holds launch
// item i's open bound (pipeline/open_bound.glsl), so the bound takes no memory of its own.
#define CARRY_WORDS 44u
#define CARRY_OPEN_BOUND_WORD 43u
// Ray cull masks (Rust: stream::MARKS_MASK, stream::TRIANGLE_MASK). Every instance has mask
// 0xFF except in a streamed TLAS its triangle instances (0x01) and its *marks* BLAS (0x02: the
// boxes of its resident clusters), which only probe passes' mark walks see: there a ray passing
// through a resident BLAS without hitting it marks it seen, so the prefetch keeps it (the
// hardware walk reports no such pass). A mark walk (CULL_MASK_MARK_WALK) meets PI and proxy
// boxes only: no triangle is tested twice.
#define CULL_MASK_WALK 0x01u
#define CULL_MASK_MARKS 0x02u
#define CULL_MASK_MARK_WALK 0x04u
#define CULL_MASK_PROBE 0xFFu
uint g_cull_mask = CULL_MASK_WALK;

// Per-pass streaming parameters (Rust: stream::StreamParams, 96 bytes). Present only when
// push.stream != 0.
struct StreamParams {
    uint64_t blas_stamps;   // u32 per BLAS: 4 × stamp + STREAM_* level
    uint64_t walked;        // u32 per BLAS: the latest stamp of a pass it was resident in
    uint64_t pixel_list;    // u32 packed (x + GUARD_BIAS) | (y + GUARD_BIAS) << 16
    uint64_t incomplete;    // u32 count, u32 packed pixels (unbiased x | y << 16); from index
                            // width × height, u32 per listed pixel: the structure it waits for
    uint stamp;
    uint full_count;        // items [0, full_count) are the image's pixels in row order
    uint list_count;        // items [full_count, full_count + list_count) come from pixel_list
    uint blas_count;
    uint64_t requests;      // u32 per BLAS: pixels whose nearest open structure it is (build order)
    uint64_t carry;         // Carry per pixel (render_pixel.glsl), zeroed at the frame's start
    uint64_t cluster_members;  // u32 global instance indices of the proxy clusters' members
    uint64_t proxy_box_index;  // uvec2 (first, fan) per BLAS into proxy_boxes (fan 0: none)
    uint64_t proxy_boxes;   // float[6] (min, max; BLAS space): fan top boxes, then fan leaves each
    uint flags;             // STREAM_PROBE_PASS, ...
    uint _pad;
};

struct FrameParams {
    CameraParams camera;
    LodParams lod;
    vec4 sun_dir_intensity;  // xyz: unit world direction towards the sun; w: intensity
    uint view;
    uint shadows;
    uint shadow_lod_from_primary;
    float ambient;
    uint root_tlas;
    uint light_count;
    uint64_t shading;        // ShadingRef (shade.glsl), 0: none
    vec4 sky;                // rgb: sky radiance of the ambient term; w: 1 = also the background
    uint ao_samples;
    uint spp;
    float ao_distance;
    float exposure_scale;
    LightRecord lights[MAX_LIGHTS];
    uint environment;    // 1: an environment map's tables follow, ENV_OFFSET_BYTES in (shade.glsl)
    uint auto_exposure;  // 1: shaded pixels are written as linear RGB9E5 (the host tone-maps)
    uint bounces;        // diffuse bounces after each primary hit
    uint first_sample;   // the frame's first sample in the pixel's sequence (progressive)
};

struct MeshGeo {
    uint64_t positions;  // [f32; 3] tightly packed
    uint64_t indices;    // u32 × 3 per triangle
};

// One recorded programmable-instance candidate: 8 bytes. AABB BLASes are instanced with
// identity (motu-compile's `validate` checks it), so the PI alone gives the child's transform:
// no instance index, no instance fetch, no inverse per candidate (issue 15: a smaller payload).
struct PiCandidate {
    uint pi;        // global PI index
    float t_near;   // world distance (t is invariant under the non-renormalised transforms)
};

// Whether candidate (t_a, pi_a) comes before (t_b, pi_b) in the walk's total order.
// Candidates are ordered by (t_near, pi): a total order, so a re-walk after truncation resumes
// exactly after the farthest kept one even where many share a t_near (a ray starting inside
// boxes meets them all at t_near 0); ordered by t_near alone, the tied ones were lost.
bool candidate_before(float t_a, uint pi_a, float t_b, uint pi_b) {
    return t_a < t_b || (t_a == t_b && pi_a < pi_b);
}

// The traversal payload (rayPayloadEXT in the pipeline backend, a plain global in the query
// backend): 52 + 8 × PI_CAPACITY bytes (116 at most). Written by raygen before the trace
// (tlas, floor, counters, streaming state) and by any-hit (candidates, kept in
// candidate_before's order; the nearest open streaming proxy) and closest-hit (the hit) during
// it.
struct Payload {
    uint tlas;
    uint count;
    float t_floor;   // record only candidates after (t_floor, floor_pi) (re-walk after truncation)
    uint floor_pi;
    float t_max;     // the trace's t_max (in any-hit, gl_RayTmaxEXT is the candidate's reported t)
    uint truncated;  // the list was full: farther candidates were dropped
    float hit_t;     // < 0: no triangle hit
    uint hit_instance;
    uint hit_geometry;
    uint hit_primitive;
    // Streaming (candidates.glsl `record_proxy`): proxy boxes of non-resident BLASes never take
    // a candidate slot; the walk keeps only the nearest open member entry (open_t, open_blas).
    // stream_start: the stamp of the pass the ray started in, | STREAM_GUARD_RAY for a guard
    // probe (marks only).
    float open_t;
    uint open_blas;
    uint stream_start;
    PiCandidate c[PI_CAPACITY];
};

layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer FrameRef { FrameParams f; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer TlasTable { TlasRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer InstanceTable { InstanceRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer BlasTable { BlasRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer GeometryTable { GeometryRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer PiTable { PiRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer SelectorTable { LodSelectorRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer U32Table { uint r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer MeshTable { MeshRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer MaterialTable { MaterialRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer MeshGeoTable { MeshGeo r[]; };
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer U64Table { uint64_t r[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer Positions { float v[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) writeonly buffer AovOut { uvec4 r[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) writeonly buffer RgbaOut { uint r[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) buffer Stats { uint n[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer StreamRef { StreamParams s; };
layout(buffer_reference, std430, buffer_reference_align = 4) buffer StampTable { uint r[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer FloatTable { float r[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) buffer IncompleteList { uint count; uint r[]; };

// 16 device addresses = 128 bytes, the guaranteed push-constant size. Order = Rust `Slot`.
layout(push_constant) uniform Push {
    FrameRef frame;
    TlasTable tlases;
    InstanceTable instances;
    BlasTable blases;
    GeometryTable geometries;
    PiTable pis;
    SelectorTable selectors;
    U32Table lod_levels;
    MeshTable meshes;
    MaterialTable materials;
    MeshGeoTable mesh_geo;
    U64Table tlas_addresses;
    AovOut aov;
    RgbaOut rgba;
    Stats stats;
    uint64_t stream;  // StreamParams address, 0 outside streaming
} push;

// Records `id` at `mark` (4 × stamp + level) in a stamp table (read first: most marks are
// repeats).
void stream_mark(uint64_t table, uint id, uint mark) {
    StampTable t = StampTable(table);
    if (t.r[id] < mark) {
        atomicMax(t.r[id], mark);
    }
}

// Row-major 3×4 as three rows.
struct Affine {
    vec4 r0;
    vec4 r1;
    vec4 r2;
};

Affine affine_identity() {
    return Affine(vec4(1, 0, 0, 0), vec4(0, 1, 0, 0), vec4(0, 0, 1, 0));
}

Affine affine_from_array(float m[12]) {
    return Affine(vec4(m[0], m[1], m[2], m[3]), vec4(m[4], m[5], m[6], m[7]),
                  vec4(m[8], m[9], m[10], m[11]));
}

// The transforms below are `precise` (no fused multiply-adds) and spell out their dot products,
// so every shader module rounds them alike: NVIDIA's compiler otherwise fuses differently in
// the full build's and the streamed ray-generation shaders, and secondary rays from the same
// hit then started a few ulps apart (9 of 230,400 pixels differed on an H100, session 49).
vec3 xform_point(Affine m, vec3 p) {
    precise vec3 r = vec3(((m.r0.x * p.x + m.r0.y * p.y) + m.r0.z * p.z) + m.r0.w,
                          ((m.r1.x * p.x + m.r1.y * p.y) + m.r1.z * p.z) + m.r1.w,
                          ((m.r2.x * p.x + m.r2.y * p.y) + m.r2.z * p.z) + m.r2.w);
    return r;
}

vec3 xform_vector(Affine m, vec3 v) {
    precise vec3 r = vec3((m.r0.x * v.x + m.r0.y * v.y) + m.r0.z * v.z,
                          (m.r1.x * v.x + m.r1.y * v.y) + m.r1.z * v.z,
                          (m.r2.x * v.x + m.r2.y * v.y) + m.r2.z * v.z);
    return r;
}

// mᵀ n for the linear part: the normal transform by object_from_world without inverting.
vec3 transpose_vector(Affine m, vec3 n) {
    precise vec3 r = (m.r0.xyz * n.x + m.r1.xyz * n.y) + m.r2.xyz * n.z;
    return r;
}

// a ∘ b (apply b first).
Affine compose(Affine a, Affine b) {
    mat3 la = mat3(a.r0.xyz, a.r1.xyz, a.r2.xyz);  // columns = rows of a: la is aᵀ
    mat3 lb = mat3(b.r0.xyz, b.r1.xyz, b.r2.xyz);
    precise mat3 l = lb * la;  // (a·b)ᵀ = bᵀ·aᵀ
    precise vec3 t = xform_vector(a, vec3(b.r0.w, b.r1.w, b.r2.w)) + vec3(a.r0.w, a.r1.w, a.r2.w);
    return Affine(vec4(l[0], t.x), vec4(l[1], t.y), vec4(l[2], t.z));
}

Affine affine_inverse(Affine m) {
    mat3 lt = mat3(m.r0.xyz, m.r1.xyz, m.r2.xyz);  // transpose of the linear part
    precise mat3 inv_t = inverse(lt);               // = (L⁻¹)ᵀ: its columns are rows of L⁻¹
    vec3 t = vec3(m.r0.w, m.r1.w, m.r2.w);
    Affine r = Affine(vec4(inv_t[0], 0.0), vec4(inv_t[1], 0.0), vec4(inv_t[2], 0.0));
    vec3 it = -xform_vector(r, t);
    r.r0.w = it.x;
    r.r1.w = it.y;
    r.r2.w = it.z;
    return r;
}

// Slab test mirrored from motu-trace's LocalRay::hit_box; returns t_near or -1.
float slab_near(vec3 org, vec3 dir, vec3 bmin, vec3 bmax, float t_min, float t_max) {
    vec3 inv = 1.0 / dir;
    vec3 n = (bmin - org) * inv;
    vec3 f = (bmax - org) * inv;
    vec3 lo = min(n, f);
    vec3 hi = max(n, f) * 1.0000004;
    float t0 = max(max(max(t_min, lo.x), lo.y), lo.z);
    float t1 = min(min(min(t_max, hi.x), hi.y), hi.z);
    return t0 <= t1 ? t0 : -1.0;
}

uint hash_u32(uint v) {
    uint state = v * 747796405u + 2891336453u;
    uint word = ((state >> ((state >> 28u) + 4u)) ^ state) * 277803737u;
    return (word >> 22u) ^ word;
}

float pixel_dither(uint x, uint y) {
    return float(hash_u32((x * 0x8da6b343u) ^ (y * 0xd8163841u)) >> 8u) / 16777216.0;
}

vec3 id_colour(uint mesh, uint primitive) {
    uint h = hash_u32(hash_u32(mesh) ^ primitive);
    return vec3(0.15) + 0.85 * vec3(float(h & 0xffu), float((h >> 8u) & 0xffu),
                                    float((h >> 16u) & 0xffu)) / 255.0;
}

vec3 lod_colour(uint level) {
    const vec3 palette[8] = vec3[8](vec3(0.1, 0.8, 0.1), vec3(0.1, 0.4, 0.9), vec3(0.9, 0.8, 0.1),
                                    vec3(0.9, 0.4, 0.1), vec3(0.8, 0.1, 0.1), vec3(0.7, 0.1, 0.8),
                                    vec3(0.1, 0.8, 0.8), vec3(0.6, 0.6, 0.6));
    return palette[level % 8u];
}

vec3 sky(vec3 dir) {
    float t = 0.5 * (clamp(dir.y, -1.0, 1.0) + 1.0);
    return vec3(0.55 + 0.25 * t, 0.65 + 0.2 * t, 0.8 + 0.15 * t) * 0.8;
}

uint encode_srgb8(vec3 c) {
    uvec3 b;
    for (int i = 0; i < 3; ++i) {
        float v = clamp(c[i], 0.0, 1.0);
        float s = v <= 0.0031308 ? 12.92 * v : 1.055 * pow(v, 1.0 / 2.4) - 0.055;
        b[i] = uint(s * 255.0 + 0.5);
    }
    return b.x | (b.y << 8u) | (b.z << 16u) | (255u << 24u);
}

// Wächter & Binder's offset after a push of 2^-18 × `reach` along n, mirrored from
// motu_trace::render::shadow_offset. `reach` (largest |origin| component + hit distance) bounds
// the error of p = origin + t·dir, which W&B alone (made for exact p) does not cover: without it
// far hits on a plane at y = 0 shadowed themselves (speckled ground at 1080p).
vec3 shadow_offset(vec3 p_in, vec3 n, float reach) {
    precise vec3 p = p_in + n * (reach * (1.0 / 262144.0));
    precise vec3 o;
    for (int a = 0; a < 3; ++a) {
        if (abs(p[a]) < 1.0 / 32.0) {
            o[a] = p[a] + (1.0 / 65536.0) * n[a];
        } else {
            int of = int(256.0 * n[a]);
            int bits = floatBitsToInt(p[a]);
            o[a] = intBitsToFloat(p[a] < 0.0 ? bits - of : bits + of);
        }
    }
    return o;
}
#endif
