// The gather stage's first part for any solver (issue 19): the emitters' direct light with
// explicit visibility (emitter_direct.h) at the solver's surfels, handed to it as its first
// shot (Solver::SetEmitterDirect), so the solver carries only bounces. A Solver wrapping
// another: edits pass through, and those that change the emitters' light (an emissive
// material, a move) recompute it.
#pragma once

#include <memory>

#include "gather/emitter_direct.h"
#include "solver/solver.h"

namespace penumbra {

class EmitterFirstShot : public Solver {
  public:
    // Computes the first shot for `inner`, built from `scene`. Throws penumbra::Error when
    // the inner solver cannot take it (Solver::SetEmitterDirect).
    EmitterFirstShot(std::unique_ptr<Solver> inner, const Scene& scene,
                     const EmitterDirectSettings& settings);

    void Iterate(int n) override { inner_->Iterate(n); }
    std::vector<glm::vec3> SurfelIrradiance(Channel channel) override {
        return inner_->SurfelIrradiance(channel);
    }
    const Surfels& GetSurfels() const override { return inner_->GetSurfels(); }
    void UpdateMaterials(const Scene& scene) override;
    void UpdateLights(const Scene& scene) override;
    SolverStats Stats() const override;
    std::string GeometryMismatch(const Scene& scene) const override {
        return inner_->GeometryMismatch(scene);
    }
    void UpdateGeometry(const Scene& scene) override;
    std::vector<float> SurfelExitant() override { return inner_->SurfelExitant(); }
    void WarmStart(const std::vector<float>& rows, const std::vector<uint8_t>& keep) override {
        inner_->WarmStart(rows, keep);
    }
    Solver& Inner() { return *inner_; }

  private:
    void Shoot();  // the emitters' light at the surfels, to the inner solver

    std::unique_ptr<Solver> inner_;
    Scene scene_;  // as last edited: RayScene traces it
    EmitterDirectSettings settings_;
    double msShot_ = 0.0;
};

// The most shadow rays a surfel the first shot takes; CheckEmitterRays throws
// penumbra::Error for a count outside 0 (off) … kMaxEmitterRays.
inline constexpr int kMaxEmitterRays = 65536;
void CheckEmitterRays(int rays);

// `solver` with the emitters' direct light as its first shot (`rays` shadow rays a surfel),
// where it can take it: not with rays 0, not for a scene without emitters, not yet for a
// scene with glossy materials (their lobes would miss the shot). Otherwise `solver` as it
// is, and `declined` (when given) says why.
std::unique_ptr<Solver> WithEmitterDirect(std::unique_ptr<Solver> solver, const Scene& scene,
                                          int rays, std::string* declined = nullptr);

}  // namespace penumbra
