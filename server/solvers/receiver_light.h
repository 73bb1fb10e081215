// The light a solver keeps per receiver, where a receiver is one surfel (the light field: in
// surfel order) or the hierarchy leaf that stands for one (implicit visibility: in leaf order):
// albedo and emission, the light gathered by bounces, the punctual lights' direct light, the
// gather stage's first shot, and the radiance leaving (B = E + ρ/π · E_arriving). One copy of
// that bookkeeping for the solvers that gather per surfel.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "scene/scene.h"
#include "scene/surfels.h"
#include "solver/solver.h"

namespace penumbra {

struct ReceiverLight {
    std::vector<uint32_t> surfel;  // per receiver: its surfel
    // Per receiver: albedo, emission carried (none under a first shot), irradiance gathered by
    // the bounces, the punctual lights' E_d, the first shot (empty: none), radiance leaving.
    std::vector<glm::vec3> albedo, emission, gathered, direct, emitterDirect, radiance;

    // Receivers in `order` (surfel indices), nothing gathered yet.
    void Reset(std::vector<uint32_t> order);
    size_t size() const { return surfel.size(); }

    // Albedo and emission per receiver from the surfels' materials, then Reradiate.
    void Rematerial(const Surfels& surfels, const std::vector<Material>& materials);
    // The light leaving each receiver from the light arriving there now.
    void Reradiate();
    // E_d per receiver from the direct stage's RGBA rows (in receiver order).
    void CopyDirect(const std::vector<float>& rgba);
    // The gather stage's first shot per surfel (empty: none); throws on a count that is not
    // the surfels'. Emission is then no longer carried: call Rematerial after.
    void SetEmitterDirect(const std::vector<glm::vec3>& perSurfel, size_t surfels);
    // Per surfel: `direct` the punctual lights, `indirect` bounces and first shot, or both.
    std::vector<glm::vec3> SurfelIrradiance(Channel channel, size_t surfels) const;
};

// Each surfel's material from its primitive's (after a SetMaterial edit moved a primitive to
// another material).
void AssignSurfelMaterials(const Scene& scene, Surfels& surfels);

}  // namespace penumbra
