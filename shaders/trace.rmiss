#version 460
// The ray met nothing (trace.rgen).
#extension GL_EXT_ray_tracing : require

struct Hit {
    uint triangle;
    float t, u, v;
};
layout(location = 0) rayPayloadInEXT Hit payload;

void main() { payload.triangle = 0xFFFFFFFFu; }
