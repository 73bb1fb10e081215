// The gather stage's emitter direct light (issue 19, part 1): the irradiance that emitting
// surfaces send straight to a set of points, with explicit visibility (shadow rays through
// RayScene), instead of through the solver's bins. Solver-neutral: it sees the input
// geometry and materials only.
#pragma once

#include <glm/glm.hpp>
#include <vector>

#include "gather/ray_scene.h"

namespace penumbra {

struct EmitterDirectSettings {
    int rays = 256;     // shadow rays per point
    uint64_t seed = 1;  // the same seed gives the same answer (no flicker between frames)
};

// E(x) = ∫ L_e(y) cosθ_x cosθ_y / |x − y|² V(x, y) dA_y over every emitting triangle's front,
// per point x with unit normal n, estimated with `rays` samples: an emitting triangle chosen
// by power and a point on it (RayScene::PickEmitter, AreaPdf): jittered strata for the
// choice, a rotated low-discrepancy (R2) sequence for the point, a random stream of its own
// per point, so the answer depends neither on the thread count nor on the frame. Points with no
// emitter in front get 0. Throws penumbra::Error for rays < 1 or mismatched arrays.
std::vector<glm::vec3> EmitterIrradiance(const RayScene& rays, const std::vector<glm::vec3>& points,
                                         const std::vector<glm::vec3>& normals,
                                         const EmitterDirectSettings& settings = {});

}  // namespace penumbra
