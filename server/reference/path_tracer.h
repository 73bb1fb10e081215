// Ground truth for the solvers: a CPU path tracer on Embree that estimates, at every input
// vertex, the irradiance the solvers output, with a per-vertex standard error.
#pragma once

#include <cstdint>
#include <functional>
#include <glm/glm.hpp>
#include <vector>

#include "output/irradiance_writer.h"
#include "scene/scene.h"
#include "solver/solver.h"

namespace penumbra {

struct ReferenceSettings {
    int samples = 1024;  // per vertex; each sample is one light path
    int maxDepth = 64;   // bounces after the vertex; Russian roulette ends most paths sooner
    uint64_t seed = 1;
    int threads = 0;  // 0: all cores
    Channel channel = Channel::kIndirect;
    // Called with the fraction done (0..1) and the estimated seconds left, from any thread,
    // never by two threads at once.
    std::function<void(double fraction, double secondsLeft)> progress;
};

struct ReferenceStats {
    int samples = 0;
    int maxDepth = 0;
    uint64_t seed = 0;
    int threads = 0;
    size_t vertices = 0;
    uint64_t rays = 0;  // closest-hit and shadow rays together
    double seconds = 0;
    double RaysPerSecond() const { return seconds > 0 ? rays / seconds : 0.0; }
};

struct ReferenceResult {
    // One array per scene primitive, in the primitive's input vertex order.
    std::vector<std::vector<glm::vec3>> irradiance;
    std::vector<std::vector<glm::vec3>> standardError;  // of each mean, per channel
    ReferenceStats stats;
};

// Irradiance at every input vertex over the hemisphere of its normal, in the settings'
// channel: `indirect` is the light of emitting surfaces plus every bounce of any light
// (punctual lights included), `direct` the light arriving straight from punctual lights
// (shadow rays, exact: no sampling, so its standard error is 0), `total` their sum.
// A path that leaves the scene picks up the environment's radiance (scene.environment) and
// counts as `indirect`; an environment map is also sampled by its brightness (a next-event
// estimate towards its bright pixels, by MIS against the BRDF's sampling), so that a sun in
// the map is found by every path rather than by the few that happen to escape towards it.
// Punctual lights follow KHR_lights_punctual (LightAttenuation in scene.h). Surfaces reflect
// with their material's diffuse part and glossy lobe (docs/MATERIALS.md, the lobe with the
// material's own exponent), reflecting and emitting on their front side (the side their vertex
// normals point to); a ray that reaches a back side ends there (opaque, black). Each vertex is
// estimated 10⁻³ × the scene's diameter inside its own surface (towards its triangles), so that a
// vertex on an edge another wall meets sees the room, not that wall's back. Deterministic for a
// fixed seed whatever the thread count: each vertex has its own random stream. Throws
// penumbra::Error on an Embree failure or invalid settings.
ReferenceResult RenderReference(const Scene& scene, const ReferenceSettings& settings);

// RenderReference's answer as `compare` reads it (solver "reference", the settings' channel).
IrradianceFile ReferenceFile(const Scene& scene, const ReferenceSettings& settings);

}  // namespace penumbra
