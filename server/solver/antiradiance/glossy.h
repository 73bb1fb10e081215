// Glossy surfaces in the antiradiance solver: Phong lobes discretised on the bins, the
// mirror bin of every incoming bin per glossy leaf, and the punctual lights' direct light
// reflected by the lobes at their exact directions.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "gpu/layout.h"
#include "scene/scene.h"

namespace penumbra {

struct AntiradianceModel;  // solver/antiradiance/model.h

// A glossy leaf: its lobe's F0 and which discretised lobe it uses. Layout shared with
// shaders/common.glsl (struct GlossyLeaf).
struct GlossyLeaf {
    glm::vec3 specular;  // F0
    uint32_t lobe;       // index into AntiradianceModel::lobes
};
static_assert(sizeof(GlossyLeaf) == 16);
PENUMBRA_GPU_FIELD(GlossyLeaf, specular, 0);
PENUMBRA_GPU_FIELD(GlossyLeaf, lobe, 12);

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
PENUMBRA_GPU_FIELD(GlossyLobe, start, 0);
PENUMBRA_GPU_FIELD(GlossyLobe, width, 4);
PENUMBRA_GPU_FIELD(GlossyLobe, exponent, 8);
PENUMBRA_GPU_FIELD(GlossyLobe, norm, 12);
inline constexpr float kLobeCutoff = 1e-3f;
// The sharpest lobe m bins resolve: σ = 1/√n at half the bin spacing √(4π/m) gives n = m/π.
// Sharper lobes (roughness below ≈ 0.33 at 128 bins) are widened to it.
inline float MaxLobeExponent(int bins) { return static_cast<float>(bins) / 3.14159265f; }

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

// Glossy leaf g's mirror bin of every incoming bin, for its current normal.
void FillMirror(AntiradianceModel& model, uint32_t g);

}  // namespace penumbra
