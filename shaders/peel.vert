// Light-field lines by depth peeling (solvers/lightfield/vulkan_lines.h), vertex stage: the
// refined mesh's triangles (three vec4 a triangle, in RayScene order, read by gl_VertexIndex)
// through one direction's orthographic view, whose pixel centres are the direction's lines.
// The triangle's number and Embree's barycentrics (u weighs its second corner, v its third)
// go to the fragment stage.
#version 450

layout(std430, binding = 0) readonly buffer Vertices { vec4 vertices[]; };

layout(push_constant) uniform Push {
    mat4 view;            // world → (x, y) in NDC, z = distance along the lines / length
    uint layer;           // 0: the nearest surfaces; k: those behind layer k − 1
    uint size;            // cells a side
    uint previousOffset;  // first texel of layer k − 1 in binding 1
} pc;

layout(location = 0) flat out uint triangle;
layout(location = 1) noperspective out vec2 bary;

void main() {
    gl_Position = pc.view * vec4(vertices[gl_VertexIndex].xyz, 1.0);
    triangle = uint(gl_VertexIndex) / 3u;
    const uint corner = uint(gl_VertexIndex) % 3u;
    bary = vec2(corner == 1u ? 1.0 : 0.0, corner == 2u ? 1.0 : 0.0);
}
