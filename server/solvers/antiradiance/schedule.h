// Which operators each pass of the antiradiance iteration applies (Sec. 2.2), the adaptive
// schedule that converges the antiradiance before every reflection, and the bound that tells
// a diverged solution (docs/SOLVER.md "Stability").
#pragma once

#include <string>
#include <vector>

#include "solver/solver.h"
#include "solvers/antiradiance/model.h"

namespace penumbra {

// The pass schedule. Symmetric and asymmetric follow the pass count alone
// (ModeOfIteration); the adaptive scheme follows the solution: one radiance step (K,
// Eq. 18 on the front hemisphere), then antiradiance steps (J, Eq. 19 on the back
// hemisphere, L frozen) until the last one moved no leaf's irradiance by more than
// tolerance × the largest leaf irradiance, or the step cap. The iteration starts with
// antiradiance steps, so the emitters' light is occluded before it is first reflected.
//
// Why (measured, docs/SOLVER.md): light that passes through a stack of d occluders is
// cancelled only d antiradiance steps later; the symmetric scheme reflects the uncancelled
// light in between, and on rows of boxes or books the iteration's operator gets a spectral
// radius above one (−2.3 on ten boxes 2 cm apart). With the antiradiance converged before
// each reflection, a bounce applies K U (1 + J U)⁻¹, transport with occlusion, whose
// radius is that of the reflectances.
class PassSchedule {
  public:
    explicit PassSchedule(const AntiradianceSettings& settings) : settings_(settings) {}
    // The mode of the next pass.
    LocalMode Next() const;
    // Whether the scheme wants each pass's leaf irradiance (Finished) to schedule on.
    bool NeedsIrradiance() const { return settings_.scheme == Scheme::kAdaptive; }
    // After a pass of mode Next(): `irradiance` is the leaves' E (RGB) it produced (unused
    // when NeedsIrradiance() is false). Returns whether the solution is settled after it: the
    // adaptive scheme's antiradiance has converged for the current radiance. In between,
    // while antiradiance steps carry light through a stack, E goes through transients far
    // from the answer (up to half the furnace bound on a row of 15 boxes 5 mm apart).
    // The symmetric scheme is settled after every pass, the asymmetric one after the last
    // antiradiance step of each bounce.
    bool Finished(const std::vector<float>& irradiance);

    int passes = 0;
    int bounces = 0;     // radiance steps done
    int steps = 0;       // antiradiance steps in the bounce under way
    int lastSteps = 0;   // antiradiance steps of the last finished bounce
    size_t capHits = 0;  // bounces whose steps ended at the cap

  private:
    AntiradianceSettings settings_;
    bool antiradiance_ = true;  // adaptive: in the antiradiance steps
    std::vector<float> last_;   // the leaves' E after the previous pass
};

// No leaf can receive more irradiance than this (lux), whatever the geometry: exitant
// radiance is at most B = (L_e + ρ E_d / π + F0 G) / (1 − ρ − F0) with maxima over the
// leaves (emission, diffuse and glossy reflectance, direct light E_d, lobe-reflected direct
// light G), or L_e + (ρ + F0) L_sky + ρ E_d / π + F0 G under a brighter sky, and E ≤
// π max(B, L_sky). Infinite when a reflectance reaches 1.
// `reflectance` (when given) gets the largest diffuse plus glossy reflectance.
float IrradianceBound(const AntiradianceModel& model, float* reflectance = nullptr);

// Why the leaves' irradiance (RGB per leaf) is no longer a bounded solution: a value that
// is not finite, or |E| past kDivergenceMargin × `bound`; empty while it is.
std::string Divergence(const std::vector<float>& irradiance, float bound);

}  // namespace penumbra
