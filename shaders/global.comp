// Global pass (operator U, Eqs. 15–17 with the σ spreading of Sec. 3.1): one invocation
// per receiver gathers F · w · I_ex[sender][bin] over its links into L_in. Receivers come
// sorted by link count so the lanes of a workgroup finish together.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 0) readonly buffer LinkOffsets { uint linkOffsets[]; };
layout(std430, binding = 1) readonly buffer Links { Link links[]; };
// Directions::Padded*: level k's list for bin b is spread[k].x + b·spread[k].y, width spread[k].y.
layout(std430, binding = 2) readonly buffer SpreadLevels { uvec2 spread[]; };
layout(std430, binding = 3) readonly buffer Neighbours { BinWeight neighbours[]; };
layout(std430, binding = 4) readonly buffer Iex { float iex[]; };
layout(std430, binding = 5) writeonly buffer Lin { vec4 lin[]; };  // rows of BINS·3/4 vec4
layout(std430, binding = 6) readonly buffer Receivers { uint receivers[]; };
// Environment radiance per bin (RGB): the root's L_in starts from it (Sec. 3.3).
layout(std430, binding = 7) readonly buffer Environment { float environment[]; };

layout(push_constant) uniform Push { uint count; } pc;

float acc[BINS * 3u];

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) return;
    uint r = receivers[i];
    for (uint k = 0u; k < BINS * 3u; ++k) acc[k] = r == 0u ? environment[k] : 0.0;
    uint end = linkOffsets[r + 1];
    // Links come sorted by (level, bin): sum a run of equal (level, bin) and spread once.
    uint key = 0xffffffffu;
    vec3 v = vec3(0.0);
    for (uint l = linkOffsets[r]; l <= end; ++l) {
        Link link;
        if (l < end) link = links[l];
        if (l == end || link.binLevel != key) {
            if (key != 0xffffffffu) {
                uvec2 level = spread[key >> 16];
                uint first = level.x + (key & 0xffffu) * level.y;
                for (uint j = first; j < first + level.y; ++j) {
                    BinWeight nb = neighbours[j];
                    uint a = nb.bin * 3u;
                    acc[a] += nb.weight * v.x;
                    acc[a + 1u] += nb.weight * v.y;
                    acc[a + 2u] += nb.weight * v.z;
                }
            }
            if (l == end) break;
            key = link.binLevel;
            v = vec3(0.0);
        }
        uint s = (link.sender * BINS + (link.binLevel & 0xffffu)) * 3u;
        v += link.formFactor * vec3(iex[s], iex[s + 1u], iex[s + 2u]);
    }
    uint row = r * (BINS * 3u / 4u);
    for (uint q = 0u; q < BINS * 3u / 4u; ++q)
        lin[row + q] = vec4(acc[4u * q], acc[4u * q + 1u], acc[4u * q + 2u], acc[4u * q + 3u]);
}
