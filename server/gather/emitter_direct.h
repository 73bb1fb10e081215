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
    int rays = 256;     // rays per point: half shadow rays to the emitters, half cosine rays
    uint64_t seed = 1;  // the same seed gives the same answer (no flicker between frames)
    // Cosine-distributed rays per point traced elsewhere (the final gather's) whose emitter
    // hits the caller adds with EmitterHitWeight: the weights here count them in.
    int extraCosineRays = 0;
};

// E(x) = ∫ L_e(y) cosθ_x cosθ_y / |x − y|² V(x, y) dA_y over every emitting triangle's front,
// per point x with unit normal n, by multiple importance sampling (Veach 1997, the power
// heuristic) of two kinds of rays: an emitting triangle chosen by power and a point on it
// (RayScene::PickEmitter, AreaPdf: jittered strata for the choice, a rotated R2 sequence for
// the point), and cosine-distributed directions (a rotated R2 sequence), each kind with a
// random stream of its own per point, so the answer depends neither on the thread count nor
// on the frame. Light sampling alone is unbounded where an emitter lies close to the point
// (the 1/d² of the area measure); cosine sampling alone misses small emitters. Points with no
// emitter in front get 0. Throws penumbra::Error for rays < 1 or mismatched arrays.
std::vector<glm::vec3> EmitterIrradiance(const RayScene& rays, const std::vector<glm::vec3>& points,
                                         const std::vector<glm::vec3>& normals,
                                         const EmitterDirectSettings& settings = {});

// The share of E that a cosine-distributed ray from a point with normal n, meeting emitting
// triangle `triangle`'s front at distance t in direction w, adds to EmitterIrradiance with
// `settings` (extraCosineRays counting this ray's kind): weight × L_e, zero for a triangle
// that does not emit or is met from behind.
float EmitterHitWeight(const RayScene& rays, const EmitterDirectSettings& settings,
                       const glm::vec3& n, const glm::vec3& w, uint32_t triangle, float t);

}  // namespace penumbra
