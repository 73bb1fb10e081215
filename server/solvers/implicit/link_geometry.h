// What the implicit linker's pair rounds and push-down share (implicit_links.cpp,
// implicit_pushdown.cpp): which node can receive from which, how wide a cluster looks, a
// closed solid's box, and the build's working buffers.
#pragma once

#include <tbb/enumerable_thread_specific.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>
#include <limits>
#include <numbers>
#include <vector>

#include "hierarchy/hierarchy.h"
#include "rays/sampling.h"
#include "solvers/implicit/implicit_links.h"

namespace penumbra::link_geometry {

// A bin covered at least this much is filled by its shares (ImplicitLinker::Build).
constexpr float kFillCoverage = 0.25f;
// A front bin covered less than this shows mostly the environment: the bins next to it lie
// at the edge of what is there, and are not filled.
constexpr float kEdgeCoverage = 0.1f;

// Whether some member of `r` can receive light from some point of `s`, `d` = s.center −
// r.center at distance `dist`: a member's front faces part of s's sphere. Conservative
// (normal cone widened by both spheres' angular radii).
// `sinCone`: the sine of r's normal cone's half angle (ConeSine).
inline bool CanReceive(const HierarchyNode& r, float sinCone, const HierarchyNode& s,
                       const glm::vec3& d, float dist) {
    if (r.coneCos <= -1.0f) return true;
    const float reach = r.radius + s.radius;
    if (dist <= reach) return true;
    // θ − cone − spread < π/2, in cosines (no inverse trigonometry in the pair loop): with
    // α = cone + spread, true when α ≥ π/2, else cos θ > cos(π/2 + α) = −sin α.
    const float cosCone = std::clamp(r.coneCos, -1.0f, 1.0f);
    const float sinSpread = reach / dist;
    const float cosSpread = std::sqrt(1.0f - sinSpread * sinSpread);
    if (cosCone * cosSpread - sinCone * sinSpread <= 0.0f) return true;
    const float sinAlpha = sinCone * cosSpread + cosCone * sinSpread;
    return glm::dot(r.normal, d) / dist > -sinAlpha;
}

inline float ConeSine(const HierarchyNode& r) {
    const float cosCone = std::clamp(r.coneCos, -1.0f, 1.0f);
    return std::sqrt(1.0f - cosCone * cosCone);
}

// How much of the disc of its bounding sphere a cluster shows along `dir` (unit): its members
// lie in the cylinder of the sphere's radius R and half height h = `slab` · R about its normal
// n, which projects to a rectangle 2R by 2h sin θ between two half ellipses of axes R and
// R |cos θ| (θ = ∠(n, dir)): π R² |cos θ| + 4 R h sin θ, at most the disc π R² (a thick
// cluster). A flat cluster seen edge-on subtends a sliver, not its sphere's disc.
inline float Foreshortening(const HierarchyNode& n, float slab, const glm::vec3& dir) {
    const float c = std::min(1.0f, std::abs(glm::dot(n.normal, dir)));
    return std::min(1.0f, c + 4.0f / std::numbers::pi_v<float> * slab * std::sqrt(1.0f - c * c));
}

// The area where two discs of radii `r` and `R` with centres `d` apart overlap (angles on the
// sphere taken as flat: the overlap of an end's disc and a bin's). In floats for the spread,
// in doubles for OverlapReach's table.
template <typename T>
T LensArea(T d, T r, T R) {
    if (d >= r + R) return T(0);
    const T small = std::min(r, R), large = std::max(r, R);
    if (d <= large - small) return std::numbers::pi_v<T> * small * small;
    const T a = r * r * std::acos(std::clamp((d * d + r * r - R * R) / (2 * d * r), T(-1), T(1)));
    const T b = R * R * std::acos(std::clamp((d * d + R * R - r * r) / (2 * d * R), T(-1), T(1)));
    const T k = (-d + r + R) * (d + r - R) * (d - r + R) * (d + r + R);
    return a + b - T(0.5) * std::sqrt(std::max(T(0), k));
}

// Whether bin w's axis (from `at`, unit w) meets a flat sender's plane (centre c, unit normal
// n, `height` = ⟨n, c − at⟩, the same for every bin of an end) in front of `at` within its disc
// of radius r, widened by the bin's footprint there (a
// cone of angular radius rBin meets the plane in an ellipse of area π (t rBin)² / |⟨n, w⟩|,
// taken as a disc of that area). A flat sender seen nearly edge-on from close by (the other
// wall at a room's corner, a box's side at a floor leaf beside it) spans a wide cone around
// its bounding sphere, but only the bins that meet its plane see it: the others look past it
// into the room.
inline bool MeetsFlatSender(float height, const glm::vec3& c, const glm::vec3& n, float r,
                            const glm::vec3& at, const glm::vec3& w, float rBin) {
    const float cosPhi = glm::dot(n, w);
    if (std::abs(cosPhi) < 1e-4f) return false;
    const float t = height / cosPhi;
    if (!(t > 0.0f)) return false;
    const float foot = t * rBin / std::sqrt(std::abs(cosPhi));
    return glm::length(at + t * w - c) < r + foot;
}

struct Pair {
    uint32_t a, b;
    uint32_t root;  // the kept pair whose descendant it is (ImplicitLinker::Build)
};

// Whether direction `dir` (unit) leaves `r` above the horizon of some member: a flat node
// does not see what lies in its own plane (coplanar neighbours would otherwise darken the
// grazing bins), a curved one sees down to its normal cone's edge.
inline bool AboveHorizon(const HierarchyNode& r, const glm::vec3& dir) {
    if (r.coneCos <= -1.0f) return true;
    const float below = std::sqrt(std::max(0.0f, 1.0f - r.coneCos * r.coneCos));
    return glm::dot(r.normal, dir) > 0.01f - below;
}

// A closed solid's box of its leaves, open (unbounded) across a face that another surface
// touches: seen through such a face the solid's outline continues into what it stands on.
struct SolidBox {
    glm::vec3 lo{std::numeric_limits<float>::max()}, hi{-std::numeric_limits<float>::max()};
    // Whether the ray from `from` along `dir` meets the box ahead (or starts inside it).
    bool Meets(const glm::vec3& from, const glm::vec3& dir) const {
        float near = 0.0f, far = std::numeric_limits<float>::max();
        for (int a = 0; a < 3; ++a) {
            if (std::abs(dir[a]) < 1e-12f) {
                if (from[a] < lo[a] || from[a] > hi[a]) return false;
                continue;
            }
            float t0 = (lo[a] - from[a]) / dir[a], t1 = (hi[a] - from[a]) / dir[a];
            if (t0 > t1) std::swap(t0, t1);
            near = std::max(near, t0);
            far = std::min(far, t1);
        }
        return near <= far;
    }
    // Whether the cone about `dir` of half angle `radius` lies inside the box's outline seen
    // from `from` (a receiver with `normal`): its axis and the rays on its rim above the
    // receiver's horizon meet the box.
    bool Holds(const glm::vec3& from, const glm::vec3& dir, float radius,
               const glm::vec3& normal) const {
        if (!Meets(from, dir)) return false;
        glm::vec3 t, s;
        Basis(dir, t, s);
        const float c = std::cos(radius), r = std::sin(radius);
        for (const glm::vec3& side : {t, -t, s, -s}) {
            const glm::vec3 ray = c * dir + r * side;
            if (glm::dot(ray, normal) > 0.0f && !Meets(from, ray)) return false;
        }
        return true;
    }
};

// Per node, how thick the slab about its centre across its normal is that holds its members'
// discs, as a fraction of its radius (at most 1; 0 for a leaf, a disc): half the slab's height,
// the largest |⟨n, c_k − c⟩| + r_k sin∠(n, n_k) over its leaves k. A cluster of one flat or
// gently curved surface is thin; one holding a tabletop and the floor under it is not, though
// every normal agrees.
std::vector<float> SlabThickness(const Hierarchy& h);

// Per closed solid (solid[node], kNoSolid for none) the box of its leaves, opened across each
// face that a leaf of something else touches (within `thin` of the face's plane, over it).
std::vector<SolidBox> SolidBoxes(const Hierarchy& h, const std::vector<uint32_t>& solid,
                                 float thin);

}  // namespace penumbra::link_geometry

namespace penumbra {

struct ImplicitLinker::Scratch {
    std::vector<link_geometry::Pair> round;
    tbb::enumerable_thread_specific<std::vector<link_geometry::Pair>> next;
    tbb::enumerable_thread_specific<std::vector<End>> recorded;
    std::vector<End> byNode, ends;
    // Each node's runs of ends by bin (ImplicitLinker::Build).
    std::vector<uint64_t> occupied;
    std::vector<uint32_t> runFirst, runs;
    // Per thread, the compositing's per-bin stacks of runs (empty between tasks).
    tbb::enumerable_thread_specific<std::vector<std::vector<std::pair<const End*, const End*>>>>
        stacks;
    std::vector<std::vector<Entry>> perLeaf;
    std::vector<uint64_t> closest;  // BuildClosest's slots
};

}  // namespace penumbra
