// Everything the antiradiance passes read, built once per scene: surfels, hierarchy,
// bins, links and per-leaf attributes. Device back ends upload it as it is.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"
#include "links/links.h"
#include "scene/scene.h"
#include "scene/surfels.h"
#include "solver/antiradiance/settings.h"
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

// A glossy leaf: its lobe's F0 and which discretised lobe it uses. Layout shared with
// shaders/common.glsl (struct GlossyLeaf).
struct GlossyLeaf {
    glm::vec3 specular;  // F0
    uint32_t lobe;       // index into AntiradianceModel::lobes
};
static_assert(sizeof(GlossyLeaf) == 16);

// A normalised Phong lobe on the bins (Material): bin b's row holds cosⁿ∠(ω_b, ω_j) / N
// for the bins j where that is at least kLobeCutoff of the peak, padded with zero weights
// to `width` entries, at lobeWeights[start + b · width]. N = max_b Σ_j ω_bin cosⁿ∠ ·
// max(0, cos∠): reflection about a mirror direction along a bin's centre returns at most
// F0 (energy is never created). The kernel is symmetric, so a row serves as either the
// incoming or the outgoing side. Layout shared with shaders/common.glsl (struct Lobe).
struct GlossyLobe {
    uint32_t start;
    uint32_t width;
    float exponent;  // n as used: min(n, m/π) (below)
    float norm;      // 1/N
};
static_assert(sizeof(GlossyLobe) == 16);
inline constexpr float kLobeCutoff = 1e-3f;
// The sharpest lobe m bins resolve: σ = 1/√n at half the bin spacing √(4π/m) gives n = m/π.
// Sharper lobes (roughness below ≈ 0.33 at 128 bins) are widened to it.
inline float MaxLobeExponent(int bins) { return static_cast<float>(bins) / 3.14159265f; }

// What one local pass updates (Sec. 2.2): K reflects into the front hemisphere (Eq. 18),
// J sends incident light through as antiradiance (Eq. 19). Symmetric: both.
enum LocalMode : uint32_t { kReflect = 1, kAntiradiance = 2, kBoth = 3 };

// The surfaces of one dynamic scene node (extras.penumbra.dynamic), moving rigidly together
// (Sec. 3.3): group g + 1 in Surfels::groups and HierarchyNode::group.
struct MotionGroup {
    int node = -1;           // scene node
    MotionBounds bounds;     // world space: the node's motion bounds, else the scene's box
    glm::mat4 built{1.0f};   // the node's world matrix when the model was built
    glm::mat4 placed{1.0f};  // the world matrix the surfaces are placed with now
};

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
    // Sec. 3.3, moving objects (SolverSettings::motionLinks): the groups, each primitive's
    // group (0: static), and what a move needs to recompute the links touching a group: the
    // oriented nodes' cosine norms, the near field, and the surfels and nodes as built.
    std::vector<MotionGroup> motion;
    std::vector<uint32_t> primitiveGroup;
    LeafNorms norms;
    NearField near;  // its `surfels` is re-pointed at `surfels` before use
    std::vector<glm::vec3> restPositions, restNormals, restCentroids;  // per surfel
    std::vector<glm::vec3> restCenters, restNodeNormals;               // per node
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

// (Re)builds the glossy data from the materials of `scene` (same geometry): flags, glossy,
// glossyLeaves, mirror, lobes; glossyDirect is zeroed (GlossyDirect fills it).
void BuildGlossy(AntiradianceModel& model, const Scene& scene);
// Whether the glossy data already matches the materials of `scene` (same glossy leaves, F0
// and lobes), so that BuildGlossy would change nothing.
bool GlossyMatches(const AntiradianceModel& model, const Scene& scene);
// glossyDirect from each light's direct irradiance at each leaf (`perLight`: lights ×
// leaves, stride 4, light-major) and the lights' places.
void GlossyDirect(AntiradianceModel& model, const std::vector<PunctualLight>& lights,
                  const std::vector<float>& perLight);

// Sec. 3.3: why the links built for the motion bounds cannot take the geometry of `scene`
// (no motion groups, a group scaled or sheared, or outside its bounds, a static surface
// moved); empty when MoveGroups can.
std::string MotionMismatch(const AntiradianceModel& model, const Scene& scene);
// A move inside the bounds, in two steps. PlaceGroups re-places the surfels, nodes, cosine
// norms, leaves and glossy mirror bins of every group whose node moved in `scene`
// (MotionMismatch must be empty) and returns which groups moved (index g, [0] static and
// never moved); `movedLeaves` (optional) gets each moved leaf's index into `leaves`.
// TouchedLinks lists the links touching a moved group (indices into Links::dynamic), and
// RedoLinks recomputes their form factors, bins and spread levels on the host (MakeLink:
// the same rules as the build, at the new places); the Vulkan back end recomputes them on
// the device instead (VulkanAntiradiance::UpdateLinks). MoveGroups does all three on the
// host and returns the number of links recomputed.
std::vector<uint8_t> PlaceGroups(AntiradianceModel& model, const Scene& scene,
                                 std::vector<uint32_t>* movedLeaves = nullptr);
std::vector<uint32_t> TouchedLinks(const AntiradianceModel& model,
                                   const std::vector<uint8_t>& moved);
void RedoLinks(AntiradianceModel& model, const std::vector<uint32_t>& touched);
size_t MoveGroups(AntiradianceModel& model, const Scene& scene,
                  std::vector<uint32_t>* movedLeaves = nullptr);

// The local-pass mode of iteration `i` (0-based) under the settings' scheme.
LocalMode ModeOfIteration(const AntiradianceSettings& settings, int i);

}  // namespace penumbra
