// Instance-level LOD (motu_abi::lod_instance): per slot, the level the host picked for this
// frame's camera (InstanceLod::levels, the CPU oracle's rule, so both agree exactly); the
// slot's TLAS instances (VkAccelerationStructureInstanceKHR) of that level get their BLAS
// addresses, the other levels' are made inactive (address 0, mask 0). The host rebuilds the
// slots' TLASes after this pass.
#version 460
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_GOOGLE_include_directive : require
#include "lod.glsl"

layout(local_size_x = 64) in;

// VkAccelerationStructureInstanceKHR: 64 bytes.
struct VkInstance {
    vec4 r0;
    vec4 r1;
    vec4 r2;
    uint custom_mask;  // custom index (low 24 bits) | mask << 24
    uint sbt_flags;    // SBT offset (low 24 bits) | flags << 24
    uint64_t reference;
};

layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer TlasTable { TlasRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer InstanceTable { InstanceRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer SelectorTable { LodSelectorRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 4) readonly buffer U32Table { uint r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) readonly buffer SlotTable { LodSlotRecord r[]; };
layout(buffer_reference, std430, buffer_reference_align = 8) readonly buffer U64Table { uint64_t r[]; };
layout(buffer_reference, std430, buffer_reference_align = 16) buffer VkInstanceTable { VkInstance r[]; };

// Rust: motu-gpu's lod_instances.rs `Push` (80 bytes).
layout(push_constant) uniform Push {
    U32Table levels;            // the frame's level per slot
    TlasTable tlases;
    InstanceTable instances;
    SelectorTable selectors;
    U32Table lod_levels;
    SlotTable slots;
    U64Table blas_addresses;    // per BLAS id, 0 where none is built
    VkInstanceTable vk_instances;  // instance `lod_instance_base + i` is entry i
    uint slot_count;
    uint lod_instance_base;
    uint refit;  // 1: every level stays active (an update may not change that): the unchosen
                 // keep their BLAS address but shrink to a point and are masked out
    uint pad_;
} push;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= push.slot_count) {
        return;
    }
    LodSlotRecord slot = push.slots.r[i];
    LodSelectorRecord sel = push.selectors.r[slot.selector];
    uint level = push.levels.r[i];
    // The slot holds every level's BLASes in order: only the chosen level's are active.
    uint gi = slot.instance;
    for (uint l = 0u; l < sel.level_count; ++l) {
        uint n = push.tlases.r[push.lod_levels.r[sel.level_base + l]].instance_count;
        for (uint j = 0u; j < n; ++j) {
            InstanceRecord ir = push.instances.r[gi];
            uint64_t blas = push.blas_addresses.r[ir.blas];
            uint64_t addr = (l == level || push.refit != 0u) ? blas : 0ul;
            uint vi = gi - push.lod_instance_base;
            // Keep the custom index (the instance's index in its TLAS, which the hit shaders
            // read); only the mask switches the level on or off.
            uint custom = push.vk_instances.r[vi].custom_mask & 0xFFFFFFu;
            bool on = l == level && blas != 0ul;
            push.vk_instances.r[vi].custom_mask = custom | (on ? (0xFFu << 24) : 0u);
            push.vk_instances.r[vi].reference = addr;
            if (push.refit != 0u) {
                // An update may not make an instance inactive, so an unchosen level stays
                // active but shrinks to a point at its origin (and is masked out): the refit
                // tree keeps only the chosen level's box.
                float k = on ? 1.0 : 0.0;
                float m[12] = ir.tlas_from_blas;
                push.vk_instances.r[vi].r0 = vec4(k * m[0], k * m[1], k * m[2], m[3]);
                push.vk_instances.r[vi].r1 = vec4(k * m[4], k * m[5], k * m[6], m[7]);
                push.vk_instances.r[vi].r2 = vec4(k * m[8], k * m[9], k * m[10], m[11]);
            }
            gi += 1u;
        }
    }
}
