// Per-frame link creation, refinement and push-down (implicit_links.h).
#include "solver/implicit/implicit_links.h"

#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <numbers>

#include "base/check.h"

namespace penumbra {
namespace {

constexpr uint64_t kEmpty = ~0ull;
// Normal cones wider than this (cos of the half angle) are split before they are linked.
constexpr float kMixedCone = 0.0f;

double MsSince(std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

// Keeps the smaller of `slot` and `key`: the closer sender (Eq. 5's closest element).
void AtomicMin(uint64_t& slot, uint64_t key) {
    std::atomic_ref<uint64_t> ref(slot);
    uint64_t now = ref.load(std::memory_order_relaxed);
    while (key < now && !ref.compare_exchange_weak(now, key, std::memory_order_relaxed)) {
    }
}

// Whether some member of `r` can receive light from some point of `s`, `d` = s.center −
// r.center at distance `dist`: a member's front faces part of s's sphere. Conservative
// (normal cone widened by both spheres' angular radii).
bool CanReceive(const HierarchyNode& r, const HierarchyNode& s, const glm::vec3& d, float dist) {
    if (r.coneCos <= -1.0f) return true;
    const float reach = r.radius + s.radius;
    if (dist <= reach) return true;
    const float cosTheta = glm::dot(r.normal, d) / dist;
    const float theta = std::acos(std::clamp(cosTheta, -1.0f, 1.0f));
    const float cone = std::acos(std::clamp(r.coneCos, -1.0f, 1.0f));
    const float spread = std::asin(std::min(1.0f, reach / dist));
    return theta - cone - spread < 0.5f * std::numbers::pi_v<float>;
}

struct Pair {
    uint32_t a, b;
};

// Whether direction `dir` (unit) leaves `r` above the horizon of some member: a flat node
// does not see what lies in its own plane (coplanar neighbours would otherwise darken the
// grazing bins), a curved one sees down to its normal cone's edge.
bool AboveHorizon(const HierarchyNode& r, const glm::vec3& dir) {
    if (r.coneCos <= -1.0f) return true;
    const float below = std::sqrt(std::max(0.0f, 1.0f - r.coneCos * r.coneCos));
    return glm::dot(r.normal, dir) > 0.01f - below;
}

}  // namespace

ImplicitLinker::ImplicitLinker(const Directions& dirs, float linkThreshold)
    : dirs_(dirs), threshold_(linkThreshold) {
    if (!(linkThreshold > 0.0f)) throw Error("link threshold must be a positive number");
    // Ends wider than half a bin's spacing are spread over the bins they cover.
    splat_ = std::sin(0.5f * dirs.Spacing());
}

void ImplicitLinker::Store(uint32_t node, const glm::vec3& dir, float sinRadius, uint64_t key) {
    const size_t bins = static_cast<size_t>(dirs_.Count());
    uint64_t* row = slots_.data() + size_t(node) * bins;
    // An end that cannot be split and still looks wider than a bin (a leaf next to its
    // receiver: a contact, a corner) covers every bin its disc spans, not only the one of
    // its centre; else the neighbouring bins would stay empty and read the environment or
    // nothing (the paper's leak at elements larger than a bin).
    if (sinRadius > splat_) {
        const float cosRadius =
            std::sqrt(std::max(0.0f, 1.0f - std::min(1.0f, sinRadius) * std::min(1.0f, sinRadius)));
        for (size_t b = 0; b < bins; ++b)
            if (glm::dot(dirs_.Direction(uint32_t(b)), dir) >= cosRadius) AtomicMin(row[b], key);
    }
    AtomicMin(row[dirs_.Lookup(dir)], key);
}

void ImplicitLinker::Build(const Hierarchy& h, ImplicitLinks& out) {
    const auto& nodes = h.nodes;
    const size_t bins = static_cast<size_t>(dirs_.Count());
    const float limit = threshold_ * dirs_.BinSolidAngle();
    const float pi = std::numbers::pi_v<float>;
    auto start = std::chrono::steady_clock::now();
    slots_.assign(nodes.size() * bins, kEmpty);

    // CreateHierarchicalLinks, level by level: each round splits or links every pair of the
    // last round, in parallel.
    std::vector<Pair> round{{0, 0}};
    tbb::enumerable_thread_specific<std::vector<Pair>> next;
    std::atomic<size_t> pairs{0}, linked{0};
    while (!round.empty()) {
        pairs += round.size();
        tbb::parallel_for(tbb::blocked_range<size_t>(0, round.size(), 512), [&](const auto& range) {
            std::vector<Pair>& emit = next.local();
            size_t made = 0;
            for (size_t k = range.begin(); k != range.end(); ++k) {
                const uint32_t a = round[k].a, b = round[k].b;
                const HierarchyNode& A = nodes[a];
                if (a == b) {  // a self-pair: its children's self-pairs and their pair
                    if (A.IsLeaf()) continue;
                    const uint32_t l = a + 1, r = nodes[a + 1].end;
                    emit.push_back({l, l});
                    emit.push_back({r, r});
                    emit.push_back({l, r});
                    continue;
                }
                const HierarchyNode& B = nodes[b];
                const glm::vec3 d = B.center - A.center;
                const float dist = glm::length(d);
                const bool aGets = CanReceive(A, B, d, dist);
                const bool bGets = CanReceive(B, A, -d, dist);
                if (!aGets && !bGets) continue;  // a pair's only use is what its ends receive
                // Sec. 4.2.2: an end that looks bigger than a bin from the other is split.
                const bool overlap = dist <= A.radius + B.radius;
                const float dist2 = std::max(dist * dist, 1e-30f);
                // A sender whose members face more than 90° apart (a box's corner) shows
                // a mix of lit and hidden faces that no one radiance per direction stands
                // for: it is split too, into parts that each face one way.
                const bool splitA = !A.IsLeaf() && (overlap || A.coneCos < kMixedCone ||
                                                    pi * A.radius * A.radius / dist2 > limit);
                const bool splitB = !B.IsLeaf() && (overlap || B.coneCos < kMixedCone ||
                                                    pi * B.radius * B.radius / dist2 > limit);
                if (splitB && (!splitA || B.radius >= A.radius)) {
                    emit.push_back({a, b + 1});
                    emit.push_back({a, nodes[b + 1].end});
                    continue;
                }
                if (splitA) {
                    emit.push_back({a + 1, b});
                    emit.push_back({nodes[a + 1].end, b});
                    continue;
                }
                if (!(dist > 0.0f)) continue;  // coincident ends: no direction between them
                const uint64_t key = uint64_t(std::bit_cast<uint32_t>(dist)) << 32;
                const glm::vec3 dir = d / dist;
                if (aGets && AboveHorizon(A, dir)) Store(a, dir, B.radius / dist, key | b);
                if (bGets && AboveHorizon(B, -dir)) Store(b, -dir, A.radius / dist, key | a);
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
    out.pairs = pairs;
    out.linked = linked;
    out.msCreate = MsSince(start);

    // RefineHierarchicalLinks + PushdownLinks: parents first, each bin keeps the shorter of
    // its own link and its parent's (its ancestors', by then).
    start = std::chrono::steady_clock::now();
    for (size_t depth = 1; depth < h.byDepth.size(); ++depth) {
        const std::vector<uint32_t>& level = h.byDepth[depth];
        tbb::parallel_for(tbb::blocked_range<size_t>(0, level.size(), 64), [&](const auto& range) {
            for (size_t k = range.begin(); k != range.end(); ++k) {
                const uint32_t n = level[k];
                uint64_t* row = slots_.data() + size_t(n) * bins;
                const uint64_t* up = slots_.data() + size_t(nodes[n].parent) * bins;
                for (size_t b = 0; b < bins; ++b) row[b] = std::min(row[b], up[b]);
            }
        });
    }
    // The leaves' front bins, compacted.
    const size_t leaves = h.leaves.size();
    std::vector<uint32_t> counts(leaves + 1, 0);
    tbb::parallel_for(size_t(0), leaves, [&](size_t i) {
        const glm::vec3& n = nodes[h.leaves[i]].normal;
        uint32_t c = 0;
        for (size_t b = 0; b < bins; ++b) c += glm::dot(n, dirs_.Direction(uint32_t(b))) > 0.0f;
        counts[i + 1] = c;
    });
    out.offsets.assign(leaves + 1, 0);
    for (size_t i = 0; i < leaves; ++i) out.offsets[i + 1] = out.offsets[i] + counts[i + 1];
    const size_t total = out.offsets[leaves];
    out.bin.resize(total);
    out.sender.resize(total);
    out.weight.resize(total);
    out.travel.resize(total);
    std::atomic<size_t> empty{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, leaves, 64), [&](const auto& range) {
        size_t none = 0;
        for (size_t i = range.begin(); i != range.end(); ++i) {
            const uint32_t node = h.leaves[i];
            const glm::vec3& n = nodes[node].normal;
            const float norm = dirs_.CosineNorm(n) * dirs_.BinSolidAngle();
            const uint64_t* row = slots_.data() + size_t(node) * bins;
            size_t k = out.offsets[i];
            for (size_t b = 0; b < bins; ++b) {
                const float c = glm::dot(n, dirs_.Direction(uint32_t(b)));
                if (!(c > 0.0f)) continue;
                out.bin[k] = uint32_t(b);
                out.weight[k] = c * norm;
                if (row[b] == kEmpty) {
                    out.sender[k] = kNoSender;
                    out.travel[k] = dirs_.Lookup(-dirs_.Direction(uint32_t(b)));
                    ++none;
                } else {
                    const uint32_t sender = uint32_t(row[b]);
                    const HierarchyNode& from = nodes[sender];
                    const glm::vec3 toLeaf = nodes[node].center - from.center;
                    out.sender[k] = sender;
                    if (from.coneCos >= kFlatCone)
                        out.travel[k] = glm::dot(from.normal, toLeaf) > 0.0f ? kFacing : kAway;
                    else
                        out.travel[k] = glm::dot(toLeaf, toLeaf) > 0.0f
                                            ? dirs_.Lookup(glm::normalize(toLeaf))
                                            : dirs_.Lookup(-dirs_.Direction(uint32_t(b)));
                }
                ++k;
            }
        }
        empty += none;
    });
    out.empty = empty;
    out.msPush = MsSince(start);
}

}  // namespace penumbra
