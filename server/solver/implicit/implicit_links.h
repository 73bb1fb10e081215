// Implicit visibility (Dong et al. 2007, Sec. 4.2): links rebuilt from scratch every frame,
// each node's directions cut into bins, and per (node, bin) only the closest link kept
// (Eq. 5: the closest element in a bin covers it, so whatever lies behind it is hidden).
// Visibility is never tested; it falls out of the closest-link rule.
//
// CPU back end (TBB). CreateHierarchicalLinks walks candidate pairs level by level from the
// root's self-pair (the data-parallel link creation of Meyer et al. 2009): a pair is split
// while an end subtends more than linkThreshold × ω_bin from the other (Sec. 4.2.2), else it
// becomes a link at both ends, written into the (node, bin) slot with an atomic minimum of
// the 64-bit key (distance bits << 32 | sender). RefineHierarchicalLinks and PushdownLinks
// fold into one top-down pass (Sec. 4.2.3, 4.2.4): each leaf bin takes the shortest link
// among itself and its ancestors. The leaves' front bins are then compacted into a list per
// leaf; a front bin without a link sees the environment (Sec. 4.4).
#pragma once

#include <cstdint>
#include <vector>

#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"

namespace penumbra {

inline constexpr uint32_t kNoSender = 0xffffffffu;
// ImplicitLinks::travel of a flat sender (a leaf, or a cluster whose normals lie within
// kFlatCone of each other): it faces the receiver (its mean radiance arrives), or it is
// turned away (a blocker: nothing arrives).
inline constexpr uint32_t kFacing = 0xfffffffeu;
inline constexpr uint32_t kAway = 0xfffffffdu;
inline constexpr float kFlatCone = 0.9f;  // cos 25.8°

struct ImplicitLinks {
    // Per leaf (hierarchy leaf order), its front bins [offsets[i], offsets[i + 1]): the bin
    // (direction from the leaf towards what it sees), the closest sender node in it
    // (kNoSender: none, the environment), and the bin's weight cos⁺θ · ω_bin · CosineNorm(n),
    // so that Σ weight · L = E and a leaf with every bin at radiance L receives exactly π L.
    std::vector<uint32_t> offsets;
    std::vector<uint32_t> bin;
    std::vector<uint32_t> sender;
    std::vector<float> weight;
    // How the sender's light is read: a flat sender's exactly (kFacing, kAway: whether it
    // faces the receiver; a bin would misjudge a sender seen edge-on), another cluster's
    // through the bin of the direction from its centre to the leaf (its light travels along
    // it).
    std::vector<uint32_t> travel;
    size_t pairs = 0;   // candidate pairs the last build examined
    size_t linked = 0;  // pairs that became links (each written at up to two ends)
    size_t empty = 0;   // front bins without a sender
    double msCreate = 0.0, msPush = 0.0;

    size_t Count() const { return sender.size() - empty; }  // filled front bins
};

class ImplicitLinker {
  public:
    ImplicitLinker(const Directions& dirs, float linkThreshold);
    // The links of `hierarchy` as it is placed now.
    void Build(const Hierarchy& hierarchy, ImplicitLinks& out);

  private:
    // Writes `key` into `node`'s slot of direction `dir` (and of every bin within the other
    // end's angular radius, asin(sinRadius), when that is wider than a bin).
    void Store(uint32_t node, const glm::vec3& dir, float sinRadius, uint64_t key);
    const Directions& dirs_;
    float threshold_;
    float splat_ = 0.0f;           // sin of the angular radius above which an end is spread
    std::vector<uint64_t> slots_;  // nodes × bins keys (scratch, kept between frames)
};

}  // namespace penumbra
