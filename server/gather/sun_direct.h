// The first shot's sky part (issue 19, part 1: "emissive surfaces (and the environment)
// sampled from each surfel with stratified shadow rays"): the direct light of an environment
// map's sun (SplitSky's `sun`, the part above the map's mean) at a set of points, with
// explicit visibility, instead of through the solver's bins (which blur a sun's shadow to a
// bin's width) or the gather's cosine rays (which meet a small sun rarely). The rest of the
// sky stays with the solver and the gather's cosine rays, which take a smooth sky well.
#pragma once

#include <glm/glm.hpp>
#include <vector>

#include "rays/ray_scene.h"
#include "scene/environment.h"

namespace penumbra {

// E_sun(x) = ∫ L_sun(ω) cosθ V(x, ω) dω ≈ 1/K Σ_k L_sun(ω_k) cosθ_k V(x, ω_k) / p(ω_k), the
// ω_k drawn by SkyParts::sampler (a density proportional to L_sun's luminance, so each term
// is nearly the same: what varies is V) from a rotated R2 pattern of its own per point, so
// the answer depends on neither the thread count nor the frame. A ray's visibility is kept (a
// bit a ray), so that an intensity edit re-reads them and a move traces again only the rays
// whose lines meet what moved.
class SunDirect {
  public:
    // Throws penumbra::Error for rays < 1.
    SunDirect(int rays, uint64_t seed);
    int Rays() const { return rays_; }
    // Traces every point's rays (points lifted off their surfaces along their normals) and
    // returns E_sun per point. `reach`: a length past every surface from every point (twice
    // the scene's diameter).
    std::vector<glm::vec3> Trace(const RayScene& rays, const SkyParts& sky,
                                 const std::vector<glm::vec3>& points,
                                 const std::vector<glm::vec3>& normals, float reach);
    // After a move (`rays` on the moved scene): the points marked in `moved` are traced again,
    // and of the others each ray whose line meets one of `boxes`. `traced` (when given) gets
    // the rays traced.
    std::vector<glm::vec3> Retrace(const RayScene& rays, const SkyParts& sky,
                                   const std::vector<glm::vec3>& points,
                                   const std::vector<glm::vec3>& normals, float reach,
                                   const std::vector<uint8_t>& moved,
                                   const std::vector<Bounds>& boxes, size_t* traced = nullptr);
    // E_sun again from the kept visibility, for a sun of the same shape and place (its
    // intensity changed).
    std::vector<glm::vec3> Reevaluate(const SkyParts& sky,
                                      const std::vector<glm::vec3>& normals) const;

  private:
    // Point i's ray k: its direction and density (0: it adds nothing).
    glm::vec3 Direction(const SkyParts& sky, size_t i, int k, float& pdf) const;
    // Point i's E from its kept bits.
    glm::vec3 Sum(const SkyParts& sky, size_t i, const glm::vec3& n) const;

    int rays_, words_;
    uint64_t seed_;
    std::vector<uint64_t> seen_;  // points × words_: bit k, ray k reaches the sky
    // Per point, the rays that reach the sky through surfaces that pass light (glass) and
    // what of it they carry (RayScene::Transmittance); empty in a scene without such
    // surfaces. A seen ray not listed carries all of it.
    std::vector<std::vector<std::pair<uint16_t, glm::vec3>>> passed_;
};

}  // namespace penumbra
