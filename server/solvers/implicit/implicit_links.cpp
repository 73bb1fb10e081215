// Per-frame link creation, refinement and push-down (implicit_links.h).
#include "solvers/implicit/implicit_links.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <limits>
#include <memory>
#include <numbers>
#include <span>
#include <utility>

#include "base/check.h"
#include "base/numeric.h"
#include "rays/sampling.h"
#include "solvers/implicit/vulkan_composite.h"
#include "solvers/implicit/vulkan_links.h"

namespace penumbra {
namespace {

// A bin covered at least this much is filled by its shares (ImplicitLinker::Build).
constexpr float kFillCoverage = 0.25f;
// A front bin covered less than this shows mostly the environment: the bins next to it lie
// at the edge of what is there, and are not filled.
constexpr float kEdgeCoverage = 0.1f;

// Whether some member of `r` can receive light from some point of `s`, `d` = s.center −
// r.center at distance `dist`: a member's front faces part of s's sphere. Conservative
// (normal cone widened by both spheres' angular radii).
// `sinCone`: the sine of r's normal cone's half angle (ConeSine).
bool CanReceive(const HierarchyNode& r, float sinCone, const HierarchyNode& s, const glm::vec3& d,
                float dist) {
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

float ConeSine(const HierarchyNode& r) {
    const float cosCone = std::clamp(r.coneCos, -1.0f, 1.0f);
    return std::sqrt(1.0f - cosCone * cosCone);
}

// Per node, how thick the slab about its centre across its normal is that holds its members'
// discs, as a fraction of its radius (at most 1; 0 for a leaf, a disc): half the slab's height,
// the largest |⟨n, c_k − c⟩| + r_k sin∠(n, n_k) over its leaves k. A cluster of one flat or
// gently curved surface is thin; one holding a tabletop and the floor under it is not, though
// every normal agrees.
std::vector<float> SlabThickness(const Hierarchy& h) {
    const auto& nodes = h.nodes;
    std::vector<float> slab(nodes.size(), 0.0f);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nodes.size(), 64), [&](const auto& range) {
        for (size_t i = range.begin(); i != range.end(); ++i) {
            const HierarchyNode& n = nodes[i];
            if (n.IsLeaf()) continue;
            if (!(glm::dot(n.normal, n.normal) > 0.5f) || !(n.radius > 0.0f)) {
                slab[i] = 1.0f;  // no axis: as thick as it is wide
                continue;
            }
            float half = 0.0f;
            for (size_t k = i + 1; k < n.end && half < n.radius; ++k) {
                const HierarchyNode& m = nodes[k];
                if (!m.IsLeaf()) continue;
                const float c = glm::dot(n.normal, m.normal);
                half = std::max(half, std::abs(glm::dot(n.normal, m.center - n.center)) +
                                          m.radius * std::sqrt(std::max(0.0f, 1.0f - c * c)));
            }
            slab[i] = std::min(1.0f, half / n.radius);
        }
    });
    return slab;
}

// How much of the disc of its bounding sphere a cluster shows along `dir` (unit): its members
// lie in the cylinder of the sphere's radius R and half height h = `slab` · R about its normal
// n, which projects to a rectangle 2R by 2h sin θ between two half ellipses of axes R and
// R |cos θ| (θ = ∠(n, dir)): π R² |cos θ| + 4 R h sin θ, at most the disc π R² (a thick
// cluster). A flat cluster seen edge-on subtends a sliver, not its sphere's disc.
float Foreshortening(const HierarchyNode& n, float slab, const glm::vec3& dir) {
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
bool MeetsFlatSender(float height, const glm::vec3& c, const glm::vec3& n, float r,
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
bool AboveHorizon(const HierarchyNode& r, const glm::vec3& dir) {
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

// Per closed solid (solid[node], kNoSolid for none) the box of its leaves, opened across each
// face that a leaf of something else touches (within `thin` of the face's plane, over it).
std::vector<SolidBox> SolidBoxes(const Hierarchy& h, const std::vector<uint32_t>& solid,
                                 float thin) {
    std::vector<SolidBox> boxes;
    if (solid.empty()) return boxes;
    for (uint32_t leaf : h.leaves) {
        const uint32_t of = solid[leaf];
        if (of == kNoSolid) continue;
        if (of >= boxes.size()) boxes.resize(size_t(of) + 1);
        boxes[of].lo = glm::min(boxes[of].lo, h.nodes[leaf].center);
        boxes[of].hi = glm::max(boxes[of].hi, h.nodes[leaf].center);
    }
    std::vector<SolidBox> open = boxes;
    constexpr float kUnbounded = std::numeric_limits<float>::max();
    tbb::parallel_for(size_t(0), boxes.size(), [&](size_t of) {
        const SolidBox& box = boxes[of];
        if (box.lo.x > box.hi.x) return;  // no such solid
        const glm::vec3 lo = box.lo - thin, hi = box.hi + thin;
        // The leaves of other surfaces within the widened box: down the tree (preorder,
        // `end` skips a subtree) through the nodes whose spheres meet it.
        for (uint32_t n = 0; n < h.nodes.size();) {
            const HierarchyNode& node = h.nodes[n];
            const glm::vec3 off = glm::clamp(node.center, lo, hi) - node.center;
            if (glm::dot(off, off) > node.radius * node.radius) {
                n = node.end;
                continue;
            }
            ++n;
            const glm::vec3& p = node.center;
            if (!node.IsLeaf() || solid[n - 1] == of || glm::any(glm::lessThan(p, lo)) ||
                glm::any(glm::greaterThan(p, hi)))
                continue;
            for (int a = 0; a < 3; ++a) {
                if (p[a] <= box.lo[a]) open[of].lo[a] = -kUnbounded;
                if (p[a] >= box.hi[a]) open[of].hi[a] = kUnbounded;
            }
        }
    });
    return open;
}

}  // namespace

struct ImplicitLinker::Scratch {
    std::vector<Pair> round;
    tbb::enumerable_thread_specific<std::vector<Pair>> next;
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

ImplicitLinker::~ImplicitLinker() = default;

ImplicitLinker::ImplicitLinker(const Directions& dirs, float linkThreshold, bool closest)
    : dirs_(dirs),
      threshold_(linkThreshold),
      closest_(closest),
      scratch_(std::make_unique<Scratch>()) {
    if (!(linkThreshold > 0.0f)) throw Error("link threshold must be a positive number");
    // Ends wider than half a bin's spacing are spread over the bins they cover.
    splat_ = std::sin(0.5f * dirs.Spacing());
    binRadius_ = std::sqrt(dirs.BinSolidAngle() / std::numbers::pi_v<float>);
    // LensArea(x R, y R, R) = R² LensArea(x, y, 1) falls as x grows: per y_k, the x where it
    // falls to kMinOverlap π (bisection, in doubles), every disc up to a hemisphere's.
    const double minArea = kMinOverlap * std::numbers::pi;
    auto lens = [](double d, double r) { return LensArea(d, r, 1.0); };
    const double yMost = std::numbers::pi / 2 / binRadius_ + 1.0;
    for (int k = 0; kReachFirst + double(k - 1) / kReachSteps <= yMost; ++k) {
        const double y = kReachFirst + double(k) / kReachSteps;
        double lo = 0.0, hi = y + 1.0;  // lens(lo) > minArea unless the disc is that small
        if (!(lens(0.0, y) > minArea)) {
            overlapReach_.push_back(0.0f);
            continue;
        }
        for (int i = 0; i < 60; ++i)
            (lens(0.5 * (lo + hi), y) > minArea ? lo : hi) = 0.5 * (lo + hi);
        overlapReach_.push_back(float(hi));
    }
}

void ImplicitLinker::UseDevice(VulkanLinkCreation* device) { device_ = device; }

float ImplicitLinker::OverlapReach(float rho) const {
    const float y = rho / binRadius_;
    // The table's entry at or above y (the reach grows with y), with a margin for rounding;
    // beyond it, or below its first entry, the disc's whole reach.
    const float at = std::ceil((y - kReachFirst) * kReachSteps);
    if (!(at >= 0.0f) || at >= float(overlapReach_.size())) return rho + binRadius_;
    return std::min(rho + binRadius_, overlapReach_[size_t(at)] * binRadius_ * 1.001f + 1e-4f);
}

void ImplicitLinker::Build(const Hierarchy& h, const std::vector<float>& frontArea,
                           const std::vector<uint32_t>& solid, float thin, ImplicitLinks& out,
                           const std::vector<uint8_t>* moving) {
    const auto& nodes = h.nodes;
    PENUMBRA_CHECK(!moving || moving->size() == nodes.size());
    const bool perFrame = moving != nullptr;  // a relink given what moves: keep scratch_
    // The closest rule's table on the device where it fits there, else this build's links here.
    VulkanLinkCreation* device = device_;
    linkedOnHost_.clear();
    if (device && closest_) {
        linkedOnHost_ = device->ClosestUnfit(nodes.size());
        if (!linkedOnHost_.empty()) device = nullptr;
    }
    if (device) moving = nullptr;  // the device examines every pair
    // With the ends kept for this `moving`: only the pairs with a moving end are examined.
    // Else everything, and the ends of the pairs without one are kept for the next build.
    incremental_ = moving && !keptFor_.empty() && keptFor_ == *moving;
    if (!incremental_) {
        kept_ = {};
        keptFor_ = moving ? *moving : std::vector<uint8_t>{};
    }
    const uint8_t* still = moving ? moving->data() : nullptr;  // still[n] == 0: n is kept
    auto keptPair = [&](uint32_t a, uint32_t b) { return still && !still[a] && !still[b]; };
    const size_t bins = static_cast<size_t>(dirs_.Count());
    const float omegaBin = dirs_.BinSolidAngle();
    const float limit = threshold_ * omegaBin;
    const float pi = std::numbers::pi_v<float>;
    PENUMBRA_CHECK_EQ(frontArea.size(), nodes.size() * bins);
    PENUMBRA_CHECK(solid.empty() || solid.size() == nodes.size());
    auto start = std::chrono::steady_clock::now();
    std::vector<float> sinCone(nodes.size());  // per node, ConeSine (the CPU's rounds)
    const std::vector<float> slab = SlabThickness(h);

    // The solid angle sender `s` covers seen from `r` along `dir` (unit, r → s) at `dist`: a
    // flat node's area times |cos| (turned away it still hides what is behind it), another
    // cluster's larger projected area (front or back: a closed solid shows one side).
    // `ahead` and `back`: the bins of the direction between the two ends and of its opposite
    // (the one its light travels along, and the other), looked up once a pair.
    auto covered = [&](uint32_t s, const glm::vec3& dir, float dist, uint32_t ahead,
                       uint32_t back) {
        const HierarchyNode& n = nodes[s];
        const float d2 = std::max(dist * dist, 1e-30f);
        if (n.coneCos >= kFlatCone) return n.area * std::abs(glm::dot(n.normal, dir)) / d2;
        const float* row = frontArea.data() + size_t(s) * bins;
        return std::max(row[back], row[ahead]) / d2;
    };

    // CreateHierarchicalLinks, level by level: each round splits or links every pair of the
    // last round, in parallel; a link is recorded at each end that can receive.
    //
    // Kept pairs (both nodes outside `moving`): which of them a build meets depends on how
    // the pairs above them, with a moving end, were split; what a kept pair yields (its
    // descendants' ends) does not. So the first kept pair of each lineage (a root, its
    // parent pair had a moving end) is numbered, its descendants carry its number, and
    // their ends, pairs and links are kept per root; a later build given the same `moving`
    // takes a root's ends where it meets that root, and splits any other kept pair afresh.
    constexpr uint32_t kFresh = 0xffffffffu;
    // The root's self-pair, below (none: the rounds run on the device).
    std::vector<Pair>& round = scratch_->round;
    auto& next = scratch_->next;
    auto& recorded = scratch_->recorded;
    round.clear();
    for (auto& v : next) v.clear();
    for (auto& v : recorded) v.clear();
    struct KeptEnd {
        End end;
        uint32_t root;
    };
    tbb::enumerable_thread_specific<std::vector<KeptEnd>> keeping;
    // Per thread: new roots (pair key, number); per kept pair examined and per kept link,
    // its root (counted per root afterwards); roots taken (incremental).
    tbb::enumerable_thread_specific<std::vector<std::pair<uint64_t, uint32_t>>> roots;
    tbb::enumerable_thread_specific<std::vector<uint32_t>> examinedOf, linkedOf, taken;
    std::atomic<uint32_t> rootCount{0};
    std::atomic<size_t> pairs{0}, linked{0};
    const bool keeps = still && !incremental_;
    // The rounds on the device (vulkan_links.h), its ends standing for the threads', or here
    // from the root's self-pair.
    if (device && closest_) {
        // The paper's rule there: each slot's closest link kept by 64-bit atomicMin
        // (VulkanLinkCreation::CreateClosest); the push-down and the shares here.
        compositedOnDevice_ = false;
        compositeOnHost_.clear();
        device->CreateClosest(h, frontArea, slab, scratch_->closest, out.pairs, out.linked);
        out.msCreate = MsSince(start);
        start = std::chrono::steady_clock::now();
        PushClosest(h, out);
        if (!perFrame) scratch_ = std::make_unique<Scratch>();
        out.msPush = MsSince(start);
        return;
    }
    if (device) {
        size_t devicePairs = 0, deviceLinked = 0;
        device->Create(h, frontArea, slab, recorded.local(), devicePairs, deviceLinked);
        pairs = devicePairs;
        linked = deviceLinked;
    } else {
        round.push_back({0, 0, kFresh});
        tbb::parallel_for(size_t(0), nodes.size(),
                          [&](size_t n) { sinCone[n] = ConeSine(nodes[n]); });
    }
    auto keyOf = [](uint32_t a, uint32_t b) { return uint64_t(a) << 32 | b; };
    while (!round.empty()) {
        pairs += round.size();
        tbb::parallel_for(tbb::blocked_range<size_t>(0, round.size(), 512), [&](const auto& range) {
            std::vector<Pair>& emit = next.local();
            std::vector<End>& fresh = recorded.local();
            std::vector<KeptEnd>* keepInto = keeps ? &keeping.local() : nullptr;
            std::vector<uint32_t>* examined = keeps ? &examinedOf.local() : nullptr;
            std::vector<uint32_t>* linkedRoots = keeps ? &linkedOf.local() : nullptr;
            size_t made = 0;
            for (size_t k = range.begin(); k != range.end(); ++k) {
                const uint32_t a = round[k].a, b = round[k].b;
                uint32_t root = round[k].root;
                if (keptPair(a, b)) {
                    if (incremental_) {
                        // A root kept: its ends stand for all its descendants' (the pair
                        // itself is counted with them).
                        const auto it = kept_.index.find(keyOf(a, b));
                        if (it != kept_.index.end()) {
                            taken.local().push_back(it->second);
                            --pairs;
                            continue;
                        }
                    } else {
                        if (root == kFresh) {
                            root = rootCount++;
                            roots.local().push_back({keyOf(a, b), root});
                        }
                        examined->push_back(root);
                    }
                }
                const HierarchyNode& A = nodes[a];
                if (a == b) {  // a self-pair: its children's self-pairs and their pair
                    if (A.IsLeaf()) continue;
                    const uint32_t l = a + 1, r = nodes[a + 1].end;
                    emit.push_back({l, l, root});
                    emit.push_back({r, r, root});
                    emit.push_back({l, r, root});
                    continue;
                }
                const HierarchyNode& B = nodes[b];
                const glm::vec3 d = B.center - A.center;
                const float dist = glm::length(d);
                const bool aGets = CanReceive(A, sinCone[a], B, d, dist);
                const bool bGets = CanReceive(B, sinCone[b], A, -d, dist);
                if (!aGets && !bGets) continue;  // a pair's only use is what its ends receive
                // Sec. 4.2.2: an end that looks bigger than a bin from the other is split. How
                // big: its sphere's disc, foreshortened as far as its slab allows (a wall or a
                // cloth seen edge-on is a sliver; its sphere would split it down to the leaves
                // for bins it hardly touches).
                const bool overlap = dist <= A.radius + B.radius;
                const float dist2 = std::max(dist * dist, 1e-30f);
                const glm::vec3 unit = dist > 0.0f ? d / dist : glm::vec3(0.0f);
                const float showsA = A.IsLeaf() ? 1.0f : Foreshortening(A, slab[a], unit);
                const float showsB = B.IsLeaf() ? 1.0f : Foreshortening(B, slab[b], unit);
                const bool splitA =
                    !A.IsLeaf() && (overlap || pi * A.radius * A.radius * showsA / dist2 > limit);
                const bool splitB =
                    !B.IsLeaf() && (overlap || pi * B.radius * B.radius * showsB / dist2 > limit);
                // Both ends too wide for each other: both split at once (each of the four
                // child pairs is examined afresh), instead of the wider one now and the other
                // in the next round, through two pairs examined only to be split again
                // (a fifth of the pairs fewer, and within 0.03% of the same answers).
                if (splitA && splitB) {
                    const uint32_t a2 = nodes[a + 1].end, b2 = nodes[b + 1].end;
                    emit.push_back({a + 1, b + 1, root});
                    emit.push_back({a + 1, b2, root});
                    emit.push_back({a2, b + 1, root});
                    emit.push_back({a2, b2, root});
                    continue;
                }
                if (splitB) {
                    emit.push_back({a, b + 1, root});
                    emit.push_back({a, nodes[b + 1].end, root});
                    continue;
                }
                if (splitA) {
                    emit.push_back({a + 1, b, root});
                    emit.push_back({nodes[a + 1].end, b, root});
                    continue;
                }
                if (!(dist > 0.0f)) continue;  // coincident ends: no direction between them
                const glm::vec3& dir = unit;
                const size_t before = fresh.size();
                const bool aRecords = aGets && AboveHorizon(A, dir);
                const bool bRecords = bGets && AboveHorizon(B, -dir);
                if (aRecords || bRecords) {
                    const uint32_t ahead = dirs_.Lookup(dir), back = dirs_.Lookup(-dir);
                    if (aRecords)
                        Record(a, b, B, A.center, dir, dist, covered(b, dir, dist, ahead, back),
                               ahead, showsB, fresh);
                    if (bRecords)
                        Record(b, a, A, B.center, -dir, dist, covered(a, -dir, dist, back, ahead),
                               back, showsA, fresh);
                }
                if (keeps && root != kFresh) {  // this pair's ends are kept with its root
                    for (size_t e = before; e < fresh.size(); ++e)
                        keepInto->push_back({fresh[e], root});
                    fresh.resize(before);
                    linkedRoots->push_back(root);
                }
                ++made;
            }
            linked += made;
        });
        round.clear();
        for (auto& v : next) {
            round.insert(round.end(), v.begin(), v.end());
            v.clear();
        }
    }
    if (keeps) {
        // The kept ends grouped by root (a counting sort), the roots by pair.
        const uint32_t n = rootCount;
        kept_.first.assign(size_t(n) + 1, 0);
        kept_.pairs.assign(n, 0);
        kept_.linked.assign(n, 0);
        for (const auto& v : keeping)
            for (const KeptEnd& e : v) ++kept_.first[e.root + 1];
        for (uint32_t r = 0; r < n; ++r) kept_.first[r + 1] += kept_.first[r];
        kept_.ends.resize(kept_.first[n]);
        std::vector<uint32_t> fill(kept_.first.begin(), kept_.first.end() - 1);
        for (const auto& v : keeping)
            for (const KeptEnd& e : v) kept_.ends[fill[e.root]++] = e.end;
        for (const auto& v : examinedOf)
            for (uint32_t r : v) ++kept_.pairs[r];
        for (const auto& v : linkedOf)
            for (uint32_t r : v) ++kept_.linked[r];
        kept_.index.reserve(n);
        for (const auto& v : roots)
            for (const auto& [key, r] : v) kept_.index.emplace(key, r);
    }
    // The roots taken, in a fixed order; what a full build would count.
    std::vector<uint32_t> used;
    for (const auto& v : taken) used.insert(used.end(), v.begin(), v.end());
    std::sort(used.begin(), used.end());
    size_t pairsSum = pairs, linkedSum = linked;
    for (uint32_t r : used) pairsSum += kept_.pairs[r], linkedSum += kept_.linked[r];
    out.pairs = pairsSum;
    out.linked = linkedSum;
    // The device's ends composited there (vulkan_composite.h), where they fit.
    compositedOnDevice_ = false;
    compositeOnHost_.clear();
    if (device && composite_) {
        // The device's ends are in the calling thread's list; joined if ever in several.
        std::vector<const std::vector<End>*> filled;
        for (const auto& v : recorded)
            if (!v.empty()) filled.push_back(&v);
        std::vector<End> joined;
        std::span<const End> all;
        if (filled.size() == 1) {
            all = *filled[0];
        } else {
            for (const auto* v : filled) joined.insert(joined.end(), v->begin(), v->end());
            all = joined;
        }
        compositeOnHost_ = composite_->Unfit(h, all.size());
        if (compositeOnHost_.empty()) {
            out.msCreate = MsSince(start);
            const auto composing = std::chrono::steady_clock::now();
            std::vector<glm::vec4> corners;
            for (const SolidBox& box : SolidBoxes(h, solid, thin)) {
                corners.emplace_back(box.lo, 0.0f);
                corners.emplace_back(box.hi, 0.0f);
            }
            if (composite_->Composite(h, device_->FrontArea(), solid, corners, thin, all, out)) {
                compositedOnDevice_ = true;
                if (!perFrame) scratch_ = std::make_unique<Scratch>();
                out.msPush = MsSince(composing);
                return;
            }
            compositeOnHost_ = composite_->Why();
        }
    }
    // The ends of this build: the kept ones of the roots it met, then the fresh ones (a
    // full build with `moving` takes its kept ends from kept_ too).
    if (keeps)
        for (uint32_t r = 0; r + 1 < kept_.first.size(); ++r) used.push_back(r);
    // The recorded ends (and the kept ones) by (node, bin), each slot's nearest first. The
    // sources (each thread's ends, the kept roots' in chunks) are counted and scattered by
    // node side by side, then each node's ends by bin and each slot by depth, node by node.
    // The order the sources are read in never shows: no two ends of a slot tie on depth and
    // sender.
    std::vector<std::vector<EndRange>> sources;
    for (const auto& v : recorded)
        if (!v.empty()) sources.push_back({{v.data(), v.data() + v.size()}});
    const size_t chunk = std::max<size_t>(1, (used.size() + 15) / 16);
    for (size_t u = 0; u < used.size(); u += chunk) {
        std::vector<EndRange>& ranges = sources.emplace_back();
        for (size_t k = u; k < std::min(used.size(), u + chunk); ++k)
            ranges.push_back({kept_.ends.data() + kept_.first[used[k]],
                              kept_.ends.data() + kept_.first[used[k] + 1]});
    }
    if (closest_) {  // the paper's closest link a slot instead of the layer below
        out.msCreate = MsSince(start);
        start = std::chrono::steady_clock::now();
        BuildClosest(h, sources, out);
        if (!perFrame) scratch_ = std::make_unique<Scratch>();
        out.msPush = MsSince(start);
        return;
    }
    const uint32_t binCount = uint32_t(bins);
    // An end's node, slot / bins, as a multiply (the division was a tenth of the counting and
    // the scatter below): exact for every 32-bit slot with m = ⌊2⁴²/bins⌋ + 1, as bins ≤ 2¹⁰.
    static_assert(Directions::kMaxBins <= 1024);
    const uint64_t magic = (uint64_t(1) << 42) / bins + 1;
    auto nodeOf = [magic](uint32_t slot) {
        return uint32_t((static_cast<unsigned __int128>(slot) * magic) >> 42);
    };
    const size_t nodeCount = nodes.size();
    std::vector<std::vector<uint32_t>> at(sources.size());  // per source and node: its place
    tbb::parallel_for(size_t(0), sources.size(), [&](size_t s) {
        at[s].assign(nodeCount, 0);
        for (const auto& [b, e] : sources[s])
            for (const End* p = b; p != e; ++p) ++at[s][nodeOf(p->slot)];
    });
    std::vector<size_t> nodeFirst(nodeCount + 1);
    size_t total = 0;
    for (size_t n = 0; n < nodeCount; ++n) {
        nodeFirst[n] = total;
        for (auto& a : at) total += std::exchange(a[n], uint32_t(total));
    }
    nodeFirst[nodeCount] = total;
    PENUMBRA_CHECK(total < 0xffffffffu);  // `first` holds them as 32 bits
    scratch_->byNode.resize(total);
    scratch_->ends.resize(total);
    End* const byNode = scratch_->byNode.data();
    End* const ends = scratch_->ends.data();
    tbb::parallel_for(size_t(0), sources.size(), [&](size_t s) {
        uint32_t* fill = at[s].data();
        for (const auto& [b, e] : sources[s])
            for (const End* p = b; p != e; ++p) byNode[fill[nodeOf(p->slot)]++] = *p;
    });
    // Each node's ends by bin, each bin's run nearest first. A node's occupied bins are bits
    // (`occupied`), and run j of node n (its j-th occupied bin) spans ends[runs[runFirst[n] +
    // j], runs[runFirst[n] + j + 1]): a few megabytes, where a start for every (node, bin)
    // slot was 30 MB a frame to write.
    const size_t words = (bins + 63) / 64;
    std::vector<uint64_t>& occupied = scratch_->occupied;  // every word written below
    occupied.resize(nodeCount * words);
    std::vector<uint32_t>& runFirst = scratch_->runFirst;
    runFirst.resize(nodeCount + 1);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nodeCount, 64), [&](const auto& range) {
        for (size_t n = range.begin(); n != range.end(); ++n) {
            uint64_t* occ = occupied.data() + n * words;
            std::fill(occ, occ + words, uint64_t(0));
            const uint32_t base = uint32_t(n) * binCount;
            for (size_t k = nodeFirst[n]; k < nodeFirst[n + 1]; ++k) {
                const uint32_t b = byNode[k].slot - base;
                occ[b >> 6] |= uint64_t(1) << (b & 63);
            }
            uint32_t count = 0;
            for (size_t w = 0; w < words; ++w) count += uint32_t(std::popcount(occ[w]));
            runFirst[n] = count + 1;  // its runs' starts and its end, summed below
        }
    });
    for (size_t n = 0, sum = 0; n <= nodeCount; ++n)
        sum += std::exchange(runFirst[n], uint32_t(sum));
    std::vector<uint32_t>& runs = scratch_->runs;
    runs.resize(runFirst[nodeCount]);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, nodeCount, 32), [&](const auto& range) {
        std::vector<uint32_t> fill(bins, 0u);  // per bin: its count, then where its next end goes
        for (size_t n = range.begin(); n != range.end(); ++n) {
            const uint32_t lo = uint32_t(nodeFirst[n]), hi = uint32_t(nodeFirst[n + 1]);
            const uint32_t base = uint32_t(n) * binCount;
            const uint64_t* occ = occupied.data() + n * words;
            uint32_t* run = runs.data() + runFirst[n];
            for (uint32_t k = lo; k < hi; ++k) ++fill[byNode[k].slot - base];
            uint32_t j = 0, o = lo;
            for (size_t w = 0; w < words; ++w)
                for (uint64_t bits = occ[w]; bits; bits &= bits - 1) {
                    const uint32_t b = uint32_t(w * 64 + std::countr_zero(bits));
                    run[j++] = o;
                    o += std::exchange(fill[b], o);
                }
            run[j] = hi;
            for (uint32_t k = lo; k < hi; ++k) ends[fill[byNode[k].slot - base]++] = byNode[k];
            for (uint32_t r = 0; r < j; ++r) {
                if (run[r + 1] - run[r] > 1)
                    std::sort(ends + run[r], ends + run[r + 1], [](const End& x, const End& y) {
                        // The sender breaks ties: the order never depends on the threads.
                        return x.dist < y.dist || (x.dist == y.dist && x.sender < y.sender);
                    });
            }
            for (size_t w = 0; w < words; ++w)  // `fill` back to zeros for the next node
                for (uint64_t bits = occ[w]; bits; bits &= bits - 1)
                    fill[w * 64 + std::countr_zero(bits)] = 0;
        }
    });
    out.msCreate = MsSince(start);

