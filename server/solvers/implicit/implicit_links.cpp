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
#include "solvers/implicit/link_geometry.h"
#include "solvers/implicit/vulkan_composite.h"
#include "solvers/implicit/vulkan_links.h"

namespace penumbra {
namespace link_geometry {

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

}  // namespace link_geometry

using namespace link_geometry;

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

// One build's rounds of pairs on the CPU (CreateHierarchicalLinks, level by level: each round
// splits or links every pair of the last round, in parallel; a link is recorded at each end
// that can receive), and the ends kept for the next build.
//
// Kept pairs (both nodes outside `moving`): which of them a build meets depends on how the
// pairs above them, with a moving end, were split; what a kept pair yields (its descendants'
// ends) does not. So the first kept pair of each lineage (a root, its parent pair had a moving
// end) is numbered, its descendants carry its number, and their ends, pairs and links are kept
// per root; a later build given the same `moving` takes a root's ends where it meets that
// root, and splits any other kept pair afresh.
struct ImplicitLinker::Rounds {
    static constexpr uint32_t kFresh = 0xffffffffu;  // a pair of no root (yet)
    struct KeptEnd {
        End end;
        uint32_t root;
    };
    ImplicitLinker& linker;
    const Hierarchy& h;
    const std::vector<float>& frontArea;
    const std::vector<float>& slab;  // SlabThickness
    const uint8_t* still;            // still[n] == 0: n is kept (null: nothing is)
    const bool keeps;                // this build keeps the ends of the kept pairs
    const float limit;               // the solid angle past which an end is split
    std::vector<float> sinCone;      // per node, ConeSine (filled by Run)
    tbb::enumerable_thread_specific<std::vector<KeptEnd>> keeping;
    // Per thread: new roots (pair key, number); per kept pair examined and per kept link,
    // its root (counted per root afterwards); roots taken (incremental).
    tbb::enumerable_thread_specific<std::vector<std::pair<uint64_t, uint32_t>>> roots;
    tbb::enumerable_thread_specific<std::vector<uint32_t>> examinedOf, linkedOf, taken;
    std::atomic<uint32_t> rootCount{0};
    std::atomic<size_t> pairs{0}, linked{0};

    Rounds(ImplicitLinker& linker, const Hierarchy& h, const std::vector<float>& frontArea,
           const std::vector<float>& slab, const uint8_t* still, bool keeps, float limit)
        : linker(linker),
          h(h),
          frontArea(frontArea),
          slab(slab),
          still(still),
          keeps(keeps),
          limit(limit) {}

    static uint64_t KeyOf(uint32_t a, uint32_t b) { return uint64_t(a) << 32 | b; }
    bool KeptPair(uint32_t a, uint32_t b) const { return still && !still[a] && !still[b]; }

    // The solid angle sender `s` covers seen from `r` along `dir` (unit, r → s) at `dist`: a
    // flat node's area times |cos| (turned away it still hides what is behind it), another
    // cluster's larger projected area (front or back: a closed solid shows one side).
    // `ahead` and `back`: the bins of the direction between the two ends and of its opposite
    // (the one its light travels along, and the other), looked up once a pair.
    float Covered(uint32_t s, const glm::vec3& dir, float dist, uint32_t ahead,
                  uint32_t back) const {
        const HierarchyNode& n = h.nodes[s];
        const float d2 = std::max(dist * dist, 1e-30f);
        if (n.coneCos >= kFlatCone) return n.area * std::abs(glm::dot(n.normal, dir)) / d2;
        const float* row = frontArea.data() + size_t(s) * linker.dirs_.Count();
        return std::max(row[back], row[ahead]) / d2;
    }

