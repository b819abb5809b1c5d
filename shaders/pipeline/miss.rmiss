#version 460
// Miss: nothing to record (raygen set hit_t = -1 before the trace).
#extension GL_EXT_ray_tracing : require

void main() {
}