    // RefineHierarchicalLinks + PushdownLinks, as front-to-back coverage: each leaf bin takes
    // the links of the leaf and its ancestors in that bin, nearest first, each covering its
    // solid angle of what the nearer ones left, until the bin is full (Eq. 5's closest
    // element, extended to the closest layer: a small light covers its own solid angle and
    // the ceiling around it the rest; a face hides what lies behind it). What no link covers
    // sees the environment.
    start = std::chrono::steady_clock::now();
    const size_t leaves = h.leaves.size();
    // A thin solid's far faces fill a bin only inside the solid's outline, where its near
    // faces' ends left gaps (SolidBoxes).
    const std::vector<SolidBox> boxes = SolidBoxes(h, solid, thin);
    std::vector<std::vector<Entry>>& perLeaf = scratch_->perLeaf;
    perLeaf.resize(leaves);
    // A closed solid's flat senders met in one bin so far: the solid angles of those facing
    // the leaf and of those turned away, the nearest facing one and its depth.
    struct SolidCover {
        uint32_t solid;
        float facing, away, near;
        uint32_t front;
    };
    using Head = std::pair<const End*, const End*>;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves, 64), [&](const auto& range) {
        // The leaf's chain (its ancestors and itself, root first), and per bin the runs of the
        // chain's nodes that hold ends there, in the same order. The leaves come in the
        // hierarchy's pre-order (a node's subtree is [n, end)), so the next leaf's chain keeps
        // the part it shares: a node's runs are pushed when the walk enters it and popped
        // when it leaves, not looked up again for every leaf and bin.
        std::vector<uint32_t> chain;
        std::vector<std::vector<Head>>& atBin = scratch_->stacks.local();
        atBin.resize(bins);
        auto enter = [&](uint32_t n) {
            chain.push_back(n);
            const uint32_t* run = runs.data() + runFirst[n];
            const uint64_t* occ = occupied.data() + n * words;
            for (size_t w = 0; w < words; ++w)
                for (uint64_t bits = occ[w]; bits; bits &= bits - 1, ++run)
                    atBin[w * 64 + std::countr_zero(bits)].push_back(
                        {ends + run[0], ends + run[1]});
        };
        auto leave = [&]() {
            const uint64_t* occ = occupied.data() + size_t(chain.back()) * words;
            chain.pop_back();
            for (size_t w = 0; w < words; ++w)
                for (uint64_t bits = occ[w]; bits; bits &= bits - 1)
                    atBin[w * 64 + std::countr_zero(bits)].pop_back();
        };
        std::vector<Head> heads;
        std::vector<SolidCover> solids;
        // Per leaf: the bins where each solid's near faces were met (solid, bin, sender), and
        // the shares of its far faces in bins without them (share index, solid).
        struct Front {
            uint32_t solid, bin, sender;
        };
        std::vector<Front> fronts;
        std::vector<std::pair<size_t, uint32_t>> unseen;
        // Per bin the solid angle its shares cover (−1: not a front bin) and its cosine to the
        // leaf's normal; the bins not covered whole, with their shares' range in the leaf's
        // list.
        std::vector<float> cover(bins), rise(bins);
        struct Partial {
            uint32_t bin;
            size_t first, end;
        };
        std::vector<Partial> partial;
        // A bin more than a spacing above the receiver's horizon lies above it whole (one
        // nearer the horizon is partly below it, where nothing covers it).
        const float aboveHorizon = std::sin(dirs_.Spacing());
        for (size_t i = range.begin(); i != range.end(); ++i) {
            const uint32_t leaf = h.leaves[i];
            while (!chain.empty() && !(chain.back() <= leaf && leaf < nodes[chain.back()].end))
                leave();
            if (chain.empty()) enter(0);
            for (uint32_t n = chain.back(); n != leaf;) {
                const uint32_t left = n + 1, right = nodes[left].end;
                n = leaf < right ? left : right;
                enter(n);
            }
            const glm::vec3& normal = nodes[leaf].normal;
            const glm::vec3& centre = nodes[leaf].center;
            const float norm = dirs_.CosineNorm(normal);
            std::vector<Entry>& list = perLeaf[i];
            list.clear();
            fronts.clear();
            unseen.clear();
            partial.clear();
            std::fill(cover.begin(), cover.end(), -1.0f);
            for (size_t b = 0; b < bins; ++b) {
                const glm::vec3& w = dirs_.Direction(uint32_t(b));
                const float c = glm::dot(normal, w);
                rise[b] = c;
                if (!(c > 0.0f)) continue;
                // The chain's slots for this bin, each sorted nearest first, merged until
                // the bin is full (most fill after a few links).
                // (The leaf's first: of two ends at one depth, the nearer node's is taken.)
                heads.assign(atBin[b].rbegin(), atBin[b].rend());
                const size_t bin0 = list.size();
                float left = omegaBin;
                solids.clear();
                while (left > 1e-4f * omegaBin) {
                    std::pair<const End*, const End*>* next = nullptr;
                    for (auto& h : heads)
                        if (h.first != h.second && (!next || h.first->dist < next->first->dist))
                            next = &h;
                    if (!next) break;
                    const End& e = *next->first++;
                    float omega = e.omega;
                    uint32_t sender = e.sender;
                    bool farOnly = false;  // a solid's far face, none of its near ones in the bin
                    const uint32_t of = solid.empty() ? kNoSolid : solid[e.sender];
                    // A flat sender of a closed solid is a near face (it faces the leaf) or
                    // a far one. A cluster of one is a far face where it shows the leaf more
                    // than twice the area turned away from it that it turns towards it: read
                    // through the tables it would be nearly black where the solid's near faces
                    // left the bin part covered (the white furnace room with two boxes was
                    // 2.2% low, 1.1 points of it such clusters, a box's far side and its top
                    // at a corner, at 0.06 m). A cluster that shows both sides alike (a whole
                    // solid: closed, it shows as much either way) stays as it was: seen from
                    // inside (a floor under a box without a bottom) it is no near face.
                    const bool flat = nodes[e.sender].coneCos >= kFlatCone;
                    auto turnedAway = [&] {
                        const float* row = frontArea.data() + size_t(e.sender) * bins;
                        return row[b] > 2.0f * row[dirs_.Opposite(uint32_t(b))];
                    };
                    if (of != kNoSolid && (flat || turnedAway())) {
                        const HierarchyNode& s = nodes[e.sender];
                        const bool facing = flat && glm::dot(s.normal, centre - s.center) > 0.0f;
                        auto it = std::find_if(solids.begin(), solids.end(),
                                               [&](const SolidCover& c) { return c.solid == of; });
                        if (it == solids.end())
                            it = solids.insert(solids.end(), {of, 0.0f, 0.0f, e.dist, e.sender});
                        if (facing) {
                            if (it->facing == 0.0f) {
                                it->near = e.dist;
                                it->front = e.sender;
                                fronts.push_back({of, uint32_t(b), e.sender});
                            }
                            it->facing += omega;
                        } else if (it->facing > 0.0f) {
                            // Behind the solid's near faces by `thin` or more, across the
                            // solid (along the far face's normal), or at the outline of a
                            // thin one (the bin's cone leaves its box: at a slab's edge the
                            // far face would add to the near one's cover of the bin what
                            // lies beyond the slab): it adds only what it covers beyond
                            // them. Either way what it covers stands for the solid as seen
                            // from here, its near face (black, it would darken the gaps the
                            // near faces' ends leave).
                            if ((e.dist - it->near) * std::abs(glm::dot(s.normal, w)) >= thin ||
                                !boxes[of].Holds(centre, w, binRadius_, normal)) {
                                const float before = std::max(it->facing, it->away);
                                it->away += omega;
                                omega = std::max(it->facing, it->away) - before;
                            }
                            sender = it->front;
                        } else {
                            farOnly = true;
                        }
                    }
                    const float take = std::min(left, omega);
                    if (!(take > 0.0f)) continue;
                    if (farOnly) unseen.push_back({list.size(), of});
                    list.push_back({uint32_t(b), sender, c * norm * take});
                    left -= take;
                }
                cover[b] = omegaBin - left;
                if (left > 1e-4f * omegaBin) partial.push_back({uint32_t(b), bin0, list.size()});
            }
            // A bin partly covered (kFillCoverage or more) is a surface the discretisation left
            // gaps in (its ends' centres fall into the bins unevenly): its shares fill it,
            // unless a front bin next to it, above the horizon, is nearly empty
            // (kEdgeCoverage): then it lies at the edge of what is there, against the
            // environment (a blocker's silhouette under a sky: filled, its bins would make it
            // look larger than it is). What a bin's shares leave unfilled shows the
            // environment.
            for (const Partial& p : partial) {
                float left = omegaBin - cover[p.bin];
                bool fill = cover[p.bin] >= kFillCoverage * omegaBin;
                for (uint32_t j : dirs_.Adjacent(p.bin))
                    if (fill && cover[j] >= 0.0f && cover[j] < kEdgeCoverage * omegaBin &&
                        rise[j] > aboveHorizon)
                        fill = false;
                if (fill) {
                    const float scale = omegaBin / cover[p.bin];
                    for (size_t k = p.first; k < p.end; ++k) list[k].weight *= scale;
                    left = 0.0f;
                }
                if (left > 1e-4f * omegaBin)
                    list.push_back({p.bin, kNoSender, rise[p.bin] * norm * left});
            }
            // A solid whose near faces this leaf sees somewhere has it outside: its far faces
            // lie behind near ones everywhere, also where the near faces' ends fell into
            // other bins; such a share shows the near face met in the closest bin. A leaf
            // that sees only far faces of a solid is inside it (a floor under a box without
            // a bottom): they block, black.
            for (const auto& [k, of] : unseen) {
                const glm::vec3& w = dirs_.Direction(list[k].bin);
                float best = -2.0f;
                for (const Front& f : fronts)
                    if (f.solid == of) {
                        const float cw = glm::dot(w, dirs_.Direction(f.bin));
                        if (cw > best) best = cw, list[k].sender = f.sender;
                    }
            }
        }
        while (!chain.empty()) leave();  // the thread's stacks empty for its next task
    });
    WriteShares(h, out);
    if (!perFrame) scratch_ = std::make_unique<Scratch>();  // no relink a frame expected
    out.msPush = MsSince(start);
}

