// Local pass at the leaves (Sec. 3.1): K reflects incident radiance into the front
// hemisphere (Eq. 18, diffuse: I_L = a⟨n|ω⟩(L_e + ρ(E + E_d)/π), E_d the shadow-mapped
// direct light of Sec. 3.3, which makes no antiradiance), J sends it through the back
// hemisphere as antiradiance (Eq. 19: I_A = a⟨n|−ω⟩L_in). I_ex = I_L − I_A.
// Glossy leaves add their lobe's share of Eq. 18 (cpu_passes.cpp, GlossyReflection: keep
// the arithmetic in step): incoming light gathered at the mirror bin of each incoming bin,
// then every outgoing bin reads its lobe row there.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

layout(std430, binding = 0) readonly buffer Leaves { Leaf leaves[]; };
layout(std430, binding = 1) readonly buffer Dirs { vec4 dirs[]; };
layout(std430, binding = 2) readonly buffer Lin { float lin[]; };
layout(std430, binding = 3) readonly buffer IexOld { float iexOld[]; };
layout(std430, binding = 4) writeonly buffer IexNew { float iexNew[]; };
layout(std430, binding = 5) writeonly buffer Irradiance { float irradiance[]; };
layout(std430, binding = 6) readonly buffer Direct { vec4 direct[]; };
layout(std430, binding = 7) readonly buffer Glossy { GlossyLeaf glossy[]; };
layout(std430, binding = 8) readonly buffer Mirror { uint mirror[]; };
layout(std430, binding = 9) readonly buffer Lobes { Lobe lobes[]; };
layout(std430, binding = 10) readonly buffer LobeWeights { BinWeight lobeWeights[]; };
layout(std430, binding = 11) readonly buffer GlossyDirect { vec4 glossyDirect[]; };

layout(push_constant) uniform Push { uint count; uint mode; float binSolidAngle; } pc;

const float kInvPi = 0.31830988618379067;

// Light arriving at the front of a glossy leaf, summed at the mirror bin of each bin.
vec3 arrived[BINS];

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= pc.count) return;
    Leaf leaf = leaves[i];
    uint row = leaf.node * BINS * 3u;

    // Irradiance E = ω_bin Σ ⟨n|−ω_l⟩ L_in(ω_l) over bins arriving at the front.
    vec3 e = vec3(0.0);
    for (uint b = 0; b < BINS; ++b) {
        float c = dot(leaf.normal, dirs[b].xyz);
        if (c < 0.0) e -= c * vec3(lin[row + b * 3u], lin[row + b * 3u + 1u], lin[row + b * 3u + 2u]);
    }
    e *= pc.binSolidAngle * leaf.cosNormIn;
    irradiance[i * 3u] = e.x;
    irradiance[i * 3u + 1u] = e.y;
    irradiance[i * 3u + 2u] = e.z;

    vec3 front = leaf.area * leaf.cosNormOut * (leaf.emission + leaf.albedo * (e + direct[i].xyz) * kInvPi);
    bool glossyLeaf = (leaf.flags & kLeafGlossy) != 0u && (pc.mode & kReflect) != 0u;
    uint g = leaf.flags >> kGlossyShift;
    Lobe lobe = Lobe(0u, 0u, 0.0, 0.0);
    vec3 f0 = vec3(0.0);
    if (glossyLeaf) {
        for (uint b = 0; b < BINS; ++b) arrived[b] = vec3(0.0);
        for (uint l = 0; l < BINS; ++l) {
            float c = dot(leaf.normal, dirs[l].xyz);
            uint k = row + l * 3u;
            if (c < 0.0) arrived[mirror[g * BINS + l]] -= c * vec3(lin[k], lin[k + 1u], lin[k + 2u]);
        }
        lobe = lobes[glossy[g].lobe];
        f0 = leaf.area * glossy[g].specular;
    }
    for (uint b = 0; b < BINS; ++b) {
        float c = dot(leaf.normal, dirs[b].xyz);
        uint k = row + b * 3u;
        vec3 v;
        if (c > 0.0) {
            // A two-sided leaf sends light arriving at its back on through its front.
            vec3 through = (leaf.flags & kLeafTwoSided) != 0u
                               ? leaf.area * c * vec3(lin[k], lin[k + 1u], lin[k + 2u])
                               : vec3(0.0);
            v = (pc.mode & kReflect) != 0u ? c * front - through
                                           : vec3(iexOld[k], iexOld[k + 1u], iexOld[k + 2u]);
            if (glossyLeaf) {
                vec3 sum = vec3(0.0);
                uint start = lobe.start + b * lobe.width;
                for (uint w = 0; w < lobe.width; ++w) {
                    BinWeight bw = lobeWeights[start + w];
                    sum += bw.weight * arrived[bw.bin];
                }
                v += c * f0 * (pc.binSolidAngle * sum + glossyDirect[g * BINS + b].xyz);
            }
        } else {
            v = (pc.mode & kAntiradiance) != 0u
                    ? leaf.area * c * vec3(lin[k], lin[k + 1u], lin[k + 2u])
                    : vec3(iexOld[k], iexOld[k + 1u], iexOld[k + 2u]);
        }
        iexNew[k] = v.x;
        iexNew[k + 1u] = v.y;
        iexNew[k + 2u] = v.z;
    }
}
