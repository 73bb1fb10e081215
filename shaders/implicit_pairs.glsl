// One round of the implicit solver's link creation (Dong et al. 2007, Sec. 4.2.2,
// CreateHierarchicalLinks), level by level as in Meyer et al. 2009's data-parallel link
// creation: one invocation per candidate pair of this round; a pair is split into the next
// round's pairs while an end subtends more than linkThreshold × ω_bin from the other, else it
// becomes a link recorded at each end that can receive, in the end's (node, bin) slot with
// its depth along the bin and the solid angle the sender covers. Both lists are appended with
// atomic counters; the host reads the counts after the round (and runs it again with larger
// buffers when one overflowed). The device twin of ImplicitLinker::Build's pair loop,
// CanReceive, AboveHorizon and Record (solvers/implicit/implicit_links.cpp): keep the
// arithmetic in step with them.
//
// Included by implicit_pairs.comp (each end appended, the closest layer's) and by
// implicit_closest.comp (CLOSEST defined: the paper's rule, each (node, bin) slot keeping its
// closest link by 64-bit atomicMin).

layout(local_size_x = 64) in;

// solvers/implicit/vulkan_links.cpp: struct PairNode (48 bytes).
struct PairNode {
    vec3 center;
    float radius;
    vec3 normal;
    float coneCos;
    float area;
    uint right;  // the second child (the first is the node after it); 0 for a leaf
    float slab;  // the slab holding its members, half height over radius (Build's SlabThickness)
    float discRadius;
};
// ImplicitLinker::End.
struct End {
    uint slot;
    uint sender;
    float dist;
    float omega;
};

layout(std430, binding = 0) readonly buffer Nodes { PairNode nodes[]; };
layout(std430, binding = 1) readonly buffer Round { uvec2 round[]; };
layout(std430, binding = 2) writeonly buffer Next { uvec2 next[]; };
layout(std430, binding = 3) writeonly buffer Ends { End ends[]; };
// [0] the next round's pairs, [1] the ends, [2] the pairs linked.
layout(std430, binding = 4) buffer Counts { uint counts[]; };
// Per node and bin: the front-facing projected area Σ A cos⁺(n, ω_b).
layout(std430, binding = 5) readonly buffer FrontArea { float frontArea[]; };
layout(std430, binding = 6) readonly buffer Dirs { vec4 dirs[]; };
layout(std430, binding = 7) readonly buffer Cube { uint cube[]; };
layout(std430, binding = 8) readonly buffer Adjacent { uint adjacent[]; };
#ifdef CLOSEST
// Per (node, bin) slot its closest link: (depth bits << 32 | sender), all ones for none (a
// positive float's bits order as it does; the sender breaks ties, as on the CPU).
layout(std430, binding = 9) buffer Closest { uint64_t best[]; };
#endif

layout(push_constant) uniform Push {
    uint count;  // pairs this round
    uint nextCapacity;
    uint endCapacity;
    uint bins;
    uint cubeRes;
    uint adjacentWidth;
    float limit;          // linkThreshold × ω_bin
    float binSolidAngle;  // ω_bin
    float splat;          // sin of the angular radius above which an end is spread
    float adjacentAngle;  // Directions::AdjacentAngle()
    float binRadius;      // the radius of a disc of a bin's solid angle
} pc;

#include "directions.glsl"

const float kFlatCone = 0.9;  // implicit_links.h
const float kPi = 3.14159265358979323846;

bool CanReceive(PairNode r, PairNode s, vec3 d, float dist) {
    if (r.coneCos <= -1.0) return true;
    float reach = r.radius + s.radius;
    if (dist <= reach) return true;
    float cosCone = clamp(r.coneCos, -1.0, 1.0);
    float sinCone = sqrt(1.0 - cosCone * cosCone);
    float sinSpread = reach / dist;
    float cosSpread = sqrt(1.0 - sinSpread * sinSpread);
    if (cosCone * cosSpread - sinCone * sinSpread <= 0.0) return true;
    float sinAlpha = sinCone * cosSpread + cosCone * sinSpread;
    return dot(r.normal, d) / dist > -sinAlpha;
}

bool AboveHorizon(PairNode r, vec3 dir) {
    if (r.coneCos <= -1.0) return true;
    float below = sqrt(max(0.0, 1.0 - r.coneCos * r.coneCos));
    return dot(r.normal, dir) > 0.01 - below;
}

// Foreshortening (implicit_links.cpp): how much of its sphere's disc a cluster shows along
// `dir`.
float Foreshortening(PairNode n, vec3 dir) {
    float c = min(1.0, abs(dot(n.normal, dir)));
    return min(1.0, c + 4.0 / kPi * n.slab * sqrt(1.0 - c * c));
}