void ImplicitLinker::WriteShares(const Hierarchy& h, ImplicitLinks& out) const {
    // Each leaf's shares (Scratch::perLeaf) one after another, and how each sender's light is
    // read (ImplicitLinks::travel).
    const auto& nodes = h.nodes;
    const size_t leaves = h.leaves.size();
    const std::vector<std::vector<Entry>>& perLeaf = scratch_->perLeaf;
    out.offsets.assign(leaves + 1, 0);
    for (size_t i = 0; i < leaves; ++i)
        out.offsets[i + 1] = out.offsets[i] + uint32_t(perLeaf[i].size());
    const size_t count = out.offsets[leaves];
    out.bin.resize(count);
    out.sender.resize(count);
    out.weight.resize(count);
    out.travel.resize(count);
    std::atomic<size_t> empty{0};
    tbb::parallel_for(size_t(0), leaves, [&](size_t i) {
        const uint32_t leaf = h.leaves[i];
        size_t k = out.offsets[i], none = 0;
        for (const Entry& e : perLeaf[i]) {
            out.bin[k] = e.bin;
            out.sender[k] = e.sender;
            out.weight[k] = e.weight;
            if (e.sender == kNoSender) {
                out.travel[k] = dirs_.Opposite(e.bin);
                ++none;
            } else {
                const HierarchyNode& from = nodes[e.sender];
                const glm::vec3 toLeaf = nodes[leaf].center - from.center;
                if (from.coneCos >= kFlatCone)
                    out.travel[k] = glm::dot(from.normal, toLeaf) > 0.0f ? kFacing : kAway;
                else
                    out.travel[k] = glm::dot(toLeaf, toLeaf) > 0.0f
                                        ? dirs_.Lookup(glm::normalize(toLeaf))
                                        : dirs_.Opposite(e.bin);
            }
            ++k;
        }
        empty += none;
    });
    out.empty = empty;
}

