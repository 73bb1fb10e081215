// Local pass at the leaves (Sec. 3.1): K reflects incident radiance into the front
// hemisphere (Eq. 18, diffuse: I_L = a⟨n|ω⟩(L_e + ρ(E + E_d)/π), E_d the shadow-mapped
// direct light of Sec. 3.3, which makes no antiradiance), J sends it through the back
// hemisphere as antiradiance (Eq. 19: I_A = a⟨n|−ω⟩L_in). I_ex = I_L − I_A.
// Glossy leaves add their lobe's share of Eq. 18 (cpu_passes.cpp, GlossyReflection: keep
// the arithmetic in step): incoming light gathered at the mirror bin of each incoming bin,
// then every outgoing bin reads its lobe row there.
// Tables are read through texel buffers (lavapipe gathers them; gpu/pipeline.h, Slot).
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 0) readonly buffer Leaves { Leaf leaves[]; };
layout(binding = 1) uniform samplerBuffer dirs;  // xyz_ per bin
layout(binding = 2) uniform samplerBuffer lin;
layout(binding = 3) uniform samplerBuffer iexOld;
layout(std430, binding = 4) writeonly buffer IexNew { float iexNew[]; };
layout(std430, binding = 5) writeonly buffer Irradiance { float irradiance[]; };
layout(binding = 6) uniform samplerBuffer direct;  // rgb_ per leaf
layout(std430, binding = 7) readonly buffer Glossy { GlossyLeaf glossy[]; };
layout(binding = 8) uniform usamplerBuffer mirror;
layout(std430, binding = 9) readonly buffer Lobes { Lobe lobes[]; };
layout(binding = 10) uniform usamplerBuffer lobeWeights;   // BinWeight as two uints
layout(binding = 11) uniform samplerBuffer glossyDirect;  // rgb_ per glossy leaf and bin

layout(push_constant) uniform Push { uint count; uint mode; float binSolidAngle; } pc;

const float kInvPi = 0.31830988618379067;

// Light arriving at the front of a glossy leaf, summed at the mirror bin of each bin.
vec3 arrived[BINS];

vec3 Fetch3(samplerBuffer table, uint k) {
    int i = int(k);
    return vec3(texelFetch(table, i).x, texelFetch(table, i + 1).x, texelFetch(table, i + 2).x);
}
float Cos(vec3 normal, uint bin) { return dot(normal, Fetch3(dirs, 4u * bin)); }

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) return;
    Leaf leaf = leaves[i];
    uint row = leaf.node * BINS * 3u;

    // Irradiance E = ω_bin Σ ⟨n|−ω_l⟩ L_in(ω_l) over bins arriving at the front.
    vec3 e = vec3(0.0);
    for (uint b = 0; b < BINS; ++b) {
        float c = Cos(leaf.normal, b);
        if (c < 0.0) e -= c * Fetch3(lin, row + b * 3u);
    }
    e *= pc.binSolidAngle * leaf.cosNormIn;
    irradiance[i * 3u] = e.x;
    irradiance[i * 3u + 1u] = e.y;
    irradiance[i * 3u + 2u] = e.z;

    vec3 front = leaf.area * leaf.cosNormOut * (leaf.emission + leaf.albedo * (e + Fetch3(direct, 4u * i)) * kInvPi);
    bool glossyLeaf = (leaf.flags & kLeafGlossy) != 0u && (pc.mode & kReflect) != 0u;
    uint g = leaf.flags >> kGlossyShift;
    Lobe lobe = Lobe(0u, 0u, 0.0, 0.0);
    vec3 f0 = vec3(0.0);
    if (glossyLeaf) {
        for (uint b = 0; b < BINS; ++b) arrived[b] = vec3(0.0);
        for (uint l = 0; l < BINS; ++l) {
            float c = Cos(leaf.normal, l);
            if (c < 0.0) arrived[texelFetch(mirror, int(g * BINS + l)).x] -= c * Fetch3(lin, row + l * 3u);
        }
        lobe = lobes[glossy[g].lobe];
        f0 = leaf.area * glossy[g].specular;
    }
    for (uint b = 0; b < BINS; ++b) {
        float c = Cos(leaf.normal, b);
        uint k = row + b * 3u;
        vec3 v;
        if (c > 0.0) {
            // A two-sided leaf sends light arriving at its back on through its front.
            vec3 through = (leaf.flags & kLeafTwoSided) != 0u ? leaf.area * c * Fetch3(lin, k) : vec3(0.0);
            v = (pc.mode & kReflect) != 0u ? c * front - through : Fetch3(iexOld, k);
            if (glossyLeaf) {
                vec3 sum = vec3(0.0);
                uint start = lobe.start + b * lobe.width;
                for (uint w = 0; w < lobe.width; ++w) {
                    int at = int(2u * (start + w));
                    sum += uintBitsToFloat(texelFetch(lobeWeights, at + 1).x) * arrived[texelFetch(lobeWeights, at).x];
                }
                v += c * f0 * (pc.binSolidAngle * sum + Fetch3(glossyDirect, 4u * (g * BINS + b)));
            }
        } else {
            v = (pc.mode & kAntiradiance) != 0u ? leaf.area * c * Fetch3(lin, k) : Fetch3(iexOld, k);
        }
        iexNew[k] = v.x;
        iexNew[k + 1u] = v.y;
        iexNew[k + 2u] = v.z;
    }
}
