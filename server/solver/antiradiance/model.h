// Everything the antiradiance passes read, built once per scene: surfels, hierarchy,
// bins, links and per-leaf attributes. Device back ends upload it as it is.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"
#include "links/links.h"
#include "scene/scene.h"
#include "scene/surfels.h"
#include "solver/solver.h"

namespace penumbra {

// Per-leaf data of the local pass. Layout shared with shaders/common.glsl (struct Leaf).
struct LeafAttributes {
    glm::vec3 normal;
    float area;
    glm::vec3 albedo;
    float cosNormIn;  // π / Σ_b ω_bin max(0, −n·ω_b): makes the discrete cosine integral exact
    glm::vec3 emission;
    float cosNormOut;  // π / Σ_b ω_bin max(0, n·ω_b)
    uint32_t node;     // hierarchy node of this leaf
    uint32_t parent;   // its parent node (kNoParent for a single-surfel scene)
    uint32_t surfel;
    uint32_t flags;  // kLeafTwoSided
};
// The leaf occludes from both sides: light arriving at its back leaves its front as
// antiradiance (Surfels::twoSided).
inline constexpr uint32_t kLeafTwoSided = 1;
static_assert(sizeof(LeafAttributes) == 64);

// What one local pass updates (Sec. 2.2): K reflects into the front hemisphere (Eq. 18),
// J sends incident light through as antiradiance (Eq. 19). Symmetric: both.
enum LocalMode : uint32_t { kReflect = 1, kAntiradiance = 2, kBoth = 3 };

struct AntiradianceModel {
    float elementSize = 0.0f;
    Surfels surfels;
    Hierarchy hierarchy;
    Directions dirs{128};
    Links links;
    std::vector<LeafAttributes> leaves;  // in hierarchy leaf (preorder) order
    // Direct irradiance E_d of punctual lights per leaf (RGB, w = 0), shadowed (Sec. 3.3):
    // reflected by the local pass like the gathered irradiance, but never sent through
    // as antiradiance. Zero without punctual lights.
    std::vector<glm::vec4> leafDirect;
    // Environment radiance travelling along each bin (direct::EnvironmentBins), RGB per bin:
    // the root's L_in starts from it and push hands it to every node, so every element's
    // incident radiance is initialised with the sky and antiradiance removes what is
    // occluded (Sec. 3.3). Zero without an environment.
    std::vector<glm::vec3> environment;
    std::vector<uint32_t> leftChild;  // per node; kNoParent for leaves
    std::vector<uint32_t> rightChild;

    size_t Nodes() const { return hierarchy.size(); }
    int Bins() const { return dirs.Count(); }
    size_t TableFloats() const { return Nodes() * Bins() * 3; }
};

AntiradianceModel BuildAntiradianceModel(const Scene& scene, const SolverSettings& settings,
                                         const ProgressFn& progress);

// The local-pass mode of iteration `i` (0-based) under the settings' scheme.
LocalMode ModeOfIteration(const SolverSettings& settings, int i);

}  // namespace penumbra