// The solid angle sender `s` covers seen along `dir` at `dist` (Build's `covered`): `ahead`
// and `back` the bins of the direction between the ends and of its opposite.
float Covered(uint s, vec3 dir, float dist, uint ahead, uint back) {
    PairNode n = nodes[s];
    float d2 = max(dist * dist, 1e-30);
    if (n.coneCos >= kFlatCone) return n.area * abs(dot(n.normal, dir)) / d2;
    uint row = s * pc.bins;
    return max(frontArea[row + back], frontArea[row + ahead]) / d2;
}

void Emit(uint slot, uint sender, float dist, float omega) {
    uint i = atomicAdd(counts[1], 1u);
    if (i < pc.endCapacity) ends[i] = End(slot, sender, dist, omega);
}

// A flat sender's depth along bin axis `w` from the receiver's centre `at` (Record's
// `depth`: its plane met along the axis, a leaf's within dist ± its radius, a cluster's at
// most dist).
float Depth(PairNode from, vec3 at, vec3 w, float dist) {
    if (from.coneCos < kFlatCone) return dist;
    float facing = dot(from.normal, w);
    if (abs(facing) < 0.2) return dist;
    float t = dot(from.normal, from.center - at) / facing;
    if (!(t > 0.0)) return dist;
    return from.right == 0u ? clamp(t, dist - from.radius, dist + from.radius) : min(t, dist);
}

// LensArea (implicit_links.cpp): the overlap of discs of radii r and R, centres d apart.
float LensArea(float d, float r, float R) {
    if (d >= r + R) return 0.0;
    float small = min(r, R), large = max(r, R);
    if (d <= large - small) return kPi * small * small;
    float a = r * r * acos(clamp((d * d + r * r - R * R) / (2.0 * d * r), -1.0, 1.0));
    float b = R * R * acos(clamp((d * d + R * R - r * r) / (2.0 * d * R), -1.0, 1.0));
    float k = (-d + r + R) * (d + r - R) * (d - r + R) * (d + r + R);
    return a + b - 0.5 * sqrt(max(0.0, k));
}

// MeetsFlatSender (implicit_links.cpp): bin w's axis meets the flat sender's plane
// (`height` = ⟨n, c − at⟩) in front of `at`, within its disc widened by the bin's footprint.
bool MeetsFlatSender(float height, vec3 c, vec3 n, float r, vec3 at, vec3 w) {
    float cosPhi = dot(n, w);
    if (abs(cosPhi) < 1e-4) return false;
    float t = height / cosPhi;
    if (!(t > 0.0)) return false;
    float foot = t * pc.binRadius / sqrt(abs(cosPhi));
    return length(at + t * w - c) < r + foot;
}

// An end wider than half a bin's spacing: each bin its disc overlaps, with the overlap (a
// flat sender's only where the bin meets it).
const float kMinOverlap = 0.2;  // implicit_links.cpp

// `cosReach`: cos(ρ + r_bin), below which a bin does not overlap the disc; `cosInside`:
// cos|ρ − r_bin|, above which the overlap is `inside` (LensArea's first case).
// `height`: ⟨n, c − at⟩ of a flat sender (MeetsFlatSender).
// `shows` < 1 (a cluster foreshortened, Record's squeeze): `m` its normal off `dir`.
void Spread(uint row, uint b, uint sender, PairNode from, vec3 at, vec3 dir, float dist,
            float rho, float cosReach, float cosInside, float inside, float height, float shows,
            vec3 m) {
    vec3 w = dirs[b].xyz;
    float c = dot(w, dir);
    if (c < cosReach) return;
    if (from.coneCos >= kFlatCone &&
        !MeetsFlatSender(height, from.center, from.normal, from.discRadius, at, w))
        return;
    float a;
    if (shows < 0.999) {
        vec3 o = w - dir;
        float across = dot(o, m);
        float apart = sqrt(max(0.0, dot(o, o) - across * across) + across * across / (shows * shows));
        a = min(pc.binSolidAngle, shows * LensArea(apart, rho, pc.binRadius / sqrt(shows)));
    } else {
        a = c >= cosInside
                ? inside
                : min(pc.binSolidAngle, LensArea(acos(clamp(c, -1.0, 1.0)), rho, pc.binRadius));
    }
    if (a > kMinOverlap * pc.binSolidAngle) Emit(row + b, sender, Depth(from, at, w, dist), a);
}

