#include "solvers/receiver_light.h"

#include <numbers>
#include <string>

#include "base/check.h"

namespace penumbra {

void ReceiverLight::Reset(std::vector<uint32_t> order) {
    surfel = std::move(order);
    const size_t n = surfel.size();
    gathered.assign(n, glm::vec3(0.0f));
    direct.assign(n, glm::vec3(0.0f));
    radiance.assign(n, glm::vec3(0.0f));
    albedo.assign(n, glm::vec3(0.0f));
    emission.assign(n, glm::vec3(0.0f));
    emitterDirect.clear();
}

void ReceiverLight::Rematerial(const Surfels& surfels, const std::vector<Material>& materials) {
    albedo.resize(size());
    emission.resize(size());
    for (size_t i = 0; i < size(); ++i) {
        const uint32_t s = surfel[i];
        const Material& m = materials[surfels.materials[s]];
        albedo[i] = surfels.Albedo(m, s);
        // With a first shot from outside (SetEmitterDirect) the emitters' light is not carried.
        emission[i] = emitterDirect.empty() ? surfels.Emission(m, s) : glm::vec3(0.0f);
    }
    Reradiate();
}

void ReceiverLight::Reradiate() {
    const float invPi = 1.0f / std::numbers::pi_v<float>;
    radiance.resize(size());
    for (size_t i = 0; i < size(); ++i) {
        glm::vec3 arriving = gathered[i] + direct[i];
        if (!emitterDirect.empty()) arriving += emitterDirect[i];
        radiance[i] = emission[i] + albedo[i] * invPi * arriving;
    }
}

void ReceiverLight::CopyDirect(const std::vector<float>& rgba) {
    PENUMBRA_CHECK_EQ(rgba.size(), 4 * size());
    for (size_t i = 0; i < size(); ++i)
        direct[i] = glm::vec3(rgba[i * 4], rgba[i * 4 + 1], rgba[i * 4 + 2]);
}

void ReceiverLight::SetEmitterDirect(const std::vector<glm::vec3>& perSurfel, size_t surfels) {
    if (!perSurfel.empty() && perSurfel.size() != surfels)
        throw Error("emitter direct light for " + std::to_string(perSurfel.size()) +
                    " surfels; the solver has " + std::to_string(surfels));
    emitterDirect.clear();
    if (perSurfel.empty()) return;
    emitterDirect.resize(size());
    for (size_t i = 0; i < size(); ++i) emitterDirect[i] = perSurfel[surfel[i]];
}

std::vector<glm::vec3> ReceiverLight::SurfelIrradiance(Channel channel, size_t surfels) const {
    std::vector<glm::vec3> out(surfels, glm::vec3(0.0f));
    for (size_t i = 0; i < size(); ++i) {
        glm::vec3 indirect = gathered[i];
        if (!emitterDirect.empty()) indirect += emitterDirect[i];
        out[surfel[i]] = channel == Channel::kDirect  ? direct[i]
                         : channel == Channel::kTotal ? indirect + direct[i]
                                                      : indirect;
    }
    return out;
}

void AssignSurfelMaterials(const Scene& scene, Surfels& surfels) {
    PENUMBRA_CHECK_EQ(scene.primitives.size(), surfels.firstSurfel.size());
    for (size_t p = 0; p < scene.primitives.size(); ++p)
        for (size_t s = surfels.firstSurfel[p]; s < surfels.End(p); ++s)
            surfels.materials[s] = scene.primitives[p].material;
}

}  // namespace penumbra
