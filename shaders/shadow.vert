// Shadow pass, vertex stage: the scene's world-space triangles (three vec4 per triangle,
// read by gl_VertexIndex from a storage buffer) through one shadow view's matrix.
// direct/direct_light.cpp (RasterShadowMaps) is the CPU twin.
#version 450

layout(std430, binding = 0) readonly buffer Vertices { vec4 vertices[]; };

layout(push_constant) uniform Push {
    mat4 viewProj;
    uint mapOffset;  // first texel of this view's map
    uint size;       // texels per side
} pc;

void main() { gl_Position = pc.viewProj * vec4(vertices[gl_VertexIndex].xyz, 1.0); }