void Record(uint node, uint sender, PairNode from, vec3 at, vec3 dir, float dist, float omega,
            uint centre, float shows) {
    uint row = node * pc.bins;
#ifdef CLOSEST
    // The paper's rule (ImplicitLinker::BuildClosest): no end is spread, the slot of the
    // centre bin keeps its closest link.
    float depth = Depth(from, at, dirs[centre].xyz, dist);
    atomicMin(best[row + centre], (uint64_t(floatBitsToUint(depth)) << 32) | uint64_t(sender));
#else
    float sinRadius = from.radius / dist;
    if (sinRadius > pc.splat) {
        float rho = asin(min(1.0, sinRadius));
        float cosReach = cos(min(kPi, rho + pc.binRadius));
        float small = min(rho, pc.binRadius);
        float cosInside = cos(abs(rho - pc.binRadius));
        float inside = min(pc.binSolidAngle, kPi * small * small);
        float height = dot(from.normal, from.center - at);
        if (from.right == 0u) shows = 1.0;  // a leaf keeps its whole disc
        vec3 m = shows < 0.999 ? normalize(from.normal - dot(from.normal, dir) * dir) : vec3(0.0);
        float theta = acos(clamp(dot(dir, dirs[centre].xyz), -1.0, 1.0));
        if (theta + rho + pc.binRadius <= pc.adjacentAngle - 1e-3) {
            // The padding repeats the centre bin, which is taken first.
            Spread(row, centre, sender, from, at, dir, dist, rho, cosReach, cosInside, inside, height, shows, m);
            for (uint k = 0u; k < pc.adjacentWidth; ++k) {
                uint b = adjacent[centre * pc.adjacentWidth + k];
                if (b != centre) Spread(row, b, sender, from, at, dir, dist, rho, cosReach, cosInside, inside, height, shows, m);
            }
        } else {
            for (uint b = 0u; b < pc.bins; ++b)
                Spread(row, b, sender, from, at, dir, dist, rho, cosReach, cosInside, inside, height, shows, m);
        }
        return;
    }
    Emit(row + centre, sender, Depth(from, at, dirs[centre].xyz, dist), omega);
#endif
}

void Split(uint a, uint b) {
    uint i = atomicAdd(counts[0], 1u);
    if (i < pc.nextCapacity) next[i] = uvec2(a, b);
}

void main() {
    uint k = gl_GlobalInvocationID.x;
    if (k >= pc.count) return;
    uint a = round[k].x, b = round[k].y;
    PairNode A = nodes[a];
    if (a == b) {  // a self-pair: its children's self-pairs and their pair
        if (A.right == 0u) return;
        uint l = a + 1u, r = A.right;
        Split(l, l);
        Split(r, r);
        Split(l, r);
        return;
    }
    PairNode B = nodes[b];
    vec3 d = B.center - A.center;
    float dist = length(d);
    bool aGets = CanReceive(A, B, d, dist);
    bool bGets = CanReceive(B, A, -d, dist);
    if (!aGets && !bGets) return;
    // Sec. 4.2.2: an end that looks bigger than a bin from the other is split.
    bool overlap = dist <= A.radius + B.radius;
    float dist2 = max(dist * dist, 1e-30);
    vec3 unit = dist > 0.0 ? d / dist : vec3(0.0);
    float showsA = A.right == 0u ? 1.0 : Foreshortening(A, unit);
    float showsB = B.right == 0u ? 1.0 : Foreshortening(B, unit);
    bool splitA = A.right != 0u && (overlap || kPi * A.radius * A.radius * showsA / dist2 > pc.limit);
    bool splitB = B.right != 0u && (overlap || kPi * B.radius * B.radius * showsB / dist2 > pc.limit);
    if (splitA && splitB) {  // both at once (ImplicitLinker::Build)
        Split(a + 1u, b + 1u);
        Split(a + 1u, B.right);
        Split(A.right, b + 1u);
        Split(A.right, B.right);
        return;
    }
    if (splitB) {
        Split(a, b + 1u);
        Split(a, B.right);
        return;
    }
    if (splitA) {
        Split(a + 1u, b);
        Split(A.right, b);
        return;
    }
    if (!(dist > 0.0)) return;
    vec3 dir = unit;
    bool aRecords = aGets && AboveHorizon(A, dir);
    bool bRecords = bGets && AboveHorizon(B, -dir);
    if (aRecords || bRecords) {
        uint ahead = LookupBin(dir, pc.cubeRes, pc.adjacentWidth);
        uint back = LookupBin(-dir, pc.cubeRes, pc.adjacentWidth);
        if (aRecords)
            Record(a, b, B, A.center, dir, dist, Covered(b, dir, dist, ahead, back), ahead, showsB);
        if (bRecords)
            Record(b, a, A, B.center, -dir, dist, Covered(a, -dir, dist, back, ahead), back, showsA);
    }
    atomicAdd(counts[2], 1u);
}
