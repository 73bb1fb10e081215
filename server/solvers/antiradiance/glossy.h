// Glossy surfaces in the antiradiance solver: Phong lobes discretised on the bins
// (solvers/bin_lobes.h), the mirror bin of every incoming bin per glossy leaf, and the
// punctual lights' direct light reflected by the lobes at their exact directions.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "gpu/layout.h"
#include "scene/scene.h"
#include "solvers/bin_lobes.h"

namespace penumbra {

struct AntiradianceModel;  // solvers/antiradiance/model.h

// A glossy leaf: its lobe's F0 and which discretised lobe it uses. Layout shared with
// shaders/common.glsl (struct GlossyLeaf).
struct GlossyLeaf {
    glm::vec3 specular;  // F0
    uint32_t lobe;       // index into AntiradianceModel::lobes
};
static_assert(sizeof(GlossyLeaf) == 16);
PENUMBRA_GPU_FIELD(GlossyLeaf, specular, 0);
PENUMBRA_GPU_FIELD(GlossyLeaf, lobe, 12);

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
