// A streamed TLAS rebuild's instance records from the records kept on the GPU
// (motu_abi::tlas_compact; motu-gpu's stream/tlas_compact.rs runs it): for each instance whose
// BLAS is resident, its kept record with the BLAS's device address, in instance order. One
// workgroup per chunk of TLAS_COMPACT_CHUNK instances; the host gave each chunk its first
// output record (prefix sums of its resident counts); inside a chunk each invocation places
// its TLAS_COMPACT_PER_THREAD instances after an exclusive scan of the invocations' counts.
// No atomics: the same residency always gives the same buffer (the host path's).
#version 460
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_buffer_reference_uvec2 : require
#extension GL_GOOGLE_include_directive : require
#include "generated/abi.glsl"

layout(local_size_x = TLAS_COMPACT_GROUP) in;

// A record (VkAccelerationStructureInstanceKHR) is 4 uvec4; the address is the last one's zw.
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer KeptRecords { uvec4 v[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) writeonly buffer OutRecords { uvec4 v[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer U32Table { uint v[]; };
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer U64Table { uvec2 v[]; };

layout(push_constant) uniform Push {
    TlasCompactPush p;
} push;

shared uint scan[TLAS_COMPACT_GROUP];

void main() {
    uint t = gl_LocalInvocationID.x;
    uint chunk = gl_WorkGroupID.x;
    uint first = chunk * uint(TLAS_COMPACT_CHUNK) + t * uint(TLAS_COMPACT_PER_THREAD);
    KeptRecords kept = KeptRecords(push.p.kept);
    U64Table addresses = U64Table(push.p.blas_addresses);
    uvec2 addr[TLAS_COMPACT_PER_THREAD];
    uint n = 0u;
    for (uint k = 0u; k < uint(TLAS_COMPACT_PER_THREAD); ++k) {
        uint i = first + k;
        addr[k] = uvec2(0u);
        if (i < push.p.instance_count) {
            addr[k] = addresses.v[kept.v[4u * i + 3u].z];
            n += (addr[k] != uvec2(0u)) ? 1u : 0u;
        }
    }
    // Inclusive scan of the invocations' counts (Hillis-Steele), then exclusive by `- n`.
    scan[t] = n;
    barrier();
    for (uint off = 1u; off < uint(TLAS_COMPACT_GROUP); off <<= 1u) {
        uint add = t >= off ? scan[t - off] : 0u;
        barrier();
        scan[t] += add;
        barrier();
    }
    uint at = U32Table(push.p.chunk_first).v[chunk] + scan[t] - n;
    OutRecords dst = OutRecords(push.p.dst);
    for (uint k = 0u; k < uint(TLAS_COMPACT_PER_THREAD); ++k) {
        if (addr[k] == uvec2(0u)) {
            continue;
        }
        uint i = first + k;
        dst.v[4u * at] = kept.v[4u * i];
        dst.v[4u * at + 1u] = kept.v[4u * i + 1u];
        dst.v[4u * at + 2u] = kept.v[4u * i + 2u];
        uvec4 last = kept.v[4u * i + 3u];
        dst.v[4u * at + 3u] = uvec4(last.xy, addr[k]);
        at += 1u;
    }
}
