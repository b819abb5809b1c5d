// Pipeline backend, streamed: a ray's nearest open entry so far where the proxy intersection
// shader (pipeline/proxy_stream.rint) can read it. An intersection shader may not read the
// payload, where record_proxy keeps that entry (Payload.open_t), so it tested the members of
// every proxy box in front of the committed triangle: for an open ray (no resident hit in
// front of its open structures) every box to the far end of the walk, most of them behind the
// nearest open one, where record_proxy changes nothing. So raygen writes each walk's starting
// bound into the launch item's word before tracing it (`open_bound_publish`: the payload's
// open_t, T_INFINITY for a mark walk, which marks every box in front of its hit, -1 for a
// guard ray's first walk, which records none), the proxy any-hit lowers it with the payload
// (`open_bound_lower`), and the intersection shader reports only boxes whose members the ray
// may enter before min(committed triangle, bound).
//
// Why that skips no box the any-hit would use: record_proxy keeps an entry only before the
// payload's open_t, and every value the word takes during a walk is >= that open_t at that
// moment (it starts equal and only falls, always to a value open_t takes; a guard ray's first
// walk records nothing); quantised member boxes contain the exact ones (proxy_may_open), and
// both tests only pass more with a larger bound. An earlier walk's value is never read: the
// word is written and read with atomics at ShaderCallKHR scope, and raygen's release barrier
// before traceRayEXT synchronizes with the intersection shader's acquire barrier (shader-call
// order, Vulkan memory model), as the any-hit's release with raygen's next acquire; a lowering
// the intersection shader does not see yet only costs tests.
//
// Where: launch item i's word is word CARRY_OPEN_BOUND_WORD of carry slot i (common.glsl), for
// items below the image's pixel count (the carry has a slot per pixel; guard-band items beyond
// it read no bound and test as before). One ray at a time per item.
#ifndef MOTU_OPEN_BOUND_GLSL
#define MOTU_OPEN_BOUND_GLSL
#extension GL_KHR_memory_scope_semantics : require
#include "common.glsl"

layout(buffer_reference, std430, buffer_reference_align = 4) buffer OpenBoundWords { uint r[]; };

// Whether this invocation's launch item has a word: the pass bounds open rays
// (STREAM_OPEN_BOUND) and the item lies below the pixel count. Its index in `slot`.
bool open_bound_slot(StreamParams s, out uint slot) {
    slot = gl_LaunchIDEXT.y * gl_LaunchSizeEXT.x + gl_LaunchIDEXT.x;  // = the launch item
    CameraParams cam = push.frame.f.camera;
    return (s.flags & STREAM_OPEN_BOUND) != 0u && slot < cam.width * cam.height;
}

void open_bound_store(StreamParams s, uint slot, float t) {
    atomicStore(OpenBoundWords(s.carry).r[slot * CARRY_WORDS + CARRY_OPEN_BOUND_WORD],
                floatBitsToUint(t), gl_ScopeShaderCallEXT, gl_StorageSemanticsBuffer,
                gl_SemanticsRelaxed);
}

// Raygen, before each traceRayEXT of a streamed walk (`stream_start`: Payload.stream_start,
// `open_t`: the walk's starting Payload.open_t).
void open_bound_publish(uint stream_start, float open_t) {
    StreamParams s = StreamRef(push.stream).s;
    uint slot;
    if (!open_bound_slot(s, slot)) {
        return;
    }
    float t = open_t;
    if ((stream_start & STREAM_MARK_WALK) != 0u) {
        t = T_INFINITY;
    } else if ((stream_start & STREAM_GUARD_RAY) != 0u) {
        t = -1.0;
    }
    memoryBarrier(gl_ScopeShaderCallEXT, gl_StorageSemanticsBuffer, gl_SemanticsAcquireRelease);
    open_bound_store(s, slot, t);
    memoryBarrier(gl_ScopeShaderCallEXT, gl_StorageSemanticsBuffer, gl_SemanticsRelease);
}

// The proxy any-hit, after record_proxy lowered Payload.open_t to `open_t`.
void open_bound_lower(StreamParams s, float open_t) {
    uint slot;
    if (open_bound_slot(s, slot)) {
        open_bound_store(s, slot, open_t);
        memoryBarrier(gl_ScopeShaderCallEXT, gl_StorageSemanticsBuffer, gl_SemanticsRelease);
    }
}

// The proxy intersection shader: the bound of the walk it runs in (T_INFINITY: none).
float open_bound_read(StreamParams s) {
    uint slot;
    if (!open_bound_slot(s, slot)) {
        return T_INFINITY;
    }
    memoryBarrier(gl_ScopeShaderCallEXT, gl_StorageSemanticsBuffer, gl_SemanticsAcquire);
    uint w = atomicLoad(OpenBoundWords(s.carry).r[slot * CARRY_WORDS + CARRY_OPEN_BOUND_WORD],
                        gl_ScopeShaderCallEXT, gl_StorageSemanticsBuffer, gl_SemanticsRelaxed);
    return uintBitsToFloat(w);
}
#endif
