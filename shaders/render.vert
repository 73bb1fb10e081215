// `penumbra render`, vertex stage: world-space vertices (position, colour and normal as three
// vec4, read by gl_VertexIndex) through the camera's matrix. The colour is the vertex's shaded
// radiance (or heat-map colour), computed on the host; the raster interpolates it.
#version 450

struct Vertex {
    vec4 position;  // xyz
    vec4 color;     // rgb
    vec4 normal;    // xyz: the side the surface lights and is lit on
};
layout(std430, binding = 0) readonly buffer Vertices { Vertex vertices[]; };

layout(push_constant) uniform Push {
    mat4 viewProj;
    vec4 eye;  // xyz: the camera's position
} pc;

layout(location = 0) out vec3 color;
layout(location = 1) out vec3 normal;
layout(location = 2) out vec3 toEye;

void main() {
    Vertex v = vertices[gl_VertexIndex];
    color = v.color.rgb;
    normal = v.normal.xyz;
    toEye = pc.eye.xyz - v.position.xyz;
    gl_Position = pc.viewProj * vec4(v.position.xyz, 1.0);
}
