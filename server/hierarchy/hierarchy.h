// Clusters over surfels, split spatially and by normal, laid out depth first (Sec. 4.1)
// so that a node's subtree is the contiguous range [index, end) and push/pull walk rows.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "scene/surfels.h"

namespace penumbra {

inline constexpr uint32_t kNoSurfel = 0xffffffffu;
inline constexpr uint32_t kNoParent = 0xffffffffu;
// HierarchyNode::group of a cluster over more than one motion group (Surfels::groups).
inline constexpr uint32_t kMixedGroup = 0xffffffffu;

struct HierarchyNode {
    glm::vec3 center;  // bounding sphere of the members' discs
    float radius;
    glm::vec3 normal;  // leaf: the surfel normal; interior: axis of the normal cone
    float coneCos;     // cos of the normal cone's half angle (1 for a leaf, −1 if unbounded)
    float area;        // Σ member areas
    float discRadius;  // √(area/π), capped by `radius`: the sender's effective size
    uint32_t parent;   // kNoParent for the root
    uint32_t end;      // one past the last node of this subtree
    uint32_t surfel;   // kNoSurfel for interior nodes
    uint32_t depth;
    // Some member occludes from both sides (Surfels::twoSided): light arriving at its back
    // must be gathered (no Fig. 7 culling) so that it can be sent on as antiradiance.
    bool twoSided;
    // Motion group of every member (0: static), or kMixedGroup: such clusters sit above the
    // groups' subtrees, change shape when a group moves and are never linked.
    uint32_t group;

    bool IsLeaf() const { return surfel != kNoSurfel; }
};

struct Hierarchy {
    std::vector<HierarchyNode> nodes;    // preorder; nodes[0] is the root
    std::vector<uint32_t> leafOfSurfel;  // kNoParent for surfels without area
    std::vector<uint32_t> leaves;        // leaf node indices in preorder
    std::vector<uint32_t> interior;      // interior node indices in preorder
    // Nodes grouped by depth (for level-by-level push/pull on the device).
    std::vector<std::vector<uint32_t>> byDepth;

    size_t size() const { return nodes.size(); }
};

// Binary hierarchy over the surfels with positive area; one surfel per leaf. With motion
// groups (Surfels::groups), the top splits separate the groups first, so every node below
// them holds one group only; `frames[g − 1]` (group g's world matrix) clusters group g in
// its own frame, so that its clusters are the same at every pose (Sec. 3.3 moves).
Hierarchy BuildHierarchy(const Surfels& surfels, const std::vector<glm::mat4>& frames = {});

// The same tree over `surfels` at their places now (moved or deformed, same surfels): every
// node's bounding sphere, normal and cone, area and disc radius again, leaves up (as a
// bounding volume hierarchy is refitted; the implicit-visibility paper's UpdateElements).
// The spheres are the children's spheres' bound, not the tightest.
void RefitHierarchy(Hierarchy& hierarchy, const Surfels& surfels);

}  // namespace penumbra
