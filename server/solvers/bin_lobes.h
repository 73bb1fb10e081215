// Glossy lobes on direction bins, shared by the solvers that carry light per bin (the
// antiradiance solver's Eq. 18, the implicit-visibility solver's glossy leaves): a Phong lobe
// discretised on the bins, the mirror bin of every bin about a normal, and a punctual light's
// direct light reflected by a lobe at its exact direction.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "gpu/layout.h"
#include "hierarchy/directions.h"
#include "scene/scene.h"

namespace penumbra {

// A normalised Phong lobe on the bins (Material): bin b's row holds cosⁿ∠(ω_b, ω_j) / N
// for the bins j where that is at least kLobeCutoff of the peak, padded with zero weights
// to `width` entries, at weights[start + b · width]. N = max_b Σ_j ω_bin cosⁿ∠ ·
// max(0, cos∠): reflection about a mirror direction along a bin's centre returns at most
// F0 (energy is never created). The kernel is symmetric, so a row serves as either the
// incoming or the outgoing side. Layout shared with shaders/common.glsl (struct Lobe).
struct GlossyLobe {
    uint32_t start;
    uint32_t width;
    float exponent;  // n as used: min(n, m/π) (below)
    float norm;      // 1/N
};
PENUMBRA_GPU_WORDS(GlossyLobe, 4);
inline constexpr float kLobeCutoff = 1e-3f;
// The sharpest lobe m bins resolve: σ = 1/√n at half the bin spacing √(4π/m) gives n = m/π.
// Sharper lobes (roughness below ≈ 0.33 at 128 bins) are widened to it.
inline float MaxLobeExponent(int bins) { return static_cast<float>(bins) / 3.14159265f; }

// The discretised lobe of exponent n (GlossyLobe), its rows appended to `weights`.
GlossyLobe MakeLobe(const Directions& dirs, float n, std::vector<BinWeight>& weights);

// Per bin l, the bin of its direction mirrored about the unit normal n (ω − 2⟨n|ω⟩n: light
// travelling along ω_l towards the surface leaves along it), into row[0 … bins).
void MirrorBins(const Directions& dirs, const glm::vec3& n, uint32_t* row);

// Adds to row[0 … bins) the lobe of exponent n at surface point p with normal `normal` for
// punctual light `light`'s direct irradiance `e` there (RGB), before F0: e · cosⁿ∠(r, ω_j) /
// N_r per bin j, r the light's mirror direction and N_r the lobe's normaliser for that exact
// direction (Σ_j ω_bin w_j cos⁺∠(r, ω_j) = 1), so narrow lobes of direct light are not
// snapped to bins. Nothing where e is black or the lobe misses every bin.
void AddLightLobe(const Directions& dirs, float n, const glm::vec3& p, const glm::vec3& normal,
                  const PunctualLight& light, const glm::vec3& e, glm::vec4* row);

}  // namespace penumbra
