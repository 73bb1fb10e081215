// Everything the antiradiance passes read, built once per scene: surfels, hierarchy,
// bins, links and per-leaf attributes. Device back ends upload it as it is.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "gpu/layout.h"
#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"
#include "links/links.h"
#include "scene/motion.h"
#include "scene/scene.h"
#include "scene/surfels.h"
#include "solver/solver.h"
#include "solvers/antiradiance/glossy.h"
#include "solvers/antiradiance/moves.h"
#include "solvers/antiradiance/settings.h"

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
    uint32_t flags;  // kLeafTwoSided | kLeafGlossy | glossy index << kGlossyShift
};
// The leaf occludes from both sides: light arriving at its back leaves its front as
// antiradiance (Surfels::twoSided).
inline constexpr uint32_t kLeafTwoSided = 1;
// The leaf's material has a glossy lobe (Material::Glossy): its local pass runs the full
// Eq. 18 sum with the lobe; flags >> kGlossyShift indexes AntiradianceModel::glossy.
inline constexpr uint32_t kLeafGlossy = 2;
inline constexpr uint32_t kGlossyShift = 8;
static_assert(sizeof(LeafAttributes) == 64);
PENUMBRA_GPU_FIELD(LeafAttributes, normal, 0);
PENUMBRA_GPU_FIELD(LeafAttributes, area, 12);
PENUMBRA_GPU_FIELD(LeafAttributes, albedo, 16);
PENUMBRA_GPU_FIELD(LeafAttributes, cosNormIn, 28);
PENUMBRA_GPU_FIELD(LeafAttributes, emission, 32);
PENUMBRA_GPU_FIELD(LeafAttributes, cosNormOut, 44);
PENUMBRA_GPU_FIELD(LeafAttributes, node, 48);
PENUMBRA_GPU_FIELD(LeafAttributes, parent, 52);
PENUMBRA_GPU_FIELD(LeafAttributes, surfel, 56);
PENUMBRA_GPU_FIELD(LeafAttributes, flags, 60);

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
    // Glossy leaves (kLeafGlossy), in leaf order: F0 and lobe; which leaf each one is; the
    // bin of the mirror direction of every incoming bin, mirror[g · m + l] (the lobe of
    // light arriving along ω_l is centred there); the discretised lobes.
    std::vector<GlossyLeaf> glossy;
    std::vector<uint32_t> glossyLeaves;
    std::vector<uint32_t> mirror;
    std::vector<GlossyLobe> lobes;
    std::vector<BinWeight> lobeWeights;
    // The punctual lights' direct light reflected by the lobes, before F0:
    // glossyDirect[g · m + j] = Σ_k E_d,k · cosⁿ∠(r_k, ω_j) / N_k (RGB, w = 0), r_k the mirror
    // direction of light k at leaf g, N_k the lobe's normaliser for that exact direction.
    // Exact light directions, so narrow lobes of direct light are not snapped to bins.
    std::vector<glm::vec4> glossyDirect;
    std::vector<uint32_t> leftChild;  // per node; kNoParent for leaves
    std::vector<uint32_t> rightChild;
    // Sec. 3.3, moving objects (SolverSettings::prepareMoves): the surfels' motion groups
    // (scene/motion.h), and what a move needs to recompute the links touching a group: the
    // oriented nodes' cosine norms, the near field, and the nodes as built.
    SurfelMotion motion;
    LeafNorms norms;
    NearField near;  // its `surfels` is re-pointed at `surfels` before use
    std::vector<glm::vec3> restCenters, restNodeNormals;  // per node
    // Why motion links were asked for but not built (AntiradianceSettings::motionLinkBudget).
    std::string motionDeclined;

    size_t Nodes() const { return hierarchy.size(); }
    int Bins() const { return dirs.Count(); }
    size_t TableFloats() const { return Nodes() * Bins() * 3; }
};

AntiradianceModel BuildAntiradianceModel(const Scene& scene, const SolverSettings& settings,
                                         const AntiradianceSettings& own,
                                         const ProgressFn& progress);

// The same with the solver's options read from settings.options (ReadAntiradianceSettings).
AntiradianceModel BuildAntiradianceModel(const Scene& scene, const SolverSettings& settings,
                                         const ProgressFn& progress);

// The local-pass mode of iteration `i` (0-based) under the settings' scheme.
LocalMode ModeOfIteration(const AntiradianceSettings& settings, int i);

}  // namespace penumbra
