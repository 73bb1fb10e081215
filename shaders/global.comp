// Global pass (operator U, Eqs. 15–17 with the σ spreading of Sec. 3.1): one invocation
// per receiver gathers F · w · I_ex[sender][bin] over its links into L_in. Receivers come
// sorted by link count so the lanes of a workgroup finish together.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 0) readonly buffer LinkOffsets { uint linkOffsets[]; };
layout(std430, binding = 1) readonly buffer Links { Link links[]; };
layout(std430, binding = 2) readonly buffer NeighbourOffsets { uint neighbourOffsets[]; };
layout(std430, binding = 3) readonly buffer Neighbours { BinWeight neighbours[]; };
layout(std430, binding = 4) readonly buffer Iex { float iex[]; };
layout(std430, binding = 5) writeonly buffer Lin { float lin[]; };
layout(std430, binding = 6) readonly buffer Receivers { uint receivers[]; };

layout(push_constant) uniform Push { uint count; } pc;

vec3 acc[BINS];

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) return;
    uint r = receivers[i];
    for (uint b = 0; b < BINS; ++b) acc[b] = vec3(0.0);
    uint end = linkOffsets[r + 1];
    for (uint l = linkOffsets[r]; l < end; ++l) {
        Link link = links[l];
        uint bin = link.binLevel & 0xffffu;
        uint level = link.binLevel >> 16;
        uint s = (link.sender * BINS + bin) * 3u;
        vec3 v = link.formFactor * vec3(iex[s], iex[s + 1u], iex[s + 2u]);
        uint o = level * (BINS + 1u) + bin;
        uint nEnd = neighbourOffsets[o + 1u];
        for (uint j = neighbourOffsets[o]; j < nEnd; ++j) {
            BinWeight nb = neighbours[j];
            acc[nb.bin] += nb.weight * v;
        }
    }
    uint row = r * BINS * 3u;
    for (uint b = 0; b < BINS; ++b) {
        lin[row + b * 3u] = acc[b].x;
        lin[row + b * 3u + 1u] = acc[b].y;
        lin[row + b * 3u + 2u] = acc[b].z;
    }
}
