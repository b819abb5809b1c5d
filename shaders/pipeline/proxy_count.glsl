// Pipeline backend, streamed, counting mode (COUNT_PROXY, common.glsl): the launch item's
// words where the proxy intersection and any-hit shaders add what the item's current ray
// costs, since neither may write the payload in the intersection shader's case. Raygen takes
// them after each ray (traverse.glsl `proxy_count_ray`, through `backend_proxy_take`). One ray
// at a time per item; atomics, as the shaders of one trace may run apart from raygen.
#ifndef MOTU_PROXY_COUNT_GLSL
#define MOTU_PROXY_COUNT_GLSL
#include "common.glsl"

uint proxy_item_word() {
    uint item = gl_LaunchIDEXT.y * gl_LaunchSizeEXT.x + gl_LaunchIDEXT.x;
    return PROXY_COUNT_BASE + PROXY_COUNT_WORDS + PROXY_ITEM_WORDS * item;
}

// Adds to the item's words: intersection-shader calls, reports, quantised and exact member
// tests.
void proxy_count_item(uint calls, uint reports, uint members, uint exact) {
    uint w = proxy_item_word();
    if (calls != 0u) {
        atomicAdd(push.stats.n[w], calls);
    }
    if (reports != 0u) {
        atomicAdd(push.stats.n[w + 1u], reports);
    }
    if (members != 0u) {
        atomicAdd(push.stats.n[w + 2u], members);
    }
    if (exact != 0u) {
        atomicAdd(push.stats.n[w + 3u], exact);
    }
}
#endif