void ImplicitLinker::BuildClosest(const Hierarchy& h,
                                  const std::vector<std::vector<EndRange>>& sources,
                                  ImplicitLinks& out) {
    // CreateHierarchicalLinks' per-bin minimum (Sec. 4.2.2): every end keeps its slot's
    // closest, as a 64-bit (depth bits, sender) key by compare-and-swap (a positive float's
    // bits order as it does; the sender breaks ties, so the threads' order never shows).
    const auto& nodes = h.nodes;
    const size_t bins = static_cast<size_t>(dirs_.Count());
    constexpr uint64_t kNone = ~uint64_t(0);
    auto start = std::chrono::steady_clock::now();
    std::vector<uint64_t>& best = scratch_->closest;
    best.resize(nodes.size() * bins);
    tbb::parallel_for(tbb::blocked_range<size_t>(0, best.size(), 1 << 16), [&](const auto& r) {
        std::fill(best.begin() + r.begin(), best.begin() + r.end(), kNone);
    });
    tbb::parallel_for(size_t(0), sources.size(), [&](size_t l) {
        for (const auto& [first, last] : sources[l])
            tbb::parallel_for(
                tbb::blocked_range<const End*>(first, last, 4096), [&](const auto& r) {
                    for (const End* p = r.begin(); p != r.end(); ++p) {
                        // The slots are scattered over the table: fetch a few ends ahead.
                        constexpr size_t kAhead = 16;
                        if (size_t(r.end() - p) > kAhead)
                            __builtin_prefetch(&best[p[kAhead].slot], 1);
                        const uint64_t key =
                            uint64_t(std::bit_cast<uint32_t>(p->dist)) << 32 | p->sender;
                        std::atomic_ref<uint64_t> slot(best[p->slot]);
                        uint64_t old = slot.load(std::memory_order_relaxed);
                        while (key < old &&
                               !slot.compare_exchange_weak(old, key, std::memory_order_relaxed)) {
                        }
                    }
                });
    });
    out.msCreate += MsSince(start);
    PushClosest(h, out);
}

