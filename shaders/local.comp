// Leaf pass: the gather of each leaf (gather.glsl: its parent's L_in row + its own links)
// and the local pass (Sec. 3.1) on that row without it leaving the invocation. K reflects
// incident radiance into the front hemisphere (Eq. 18, diffuse: I_L = a⟨n|ω⟩(L_e +
// ρ(E + E_d)/π), E_d the shadow-mapped direct light of Sec. 3.3, which makes no
// antiradiance), J sends it through the back hemisphere as antiradiance (Eq. 19:
// I_A = a⟨n|−ω⟩L_in). I_ex = I_L − I_A.
// Glossy leaves add their lobe's share of Eq. 18 (cpu_passes.cpp, GlossyReflection: keep
// the arithmetic in step): incoming light gathered at the mirror bin of each incoming bin,
// then every outgoing bin reads its lobe row there.
// Leaves come sorted by link count so the lanes of a workgroup finish their gathers together.
// The pipeline is specialised per mode (kReflect | kAntiradiance) and for glossy leaves:
// diffuse leaves run a variant without the lobe's code (lavapipe runs both sides of a
// branch, so code a leaf does not need costs it anyway).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"
#include "gather.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 6) readonly buffer Leaves { Leaf leaves[]; };
layout(binding = 7) uniform samplerBuffer dirs;  // xyz_ per bin
layout(std430, binding = 8) writeonly buffer IexNew { float iexNew[]; };
layout(std430, binding = 9) writeonly buffer Irradiance { float irradiance[]; };
layout(binding = 10) uniform samplerBuffer direct;  // rgb_ per leaf
layout(std430, binding = 11) readonly buffer Glossy { GlossyLeaf glossy[]; };
layout(binding = 12) uniform usamplerBuffer mirror;
layout(std430, binding = 13) readonly buffer Lobes { Lobe lobes[]; };
layout(binding = 14) uniform usamplerBuffer lobeWeights;   // BinWeight as two uints
layout(binding = 15) uniform samplerBuffer glossyDirect;  // rgb_ per glossy leaf and bin
layout(std430, binding = 16) readonly buffer Order { uint order[]; };  // leaf indices

layout(constant_id = 2) const uint MODE = 3;      // kReflect | kAntiradiance
layout(constant_id = 3) const bool GLOSSY = true;  // false: every leaf of the dispatch is diffuse

// order[first .. first + count) are this dispatch's leaves. envRow: the L_in table's
// environment row (a single-surfel scene's leaf starts there).
layout(push_constant) uniform Push { uint first; uint count; float binSolidAngle; uint envRow; } pc;

const float kInvPi = 0.31830988618379067;

// Light arriving at the front of a glossy leaf, summed at the mirror bin of each bin.
vec3 arrived[BINS];
// ⟨n|ω_b⟩ per bin.
float cosines[BINS];

vec3 Fetch3(samplerBuffer table, uint k) {
    int i = int(k);
    return vec3(texelFetch(table, i).x, texelFetch(table, i + 1).x, texelFetch(table, i + 2).x);
}
float Cos(vec3 normal, uint bin) { return dot(normal, Fetch3(dirs, 4u * bin)); }
// The gathered L_in of bin b.
vec3 In(uint b) { return vec3(acc[3u * b], acc[3u * b + 1u], acc[3u * b + 2u]); }
// What a leaf blocks and sends on as antiradiance: L_in at zero or above (docs/SOLVER.md
// "Stability"; LocalLeaf in cpu_walk.h, with E ≥ 0 below).
vec3 Blocked(uint b) { return max(In(b), vec3(0.0)); }

void main() {
    uint invocation = gl_GlobalInvocationID.x;
    if (invocation >= pc.count) return;
    uint i = order[pc.first + invocation];
    Leaf leaf = leaves[i];
    uint row = leaf.node * BINS * 3u;
    StartFrom(min(leaf.parent, pc.envRow));
    Gather(leaf.node);

    // Irradiance E = ω_bin Σ ⟨n|−ω_l⟩ L_in(ω_l) over bins arriving at the front.
    vec3 e = vec3(0.0);
    for (uint b = 0; b < BINS; ++b) {
        float c = Cos(leaf.normal, b);
        cosines[b] = c;
        if (c < 0.0) e -= c * In(b);
    }
    e = max(e * (pc.binSolidAngle * leaf.cosNormIn), vec3(0.0));
    irradiance[i * 3u] = e.x;
    irradiance[i * 3u + 1u] = e.y;
    irradiance[i * 3u + 2u] = e.z;

    vec3 front = leaf.area * leaf.cosNormOut *
                 (leaf.emission + leaf.albedo * (e + Fetch3(direct, 4u * i)) * kInvPi);
    bool glossyLeaf = GLOSSY && (leaf.flags & kLeafGlossy) != 0u && (MODE & kReflect) != 0u;
    uint g = leaf.flags >> kGlossyShift;
    Lobe lobe = Lobe(0u, 0u, 0.0, 0.0);
    vec3 f0 = vec3(0.0);
    if (glossyLeaf) {
        for (uint b = 0; b < BINS; ++b) arrived[b] = vec3(0.0);
        for (uint l = 0; l < BINS; ++l) {
            float c = cosines[l];
            if (c < 0.0) arrived[texelFetch(mirror, int(g * BINS + l)).x] -= c * In(l);
        }
        lobe = lobes[glossy[g].lobe];
        f0 = leaf.area * glossy[g].specular;
    }
    for (uint b = 0; b < BINS; ++b) {
        float c = cosines[b];
        uint k = row + b * 3u;
        vec3 v;
        if (c > 0.0) {
            // A two-sided leaf sends light arriving at its back on through its front.
            vec3 through =
                (leaf.flags & kLeafTwoSided) != 0u ? leaf.area * c * Blocked(b) : vec3(0.0);
            v = (MODE & kReflect) != 0u ? c * front - through : Fetch3(iex, k);
            if (glossyLeaf) {
                vec3 sum = vec3(0.0);
                uint start = lobe.start + b * lobe.width;
                for (uint w = 0; w < lobe.width; ++w) {
                    int at = int(2u * (start + w));
                    sum += uintBitsToFloat(texelFetch(lobeWeights, at + 1).x) *
                           arrived[texelFetch(lobeWeights, at).x];
                }
                v += c * f0 * (pc.binSolidAngle * sum + Fetch3(glossyDirect, 4u * (g * BINS + b)));
            }
        } else {
            v = (MODE & kAntiradiance) != 0u ? leaf.area * c * Blocked(b) : Fetch3(iex, k);
        }
        iexNew[k] = v.x;
        iexNew[k + 1u] = v.y;
        iexNew[k + 2u] = v.z;
    }
}
