// Rigid motion of the dynamic nodes (antiradiance paper Sec. 3.3, which every solver and the
// service share): which surfels move together, whether a new pose is a rigid move inside the
// motion bounds, the surfels placed at it, and which surfels of a rebuilt solver are the
// old ones, moved or not (a warm start's correspondence).
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <optional>
#include <string>
#include <vector>

#include "scene/scene.h"
#include "scene/surfels.h"

namespace penumbra {

// Where a motion group's surfaces may go, world space (links between a group and anything
// else are refined for the worst case over this box).
struct MotionBounds {
    glm::vec3 min{0.0f}, max{0.0f};
};

// How far a vertex may stray past its bounds (float noise of a transformed vertex): 1e-4 of
// the scene's diameter.
float MotionSlack(const Scene& scene);
// Whether a vertex of primitives `primitives` of `scene` lies outside `bounds` (with slack).
bool OutsideBounds(const Scene& scene, const std::vector<uint32_t>& primitives,
                   const MotionBounds& bounds);
// Whether a vertex of `node`'s own primitives lies outside its motion bounds (false for a
// node without any).
bool OutsideBounds(const Scene& scene, const SceneNode& node);
// Why `delta` is not a rigid move ("was scaled or sheared, not moved rigidly", "was
// mirrored"), or null when it is a rotation and a translation only (to 1e-3).
const char* NotRigid(const glm::mat4& delta);
// The rotation of a rigid `delta`; nullopt when NotRigid.
std::optional<glm::mat3> RigidRotation(const glm::mat4& delta);

// The surfaces of one dynamic scene node, moving rigidly together: group g + 1 in
// Surfels::groups and HierarchyNode::group.
struct MotionGroup {
    int node = -1;           // scene node
    MotionBounds bounds;     // world space: the node's motion bounds, else the scene's box
    glm::mat4 built{1.0f};   // the node's world matrix when the surfels were made
    glm::mat4 placed{1.0f};  // the world matrix the surfaces are placed with now
};

// The motion groups of a solver's surfels and what placing them needs.
struct SurfelMotion {
    std::vector<MotionGroup> groups;
    std::vector<uint32_t> primitiveGroup;  // per primitive: its group (0: static)
    std::vector<uint32_t> primitiveShape;  // per primitive: Primitive::shape when made
    // Per surfel, as made (the rest pose every placement starts from).
    std::vector<glm::vec3> restPositions, restNormals, restCentroids;

    size_t size() const { return groups.size(); }
    bool empty() const { return groups.empty(); }
    std::vector<MotionBounds> Bounds() const;
    std::vector<glm::mat4> BuiltFrames() const;  // each group's `built`
};

// One group per dynamic scene node with surfaces, bounded by the node's motion bounds or else
// the scene's box (the whole scene is where it may go); sets `surfels.groups` when there is
// a group and keeps the rest pose.
SurfelMotion AssignMotionGroups(const Scene& scene, Surfels& surfels);

// Why `scene` (the scene the surfels were made from, dynamic nodes moved) is not a move the
// groups can take in place (no groups, other primitives, a static surface moved, a group
// scaled, sheared, mirrored, deformed (SetNodeVertices) or outside its bounds); empty when
// PlaceSurfels can.
std::string MotionMismatch(const SurfelMotion& motion, const Surfels& surfels, const Scene& scene);

// The groups re-placed at their nodes' poses in `scene` (MotionMismatch must be empty).
struct Placement {
    std::vector<uint8_t> moved;    // per group index g ([0] static, never moved)
    std::vector<glm::mat4> delta;  // rest pose → now, per group index
    bool Moved(uint32_t group) const { return moved[group] != 0; }
};
// Moves the positions, centroids and normals of the surfels of every group whose node moved.
Placement PlaceSurfels(SurfelMotion& motion, Surfels& surfels, const Scene& scene);

// Which surfels of `now` (made from `after`) are those of `was` (made from `before`): a
// primitive whose vertices stayed put keeps its surfels in order, and so does one moved
// rigidly (a dynamic node's surfels are made in its own space); anything else, and
// everything when the primitives do not line up, has none.
struct SurfelCarry {
    static constexpr int64_t kNone = -1;
    std::vector<int64_t> from;   // per surfel of `now`: its surfel in `was`, or kNone
    std::vector<uint32_t> turn;  // per surfel of `now`: index into `turns`
    std::vector<glm::mat3> turns{glm::mat3(1.0f)};  // [0]: stayed put
    size_t kept = 0;                                // surfels with a `from`
    size_t turned = 0;                              // of them, moved (turn > 0)
};
SurfelCarry CarrySurfels(const Scene& before, const Surfels& was, const Scene& after,
                         const Surfels& now);

}  // namespace penumbra