void ImplicitLinker::PushClosest(const Hierarchy& h, ImplicitLinks& out) {
    const auto& nodes = h.nodes;
    const size_t bins = static_cast<size_t>(dirs_.Count());
    const float omegaBin = dirs_.BinSolidAngle();
    constexpr uint64_t kNone = ~uint64_t(0);
    std::vector<uint64_t>& best = scratch_->closest;
    PENUMBRA_CHECK_EQ(best.size(), nodes.size() * bins);
    // RefineHierarchicalLinks + PushdownLinks (Sec. 4.2.3–4.2.4): each node's slots take its
    // parent's where those are closer, top down; then each leaf's front bins are its closest
    // links, each covering the bin, or the environment where there is none. The nodes above
    // kSplit levels one after another, then each subtree below them in a task of its own, in
    // pre-order (a parent's row before its children's, still in cache), its leaves' shares
    // made as the walk reaches them.
    constexpr uint32_t kSplit = 6;
    auto push = [&](uint32_t n) {
        uint64_t* row = best.data() + size_t(n) * bins;
        const uint64_t* up = best.data() + size_t(nodes[n].parent) * bins;
        for (size_t b = 0; b < bins; ++b) row[b] = std::min(row[b], up[b]);
    };
    std::vector<uint32_t> tasks;  // the subtrees' roots
    for (uint32_t n = 0; n < nodes.size();) {
        if (nodes[n].depth < kSplit && !nodes[n].IsLeaf()) {
            if (n != 0) push(n);
            ++n;
        } else {
            tasks.push_back(n);
            n = nodes[n].end;
        }
    }
    const size_t leaves = h.leaves.size();
    std::vector<std::vector<Entry>>& perLeaf = scratch_->perLeaf;
    perLeaf.resize(leaves);
    tbb::parallel_for(size_t(0), tasks.size(), [&](size_t t) {
        const uint32_t root = tasks[t];
        size_t i = size_t(std::lower_bound(h.leaves.begin(), h.leaves.end(), root) -
                          h.leaves.begin());  // the subtree's first leaf
        for (uint32_t n = root; n < std::max(nodes[root].end, root + 1); ++n) {
            if (n != 0) push(n);
            if (!nodes[n].IsLeaf()) continue;
            const uint64_t* row = best.data() + size_t(n) * bins;
            std::vector<Entry>& list = perLeaf[i++];
            list.clear();
            for (size_t b = 0; b < bins; ++b) {  // cos⁺ a front bin, normalised below
                const float c = glm::dot(nodes[n].normal, dirs_.Direction(uint32_t(b)));
                if (!(c > 0.0f)) continue;
                const uint32_t sender = row[b] == kNone ? kNoSender : uint32_t(row[b]);
                list.push_back({uint32_t(b), sender, c});
            }
            // Directions::CosineNorm from the same cosines: Σ weight = π.
            double sum = 0.0;
            for (const Entry& e : list) sum += e.weight;
            const float scale = dirs_.CosineNormOfSum(sum) * omegaBin;
            for (Entry& e : list) e.weight *= scale;
        }
    });
    WriteShares(h, out);
}

