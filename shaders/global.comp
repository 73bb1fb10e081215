// Global pass (operator U, Eqs. 15–17 with the σ spreading of Sec. 3.1): one invocation
// per receiver gathers F · w · I_ex[sender][bin] over its links into L_in. Receivers come
// sorted by link count so the lanes of a workgroup finish together. Links, spread lists and
// I_ex are read through texel buffers: random per-lane reads that lavapipe gathers in vector
// registers (gpu/pipeline.h, Slot).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 0) readonly buffer LinkOffsets { uint linkOffsets[]; };
// Link (common.glsl) as three uints: sender, binLevel, formFactor bits.
layout(binding = 1) uniform usamplerBuffer links;
// Directions::Padded*: level k's list for bin b is spread[k].x + b·spread[k].y, width
// spread[k].y (uvec2 as two uints).
layout(binding = 2) uniform usamplerBuffer spread;
// BinWeight (common.glsl) as two uints: bin, weight bits.
layout(binding = 3) uniform usamplerBuffer neighbours;
layout(binding = 4) uniform samplerBuffer iex;
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
        uint sender = 0u, binLevel = 0u;
        float formFactor = 0.0;
        if (l < end) {
            sender = texelFetch(links, int(3u * l)).x;
            binLevel = texelFetch(links, int(3u * l + 1u)).x;
            formFactor = uintBitsToFloat(texelFetch(links, int(3u * l + 2u)).x);
        }
        if (l == end || binLevel != key) {
            if (key != 0xffffffffu) {
                uint level = key >> 16;
                uint width = texelFetch(spread, int(2u * level + 1u)).x;
                uint first = texelFetch(spread, int(2u * level)).x + (key & 0xffffu) * width;
                for (uint j = first; j < first + width; ++j) {
                    uint a = texelFetch(neighbours, int(2u * j)).x * 3u;
                    float weight = uintBitsToFloat(texelFetch(neighbours, int(2u * j + 1u)).x);
                    acc[a] += weight * v.x;
                    acc[a + 1u] += weight * v.y;
                    acc[a + 2u] += weight * v.z;
                }
            }
            if (l == end) break;
            key = binLevel;
            v = vec3(0.0);
        }
        int s = int((sender * BINS + (binLevel & 0xffffu)) * 3u);
        v += formFactor * vec3(texelFetch(iex, s).x, texelFetch(iex, s + 1).x, texelFetch(iex, s + 2).x);
    }
    uint row = r * (BINS * 3u / 4u);
    for (uint q = 0u; q < BINS * 3u / 4u; ++q)
        lin[row + q] = vec4(acc[4u * q], acc[4u * q + 1u], acc[4u * q + 2u], acc[4u * q + 3u]);
}
