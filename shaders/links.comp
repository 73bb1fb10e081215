// Link update of a move (Sec. 3.3, "for each link touching a moved object, only its form
// factor and bin are recomputed"): one invocation per link touching a motion group; when
// the receiver's or the sender's group moved, the link's bin, spread level and form factor
// (Eq. 17, with the near field and the calibration of oriented ends) are computed again at
// the nodes' new places. The device twin of links.cpp MakeLink and Directions::LookupWithin
// / LevelFor: keep the arithmetic in step with them.
#version 450
#extension GL_GOOGLE_include_directive : require
#include "common.glsl"

layout(local_size_x_id = 0) in;

// solvers/antiradiance/vulkan_passes.cpp: struct LinkNode (48 bytes).
struct LinkNode {
    vec3 center;
    float discRadius;
    vec3 normal;
    float area;
    uint surfel;
    uint flags;  // kNodeLeaf | kNodeOriented | motion group << kNodeGroupShift
    float normIn;
    float normOut;
};
const uint kNodeLeaf = 1u;
const uint kNodeOriented = 2u;
const uint kNodeGroupShift = 2u;

layout(std430, binding = 0) buffer Links { Link links[]; };
// Links::dynamic and Links::dynamicReceivers: (index into links, receiver node).
layout(std430, binding = 1) readonly buffer Dynamic { uvec2 dynamicLinks[]; };
layout(std430, binding = 2) readonly buffer Nodes { LinkNode nodes[]; };
layout(std430, binding = 3) readonly buffer Moved { uint moved[]; };  // per group, [0] static
layout(std430, binding = 4) readonly buffer Dirs { vec4 dirs[]; };
// Directions: the cube map (6 · res² texels → a bin near the texel centre) and each bin's
// neighbours within two spacings, padded with the bin itself to `adjacentWidth`.
layout(std430, binding = 5) readonly buffer Cube { uint cube[]; };
layout(std430, binding = 6) readonly buffer Adjacent { uint adjacent[]; };
layout(std430, binding = 7) readonly buffer SpreadLevels { uvec2 spread[]; };
layout(std430, binding = 8) readonly buffer Neighbours { BinWeight neighbours[]; };
// Surfels (position, normal as vec4 pairs) and the near field (NearField, refined triangles).
layout(std430, binding = 9) readonly buffer Surfels { vec4 surfels[]; };
layout(std430, binding = 10) readonly buffer NearOffsets { uint nearOffsets[]; };
layout(std430, binding = 11) readonly buffer NearTriangles { uint nearTriangles[]; };
layout(std430, binding = 12) readonly buffer Triangles { uint triangles[]; };

layout(push_constant) uniform Push {
    uint first;
    uint count;
    uint cubeRes;
    uint adjacentWidth;
    float binSolidAngle;
    float sigma0;  // Directions::LevelSigma(0)
} pc;

const uint kLevels = 6u;             // Directions::kLevels
const float kNearRadii = 4.0;        // links.cpp MakeLink
const float kMaxCalibration = 16.0;  // links.cpp MakeLink
const float kFrontMargin = 1e-4;     // links.cpp MakeLink
const float kNearTrace = 1e-5;       // links.cpp
const int kDiv = 6;                  // links.cpp NearFieldIrradiance

#include "directions.glsl"
uint Lookup(vec3 d) { return LookupBin(d, pc.cubeRes, pc.adjacentWidth); }

// Directions::LookupWithin, with `useA`/`useB` false for the zero vectors of the C++ side.
bool Within(uint j, bool useA, vec3 a, bool useB, vec3 b) {
    vec3 w = dirs[j].xyz;
    return (!useA || dot(w, a) > 0.0) && (!useB || dot(w, b) > 0.0);
}
uint LookupWithin(vec3 d, bool useA, vec3 a, bool useB, vec3 b) {
    uint nearest = Lookup(d);
    if (Within(nearest, useA, a, useB, b)) return nearest;
    uint best = nearest;
    float bestDot = -2.0;
    uint row = nearest * pc.adjacentWidth;
    for (uint k = 0u; k < pc.adjacentWidth; ++k) {
        uint j = adjacent[row + k];
        float dd = dot(d, dirs[j].xyz);
        if (Within(j, useA, a, useB, b) && dd > bestDot) {
            bestDot = dd;
            best = j;
        }
    }
    return best;
}

// Directions::LevelFor.
uint LevelFor(float alpha) {
    float s = sqrt(0.25 * alpha * alpha + pc.sigma0 * pc.sigma0);
    int k = int(floor(2.0 * log2(s / pc.sigma0) + 0.5));
    return uint(clamp(k, 0, int(kLevels) - 1));
}

