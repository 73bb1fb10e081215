// Implicit visibility (Dong et al. 2007, Sec. 4.2): links rebuilt from scratch every frame,
// each node's directions cut into bins, and in each bin the closest links kept (Eq. 5: the
// closest element in a bin covers it, so whatever lies behind it is hidden). Visibility is
// never tested; it falls out of the closest-link rule.
//
// CPU back end (TBB), link creation and compositing also on a Vulkan device (vulkan_links.h,
// vulkan_composite.h).
// CreateHierarchicalLinks walks candidate pairs level by level from the
// root's self-pair (the data-parallel link creation of Meyer et al. 2009): a pair is split
// while an end subtends more than linkThreshold × ω_bin from the other (Sec. 4.2.2: its
// bounding sphere's disc, foreshortened as far as the slab holding its members allows), else it
// becomes a link at both ends, recorded in the end's (node, bin) slot with its distance and
// the solid angle the other end covers. RefineHierarchicalLinks and PushdownLinks fold into
// one pass per leaf (Sec. 4.2.3, 4.2.4): each front bin takes the links of the leaf and its
// ancestors in that bin nearest first, each covering what the nearer ones left of the bin,
// until it is full: the paper's closest element, extended to the closest layer, so that a
// light smaller than a bin covers only its own solid angle. What no link covers sees the
// environment (Sec. 4.4).
#pragma once

#include <chrono>
#include <cstdint>
#include <memory>
#include <string>
#include <unordered_map>
#include <utility>
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
// ImplicitLinker::Build's `solid` of a node that is not part of one closed solid.
inline constexpr uint32_t kNoSolid = 0xffffffffu;

struct ImplicitLinks {
    // Per leaf (hierarchy leaf order), the shares of its front bins [offsets[i],
    // offsets[i + 1]): the bin (direction from the leaf towards what it sees), a sender node
    // in it (kNoSender: the environment) and its weight cos⁺θ · Ω · CosineNorm(n), Ω the
    // solid angle of the bin it covers; a bin's shares cover its ω_bin, so that Σ weight · L
    // = E and a leaf with every bin at radiance L receives exactly π L.
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
    size_t linked = 0;  // pairs that became links (each recorded at up to two ends)
    size_t empty = 0;   // bin shares that see the environment
    double msCreate = 0.0, msPush = 0.0;

    size_t Count() const { return sender.size() - empty; }  // shares from a sender
};

// The table a bounce reads every share's light from (ImplicitSolver::ExitantTables and its
// device twin, vulkan_bounce.h): per node a row of `bins` exitant intensities, then per node
// its Σ A L, then per bin the environment's radiance.
struct ShareTable {
    size_t nodes, bins;
    size_t SumsAt() const { return nodes * bins; }
    size_t EnvironmentAt() const { return nodes * bins + nodes; }
    size_t Entries() const { return nodes * bins + nodes + bins; }
};

class VulkanLinkCreation;
class VulkanCompositing;