    // The rounds from the root's self-pair until no pair is left.
    void Run() {
        std::vector<Pair>& round = linker.scratch_->round;
        auto& next = linker.scratch_->next;
        const auto& nodes = h.nodes;
        sinCone.resize(nodes.size());
        tbb::parallel_for(size_t(0), nodes.size(),
                          [&](size_t n) { sinCone[n] = ConeSine(nodes[n]); });
        round.push_back({0, 0, kFresh});
        while (!round.empty()) {
            pairs += round.size();
            tbb::parallel_for(tbb::blocked_range<size_t>(0, round.size(), 512),
                              [&](const auto& range) {
                                  std::vector<Pair>& emit = next.local();
                                  std::vector<End>& fresh = linker.scratch_->recorded.local();
                                  size_t made = 0;
                                  for (size_t k = range.begin(); k != range.end(); ++k)
                                      made += Examine(round[k], emit, fresh);
                                  linked += made;
                              });
            round.clear();
            for (auto& v : next) {
                round.insert(round.end(), v.begin(), v.end());
                v.clear();
            }
        }
    }

    // One pair of a round: taken from a kept root, split (its child pairs into `emit`),
    // linked (its ends recorded into `fresh`, or kept with its root), or dropped. True when
    // it linked.
    bool Examine(const Pair& pair, std::vector<Pair>& emit, std::vector<End>& fresh) {
        const auto& nodes = h.nodes;
        const float pi = std::numbers::pi_v<float>;
        const uint32_t a = pair.a, b = pair.b;
        uint32_t root = pair.root;
        if (KeptPair(a, b)) {
            if (linker.incremental_) {
                // A root kept: its ends stand for all its descendants' (the pair itself is
                // counted with them).
                const auto it = linker.kept_.index.find(KeyOf(a, b));
                if (it != linker.kept_.index.end()) {
                    taken.local().push_back(it->second);
                    --pairs;
                    return false;
                }
            } else {
                if (root == kFresh) {
                    root = rootCount++;
                    roots.local().push_back({KeyOf(a, b), root});
                }
                examinedOf.local().push_back(root);
            }
        }
        const HierarchyNode& A = nodes[a];
        if (a == b) {  // a self-pair: its children's self-pairs and their pair
            if (A.IsLeaf()) return false;
            const uint32_t l = a + 1, r = nodes[a + 1].end;
            emit.push_back({l, l, root});
            emit.push_back({r, r, root});
            emit.push_back({l, r, root});
            return false;
        }
        const HierarchyNode& B = nodes[b];
        const glm::vec3 d = B.center - A.center;
        const float dist = glm::length(d);
        const bool aGets = CanReceive(A, sinCone[a], B, d, dist);
        const bool bGets = CanReceive(B, sinCone[b], A, -d, dist);
        if (!aGets && !bGets) return false;  // a pair's only use is what its ends receive
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
            return false;
        }
        if (splitB) {
            emit.push_back({a, b + 1, root});
            emit.push_back({a, nodes[b + 1].end, root});
            return false;
        }
        if (splitA) {
            emit.push_back({a + 1, b, root});
            emit.push_back({nodes[a + 1].end, b, root});
            return false;
        }
        if (!(dist > 0.0f)) return false;  // coincident ends: no direction between them
        const glm::vec3& dir = unit;
        const size_t before = fresh.size();
        const bool aRecords = aGets && AboveHorizon(A, dir);
        const bool bRecords = bGets && AboveHorizon(B, -dir);
        if (aRecords || bRecords) {
            const uint32_t ahead = linker.dirs_.Lookup(dir), back = linker.dirs_.Lookup(-dir);
            if (aRecords)
                linker.Record(a, b, B, A.center, dir, dist, Covered(b, dir, dist, ahead, back),
                              ahead, showsB, fresh);
            if (bRecords)
                linker.Record(b, a, A, B.center, -dir, dist, Covered(a, -dir, dist, back, ahead),
                              back, showsA, fresh);
        }
        if (keeps && root != kFresh) {  // this pair's ends are kept with its root
            for (size_t e = before; e < fresh.size(); ++e)
                keeping.local().push_back({fresh[e], root});
            fresh.resize(before);
            linkedOf.local().push_back(root);
        }
        return true;
    }

