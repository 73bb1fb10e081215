#version 460
// The nearest hit (trace.rgen): the triangle, the distance along the ray and the
// barycentrics of its second and third corners, as Embree's (u, v) of p0 + u·e1 + v·e2.
#extension GL_EXT_ray_tracing : require

struct Hit {
    uint triangle;
    float t, u, v;
};
layout(location = 0) rayPayloadInEXT Hit payload;
hitAttributeEXT vec2 barycentrics;

void main() { payload = Hit(uint(gl_PrimitiveID), gl_HitTEXT, barycentrics.x, barycentrics.y); }
