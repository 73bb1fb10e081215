// The light field's radiance-interface walk on a device (solvers/lightfield/vulkan_walk.h;
// WalkBatch in lines.cpp is the CPU twin): one invocation a line of a group of directions,
// front to back along +d then back to front along −d (Mortensen et al. 2008, Sec. 3.2). A
// surface facing along the travel overwrites the interface with its exitant radiance (its
// three surfels' by their hat weights, plus a glossy surfel's exitant along that column); one
// facing against it receives the interface, and its black back follows. What a surfel
// receives is added with float atomics to its (column, surfel) sums: Σ φ L_I and Σ φ.
#version 450
#extension GL_EXT_shader_atomic_float : require

layout(local_size_x = 64) in;

layout(std430, binding = 0) readonly buffer Hits { uvec2 hits[]; };  // triangle|along, u|v<<16
layout(std430, binding = 1) readonly buffer LineHits { uint lineHits[]; };   // lines + 1
layout(std430, binding = 2) readonly buffer LineDirs { uint lineDirection[]; };
layout(std430, binding = 3) readonly buffer Corners { uvec4 corners[]; };  // per triangle
layout(std430, binding = 4) readonly buffer Radiances { vec4 radiance[]; };  // per surfel
layout(std430, binding = 5) readonly buffer Sky { vec4 sky[]; };  // per column (2 × directions)
layout(std430, binding = 6) buffer Sums { float sums[]; };  // (local column, surfel) × 4
layout(std430, binding = 7) readonly buffer Slots { int slot[]; };  // per surfel: glossy or −1
layout(std430, binding = 8) readonly buffer GlossyExitant { vec4 exitant[]; };  // slot × columns

layout(push_constant) uniform Push {
    uint firstLine;       // the group's first line
    uint lineCount;
    uint directions;      // the batch's (columns = 2 × directions)
    uint surfels;
    uint firstDirection;  // the group's
    uint group;           // directions in the group
    uint glossy;          // 1: slot and exitant are read
} pc;

vec3 Weights(uint uv) {
    const float u = float(uv & 0xffffu) / 65535.0, v = float(uv >> 16) / 65535.0;
    return vec3(1.0 - u - v, u, v);
}

vec3 Exitant(uvec2 h, uint column) {
    const uvec4 c = corners[h.x & 0x7fffffffu];
    const vec3 w = Weights(h.y);
    vec3 l = w.x * radiance[c.x].xyz + w.y * radiance[c.y].xyz + w.z * radiance[c.z].xyz;
    if (pc.glossy != 0u)
        for (int k = 0; k < 3; ++k) {
            const int g = slot[c[k]];
            if (g >= 0) l += w[k] * exitant[uint(g) * 2u * pc.directions + column].xyz;
        }
    return l;
}

void Receive(uvec2 h, uint localColumn, vec3 l) {
    const uvec4 c = corners[h.x & 0x7fffffffu];
    const vec3 w = Weights(h.y);
    for (int k = 0; k < 3; ++k) {
        if (w[k] <= 0.0) continue;
        const uint base = (localColumn * pc.surfels + c[k]) * 4u;
        atomicAdd(sums[base], w[k] * l.x);
        atomicAdd(sums[base + 1u], w[k] * l.y);
        atomicAdd(sums[base + 2u], w[k] * l.z);
        atomicAdd(sums[base + 3u], w[k]);
    }
}

void main() {
    if (gl_GlobalInvocationID.x >= pc.lineCount) return;
    const uint line = pc.firstLine + gl_GlobalInvocationID.x;
    const uint k = lineDirection[line];
    const uint local = k - pc.firstDirection;
    const uint begin = lineHits[line], end = lineHits[line + 1u];
    // Along +d (column k): the sky's light from −d first.
    vec3 l = sky[k].xyz;
    for (uint i = begin; i < end; ++i) {
        const uvec2 h = hits[i];
        if ((h.x & 0x80000000u) != 0u) {
            l = Exitant(h, k);
        } else {
            Receive(h, local, l);
            l = vec3(0.0);
        }
    }
    // Along −d (column directions + k): the roles swap.
    l = sky[pc.directions + k].xyz;
    for (uint i = end; i-- > begin;) {
        const uvec2 h = hits[i];
        if ((h.x & 0x80000000u) != 0u) {
            Receive(h, pc.group + local, l);
            l = vec3(0.0);
        } else {
            l = Exitant(h, pc.directions + k);
        }
    }
}