// links.cpp NearFieldIrradiance: ∫ φ_s |cos_s| cos_r / d² dA over surfel s's triangles.
float NearFieldIrradiance(uint s, vec3 p, vec3 n) {
    vec3 ns = surfels[2u * s + 1u].xyz;
    float sum = 0.0;
    for (uint i = nearOffsets[s]; i < nearOffsets[s + 1u]; ++i) {
        uint t = nearTriangles[i];
        uint v0 = triangles[t], v1 = triangles[t + 1u], v2 = triangles[t + 2u];
        uint ia = v0, ib = v1, ic = v2;
        if (v1 == s) {
            ia = v1;
            ib = v2;
            ic = v0;
        } else if (v2 == s) {
            ia = v2;
            ib = v0;
            ic = v1;
        }
        vec3 a = surfels[2u * ia].xyz, b = surfels[2u * ib].xyz, c = surfels[2u * ic].xyz;
        float w = 0.5 * length(cross(b - a, c - a)) / float(kDiv * kDiv);
        for (int row = 0; row < kDiv; ++row)
            for (int col = 0; col < kDiv - row; ++col)
                for (int up = 0; up < (col + row < kDiv - 1 ? 2 : 1); ++up) {
                    float u = float(3 * col + (up != 0 ? 2 : 1)) / float(3 * kDiv);
                    float vv = float(3 * row + (up != 0 ? 2 : 1)) / float(3 * kDiv);
                    float phi = 1.0 - u - vv;
                    vec3 q = a + u * (b - a) + vv * (c - a);
                    vec3 d = p - q;
                    float d2 = dot(d, d);
                    if (d2 <= 0.0) continue;
                    float inv = 1.0 / sqrt(d2);
                    float cs = abs(dot(ns, d)) * inv;
                    float cr = max(0.0, -dot(n, d)) * inv;
                    sum += w * phi * cs * cr / d2;
                }
    }
    return sum;
}

void main() {
    uint k = pc.first + gl_GlobalInvocationID.x;
    if (gl_GlobalInvocationID.x >= pc.count) return;
    uvec2 entry = dynamicLinks[k];
    uint receiver = entry.y;
    uint sender = links[entry.x].sender;
    LinkNode R = nodes[receiver];
    LinkNode S = nodes[sender];
    if (moved[R.flags >> kNodeGroupShift] == 0u && moved[S.flags >> kNodeGroupShift] == 0u)
        return;

    vec3 d = R.center - S.center;  // direction of travel: sender → receiver
    float dist2 = dot(d, d);
    float dist = sqrt(dist2);
    vec3 u = d / dist;
    bool orientedS = (S.flags & kNodeOriented) != 0u;
    bool orientedR = (R.flags & kNodeOriented) != 0u;
    float cosS = orientedS ? dot(S.normal, u) : 0.0;
    float cosR = orientedR ? -dot(R.normal, u) : 0.0;
    bool front = cosS >= -kFrontMargin;
    vec3 sideS = front ? S.normal : -S.normal;
    vec3 sideR = -R.normal;
    uint bin = LookupWithin(u, orientedS, sideS, orientedR, sideR);
    uint level = LevelFor(atan(S.discRadius, dist));
    // Eq. 17, F = 1/(d² ω_bin), d² regularised by the sender's disc.
    float f = 1.0 / ((dist2 + S.discRadius * S.discRadius) * pc.binSolidAngle);
    bool leaves = (S.flags & kNodeLeaf) != 0u && (R.flags & kNodeLeaf) != 0u;
    vec3 wb = dirs[bin].xyz;
    float modelS = 1.0, modelR = 1.0;
    if (orientedS) modelS = abs(dot(S.normal, wb)) * (front ? S.normOut : 1.0);
    if (orientedR) {
        uvec2 lv = spread[level];
        uint first = lv.x + bin * lv.y;
        float spreadCos = 0.0;
        for (uint j = first; j < first + lv.y; ++j) {
            BinWeight nb = neighbours[j];
            spreadCos += nb.weight * max(0.0, -dot(R.normal, dirs[nb.bin].xyz));
        }
        modelR = spreadCos * R.normIn;
    }
    if (leaves && dist < kNearRadii * (S.discRadius + R.discRadius)) {
        // Near field: the integral carried through the models of both ends (links.cpp).
        float model = S.area * modelS * modelR * pc.binSolidAngle;
        float exact = NearFieldIrradiance(S.surfel, R.center, R.normal);
        if (exact < kNearTrace * S.area / dist2) exact = 0.0;  // coplanar neighbours
        f = model > 0.0 ? exact / model : 0.0;
    } else {
        if (orientedS) f *= modelS > 0.0 ? min(kMaxCalibration, abs(cosS) / modelS) : 0.0;
        if (orientedR) f *= modelR > 0.0 ? min(kMaxCalibration, max(0.0, cosR) / modelR) : 0.0;
    }
    links[entry.x] = Link(sender, bin | (level << 16), f);
}