class ImplicitLinker {
  public:
    // A link at one end: the (node, bin) slot, the sender, its depth along the bin (what the
    // bin's front-to-back order sorts by), the solid angle of the bin the sender covers.
    struct End {
        uint32_t slot;
        uint32_t sender;
        float dist;
        float omega;
    };
    // `closest`: each (node, bin) slot keeps its closest link only, which covers the bin
    // (Eq. 5 as the paper writes it; ImplicitSettings::closest): no end is spread, no layer
    // composited. On a device (UseDevice, made with `closest`) the slots are kept there.
    ImplicitLinker(const Directions& dirs, float linkThreshold, bool closest = false);
    ~ImplicitLinker();
    // The links of `hierarchy` as it is placed now. `frontArea`: per node and bin, the
    // front-facing projected area Σ A cos⁺(n, ω_b) (what a cluster covers of a bin).
    // `solid`: per node, the closed solid (scene/solids.h NodeSolids) all its members bound,
    // or kNoSolid; empty: none known. In a bin, a solid's turned-away flat senders that lie
    // `thin` or more behind its nearest facing one add only what they cover beyond its
    // facing ones: seen from outside, a solid's far faces lie behind its near ones (at a
    // silhouette both would count, and the far ones, black, darken the bin); seen from
    // inside (a floor under a box without a bottom) only far faces show, and they block. A
    // solid thinner than `thin` (a wall thinner than an element) keeps both inside its
    // outline: its near faces' ends fall into the bins unevenly, and its far faces fill the
    // gaps. At the outline (a bin's cone leaves the box of the solid's leaves, whose faces
    // that other surfaces touch are open) it adds, as a thick one does, only what it covers
    // beyond them.
    //
    // `moving` (per node, or null): the nodes whose subtree holds an element that moved since
    // the last build, or can move from now on. The ends of every pair of two nodes outside
    // it are kept (a pair's ends depend on its two subtrees only), and a build given the same
    // `moving` again takes them as kept, examining only the pairs with a moving end: the
    // same links as a full build, when the nodes outside `moving` are as they were. Another
    // `moving`, or none, builds everything (and keeps for the new one).
    void Build(const Hierarchy& hierarchy, const std::vector<float>& frontArea,
               const std::vector<uint32_t>& solid, float thin, ImplicitLinks& out,
               const std::vector<uint8_t>* moving = nullptr);
    // Whether the last build took kept ends (the pairs examined are in ImplicitLinks::pairs).
    bool Incremental() const { return incremental_; }
    // How far (an angle) from the centre of a spread end's disc of angular radius `rho` a
    // bin's centre may lie and the bin still overlap the disc by more than kMinOverlap of a
    // bin: at most rho + the bin's radius, less where that ring's overlaps are slivers. Read
    // from a table over rho (in bin radii: y = kReachFirst + k / kReachSteps, each entry the
    // reach at the next y up, as it grows with y); Record walks no bin beyond it.
    float OverlapReach(float rho) const;
    // The bin's radius (a disc of its solid angle), and how much of a bin a spread end must
    // overlap to cover it (Record: smaller slivers add shares, not light).
    float BinRadius() const { return binRadius_; }
    static constexpr float kMinOverlap = 0.2f;

    // Creates the links' ends on `device` (vulkan_links.h) from now on, null: on the CPU. The
    // device examines every pair each build: `moving` is not used, nothing is kept. With
    // `closest` the device keeps each slot's closest link (made with `closest` too), where
    // its table fits (LinkedOnHostBecause says when it did not).
    void UseDevice(VulkanLinkCreation* device);
    // Why the last build, given a device, made its links on the CPU (empty: it did not).
    const std::string& LinkedOnHostBecause() const { return linkedOnHost_; }
    // With the ends created on the device (UseDevice), composites the leaves' bins there too
    // (vulkan_composite.h), null: on the CPU. A build the device cannot composite whole
    // (VulkanCompositing::Unfit and Composite say when) composites here.
    void UseDeviceCompositing(VulkanCompositing* composite) { composite_ = composite; }
    // Whether the last build composited on the device, and if one was given and it did not,
    // why.
    bool CompositedOnDevice() const { return compositedOnDevice_; }
    const std::string& CompositedOnHostBecause() const { return compositeOnHost_; }