void ImplicitLinker::Record(uint32_t node, uint32_t sender, const HierarchyNode& from,
                            const glm::vec3& at, const glm::vec3& dir, float dist, float omega,
                            uint32_t centre, float shows, std::vector<End>& ends) const {
    const size_t bins = static_cast<size_t>(dirs_.Count());
    const size_t row = size_t(node) * bins;
    // How far along bin axis `w` from the receiver's centre the sender lies, for the bin's
    // front-to-back order: a flat sender's plane is met at dot(n, c − at) / dot(n, w). A leaf
    // (a disc) is ordered by its plane along the axis of the bin, the same axis for every end
    // of the bin, wherever its centre lies: two stacked faces (a lamp 1 cm under the ceiling,
    // books on a shelf) sort by their planes. By its own direction (its centre's distance),
    // a ceiling leaf beside the lamp came before a lamp leaf farther out, and the closest
    // layer gave the ceiling the lamp's share of the bin: a panel 1 cm under a black ceiling
    // lit the floor 0.82 of its light at 128 bins, 0.70 at 864
    // (Implicit.LampUnderACeilingLightsTheFloor). Within dist ± its radius, where every
    // point of it lies: a plane met far beyond the disc (the axis nearly along it) does not
    // put the leaf behind what it hides. A flat cluster's members lie about its plane, not
    // on it: its plane along the axis, at most its centre's distance (measured: beyond it,
    // the deforming room of Implicit.ADeformingMeshOverAHundredFramesStaysBoundedAndSmooth
    // changed 3.5% between frames, against 2.4%). Another cluster, or a face seen edge-on, by
    // its centre's distance.
    auto depth = [&](const glm::vec3& w) {
        if (from.coneCos < kFlatCone) return dist;
        const float facing = glm::dot(from.normal, w);
        if (std::abs(facing) < 0.2f) return dist;
        const float t = glm::dot(from.normal, from.center - at) / facing;
        if (!(t > 0.0f)) return dist;
        return from.IsLeaf() ? std::clamp(t, dist - from.radius, dist + from.radius)
                             : std::min(t, dist);
    };
    // An end that cannot be split and still looks wider than half a bin's spacing (a leaf
    // next to its receiver: a contact, a corner) covers every bin its disc (the angular
    // radius of its bounding sphere) overlaps, each by the overlap (LensArea, the bin taken
    // as a disc of its solid angle, at most the bin): else the neighbouring bins would stay
    // empty and read the environment or nothing (the paper's leak at elements larger than a
    // bin). Covering only the bins whose centres the disc holds, each whole, left the bins
    // between the discs of a wall's small leaves near a floor empty (the maze: 5.5% of the
    // leaves' cosine weight seeing nothing above the horizon). A bin the disc overlaps lies
    // within ρ + r_bin of `dir` (Directions::ForEachWithin finds those). A flat sender
    // covers only the bins whose axes meet its plane near its disc (MeetsFlatSender): seen
    // edge-on from a corner, its bounding sphere's cone would also take the bins that look
    // past it into the room (a room's edges came out half as bright as the truth's).
    const float sinRadius = from.radius / dist;
    if (!closest_ && sinRadius > splat_) {
        const float rho = std::asin(std::min(1.0f, sinRadius));
        const float omegaBin = dirs_.BinSolidAngle();
        // Bins nearer than |ρ − r_bin| lie inside the disc (or hold it) whole: LensArea's
        // first case, without the arc cosine.
        const float small = std::min(rho, binRadius_);
        const float cosInside = std::cos(std::abs(rho - binRadius_));
        const float inside = std::min(omegaBin, std::numbers::pi_v<float> * small * small);
        const bool flat = from.coneCos >= kFlatCone;
        const float height = glm::dot(from.normal, from.center - at);
        // A cluster seen foreshortened (`shows` < 1) covers of each bin its overlap with the
        // ellipse its disc projects to, the minor axis ρ · shows along m (its normal off
        // `dir`): squeezed by 1 / shows along m, the ellipse is the disc, and a bin an ellipse
        // the area of a disc of radius r_bin / √shows. A leaf keeps its whole disc (a contact).
        const bool squeeze = !from.IsLeaf() && shows < 0.999f;
        glm::vec3 m(0.0f);
        if (squeeze) m = glm::normalize(from.normal - glm::dot(from.normal, dir) * dir);
        const float squeezedBin = squeeze ? binRadius_ / std::sqrt(shows) : binRadius_;
        // Every bin within reach (ρ + r_bin of `dir`, near the centre bin): whether its axis
        // meets a flat sender, then its overlap.
        auto spread = [&](uint32_t b, const glm::vec3& w, float c) {
            if (flat && !MeetsFlatSender(height, from.center, from.normal, from.discRadius, at, w,
                                         binRadius_))
                return;
            float a;
            if (squeeze) {
                const glm::vec3 o = w - dir;
                const float across = glm::dot(o, m);
                const float apart = std::sqrt(std::max(0.0f, glm::dot(o, o) - across * across) +
                                              across * across / (shows * shows));
                a = std::min(omegaBin, shows * LensArea(apart, rho, squeezedBin));
            } else {
                a = c >= cosInside
                        ? inside
                        : std::min(omegaBin, LensArea(std::acos(std::clamp(c, -1.0f, 1.0f)), rho,
                                                      binRadius_));
            }
            if (a > kMinOverlap * omegaBin)
                ends.push_back({uint32_t(row + b), sender, depth(w), a});
        };
        const float theta =
            std::acos(std::clamp(glm::dot(dir, dirs_.Direction(centre)), -1.0f, 1.0f));
        // A bin farther than OverlapReach overlaps a disc by less than kMinOverlap (squeezed,
        // by less than the disc does).
        dirs_.ForEachWithin(centre, theta, dir, squeeze ? rho + binRadius_ : OverlapReach(rho),
                            spread);
        return;
    }
    ends.push_back({uint32_t(row + centre), sender, depth(dirs_.Direction(centre)), omega});
}

}  // namespace penumbra
