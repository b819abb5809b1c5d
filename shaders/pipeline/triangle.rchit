#version 460
// Closest hit on (opaque) triangles: record what raygen needs to resolve the hit.
#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_ray_tracing : require
#include "common.glsl"

layout(location = 0) rayPayloadInEXT Payload pl;

void main() {
    pl.hit_t = gl_HitTEXT;
    pl.hit_instance = gl_InstanceCustomIndexEXT;  // the local instance index (streamed TLASes hold a subset)
    pl.hit_geometry = gl_GeometryIndexEXT;
    pl.hit_primitive = gl_PrimitiveID;
}