  private:
    // One front bin's share of a leaf's light: from a sender (or kNoSender: the environment)
    // with its weight.
    struct Entry {
        uint32_t bin, sender;
        float weight;
    };
    // Records the link (`node`, centred at `at`, receives from `sender`, node `from`, along
    // `dir` at `dist`) in the slot of `dir`'s bin `centre` with the solid angle `omega` it
    // covers, or, when the sender looks wider than a bin, in every bin its disc spans,
    // covering each (a cluster's disc foreshortened to `shows` of it across, Foreshortening).
    void Record(uint32_t node, uint32_t sender, const HierarchyNode& from, const glm::vec3& at,
                const glm::vec3& dir, float dist, float omega, uint32_t centre, float shows,
                std::vector<End>& ends) const;
    // Ends [first, last) of one source (a thread's recorded ends, a kept root's).
    using EndRange = std::pair<const End*, const End*>;
    // The closest-link rule's shares (Build, `closest`) from the ends of `sources`: per
    // (node, bin) slot the closest end's (depth bits << 32 | sender) by atomic minimum, pushed
    // down the tree, each leaf's front bin its closest link's whole.
    void BuildClosest(const Hierarchy& h, const std::vector<std::vector<EndRange>>& sources,
                      ImplicitLinks& out);
    // The rest of it from the slots' keys in Scratch::closest (made by BuildClosest, or on
    // the device): the push-down and the leaves' shares.
    void PushClosest(const Hierarchy& h, ImplicitLinks& out);
    // Scratch::perLeaf's shares into `out`, with each share's travel.
    void WriteShares(const Hierarchy& h, ImplicitLinks& out) const;
    // The recorded ends of `sources` (and the kept ones) by (node, bin), each slot's nearest
    // first, into Scratch (ends, occupied, runFirst, runs; implicit_pushdown.cpp). The
    // sources are counted and scattered by node side by side, then each node's ends by bin
    // and each slot by depth, node by node; the order they are read in never shows: no two
    // ends of a slot tie on depth and sender.
    void SortEnds(const Hierarchy& h, const std::vector<std::vector<EndRange>>& sources);
    // Each leaf's bins covered front to back by the sorted ends of the leaf and its
    // ancestors, into Scratch::perLeaf (Build's arguments; implicit_pushdown.cpp).
    void Composite(const Hierarchy& h, const std::vector<float>& frontArea,
                   const std::vector<uint32_t>& solid, float thin);
    struct LeafWalk;  // one thread's walk over the leaves (Composite)
    struct Rounds;    // one build's rounds of pairs on the CPU (implicit_links.cpp)
    using TimePoint = std::chrono::steady_clock::time_point;
    // The device's ends composited there (vulkan_composite.h) where they fit: true when it
    // did (`out` is done); else CompositedOnHostBecause says why. `start`: when the build
    // began; `perFrame`: the build was given `moving` (its scratch is kept).
    bool CompositeOnDevice(const Hierarchy& h, const std::vector<uint32_t>& solid, float thin,
                           ImplicitLinks& out, TimePoint start, bool perFrame);
    const Directions& dirs_;
    float threshold_;
    bool closest_;
    // The ends of the pairs with no moving end, for `keptFor_` (empty: none kept), per root
    // (the first such pair of a lineage, Build): its descendants' ends in ends[first[r],
    // first[r + 1]), the pairs examined and the pairs linked below it, the roots by pair
    // (receiver << 32 | sender).
    struct Kept {
        std::vector<End> ends;
        std::vector<uint32_t> first, pairs, linked;
        std::unordered_map<uint64_t, uint32_t> index;
    };
    std::vector<uint8_t> keptFor_;
    Kept kept_;
    bool incremental_ = false;
    VulkanLinkCreation* device_ = nullptr;
    VulkanCompositing* composite_ = nullptr;
    bool compositedOnDevice_ = false;
    std::string compositeOnHost_;
    std::string linkedOnHost_;
    // The build's working buffers (the rounds' pairs, the threads' ends, the ends by slot, the
    // leaves' shares), kept from a build given `moving` to the next: a relink a frame would
    // otherwise map and fault in their pages (hundreds of megabytes) every frame (also when
    // the device creates the ends). A build without `moving` (a scene's first, a rebuild)
    // hands them back at its end.
    struct Scratch;
    std::unique_ptr<Scratch> scratch_;
    float splat_ = 0.0f;      // sin of the angular radius above which an end is spread
    float binRadius_ = 0.0f;  // the radius of a disc of a bin's solid angle
    static constexpr float kReachFirst = 0.25f;
    static constexpr int kReachSteps = 64;
    std::vector<float> overlapReach_;  // OverlapReach's table, in bin radii
};

}  // namespace penumbra
