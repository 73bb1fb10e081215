// The environment as the solvers see it: radiance from infinity averaged over each
// direction bin. Antiradiance initialises every element's incident radiance L_in with it
// (Sec. 3.3, "Direct Light Initialization": "initialize all the L_in using an environment
// map"); the antiradiance of whatever stands in between then removes the occluded part, so
// the sky needs no rays of its own.
#pragma once

#include <glm/glm.hpp>
#include <vector>

#include "hierarchy/directions.h"
#include "scene/environment.h"

namespace penumbra::direct {

// Per bin b: the mean radiance travelling along ω_b, i.e. arriving from −ω_b, over bin b's
// cell of the sphere (the directions whose nearest bin is b), intensity and rotation applied.
// Maps of at least kEnvironmentGrid rows are averaged pixel by pixel (each pixel weighted by
// its solid angle); smaller maps and constant skies are sampled bilinearly on a
// kEnvironmentGrid × 2·kEnvironmentGrid grid. All zero for an inactive environment.
std::vector<glm::vec3> EnvironmentBins(const Environment& environment, const Directions& dirs);
inline constexpr int kEnvironmentGrid = 256;

}  // namespace penumbra::direct