    // The kept ends grouped by root (a counting sort), the roots by pair, into linker.kept_.
    void Keep() {
        Kept& kept = linker.kept_;
        const uint32_t n = rootCount;
        kept.first.assign(size_t(n) + 1, 0);
        kept.pairs.assign(n, 0);
        kept.linked.assign(n, 0);
        for (const auto& v : keeping)
            for (const KeptEnd& e : v) ++kept.first[e.root + 1];
        for (uint32_t r = 0; r < n; ++r) kept.first[r + 1] += kept.first[r];
        kept.ends.resize(kept.first[n]);
        std::vector<uint32_t> fill(kept.first.begin(), kept.first.end() - 1);
        for (const auto& v : keeping)
            for (const KeptEnd& e : v) kept.ends[fill[e.root]++] = e.end;
        for (const auto& v : examinedOf)
            for (uint32_t r : v) ++kept.pairs[r];
        for (const auto& v : linkedOf)
            for (uint32_t r : v) ++kept.linked[r];
        kept.index.reserve(n);
        for (const auto& v : roots)
            for (const auto& [key, r] : v) kept.index.emplace(key, r);
    }

    // The roots taken, in a fixed order; `out` gets what a full build would count.
    std::vector<uint32_t> Taken(ImplicitLinks& out) const {
        std::vector<uint32_t> used;
        for (const auto& v : taken) used.insert(used.end(), v.begin(), v.end());
        std::sort(used.begin(), used.end());
        size_t pairsSum = pairs, linkedSum = linked;
        for (uint32_t r : used)
            pairsSum += linker.kept_.pairs[r], linkedSum += linker.kept_.linked[r];
        out.pairs = pairsSum;
        out.linked = linkedSum;
        return used;
    }
};

bool ImplicitLinker::CompositeOnDevice(const Hierarchy& h, const std::vector<uint32_t>& solid,
                                       float thin, ImplicitLinks& out, TimePoint start,
                                       bool perFrame) {
    // The device's ends are in the calling thread's list; joined if ever in several.
    std::vector<const std::vector<End>*> filled;
    for (const auto& v : scratch_->recorded)
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
    if (!compositeOnHost_.empty()) return false;
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
        return true;
    }
    compositeOnHost_ = composite_->Why();
    return false;
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
    const size_t bins = static_cast<size_t>(dirs_.Count());
    PENUMBRA_CHECK_EQ(frontArea.size(), nodes.size() * bins);
    PENUMBRA_CHECK(solid.empty() || solid.size() == nodes.size());
    auto start = std::chrono::steady_clock::now();
    const std::vector<float> slab = SlabThickness(h);
    scratch_->round.clear();
    for (auto& v : scratch_->next) v.clear();
    for (auto& v : scratch_->recorded) v.clear();
    const bool keeps = still && !incremental_;
    Rounds rounds(*this, h, frontArea, slab, still, keeps, threshold_ * dirs_.BinSolidAngle());
    // The rounds on the device (vulkan_links.h), its ends standing for the threads', or here.
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
        device->Create(h, frontArea, slab, scratch_->recorded.local(), devicePairs, deviceLinked);
        rounds.pairs = devicePairs;
        rounds.linked = deviceLinked;
    } else {
        rounds.Run();
    }
    if (keeps) rounds.Keep();
    std::vector<uint32_t> used = rounds.Taken(out);
    // The device's ends composited there (vulkan_composite.h), where they fit.
    compositedOnDevice_ = false;
    compositeOnHost_.clear();
    if (device && composite_ && CompositeOnDevice(h, solid, thin, out, start, perFrame)) return;
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
    for (const auto& v : scratch_->recorded)
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
    SortEnds(h, sources);
    out.msCreate = MsSince(start);

    // RefineHierarchicalLinks + PushdownLinks, as front-to-back coverage: each leaf bin takes
    // the links of the leaf and its ancestors in that bin, nearest first, each covering its
    // solid angle of what the nearer ones left, until the bin is full (Eq. 5's closest
    // element, extended to the closest layer: a small light covers its own solid angle and
    // the ceiling around it the rest; a face hides what lies behind it). What no link covers
    // sees the environment.
    start = std::chrono::steady_clock::now();
    Composite(h, frontArea, solid, thin);
    WriteShares(h, out);
    if (!perFrame) scratch_ = std::make_unique<Scratch>();  // no relink a frame expected
    out.msPush = MsSince(start);
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
