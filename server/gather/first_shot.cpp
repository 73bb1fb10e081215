// The emitters' direct light as a solver's first shot (first_shot.h).
#include "gather/first_shot.h"

#include <algorithm>
#include <chrono>

#include "base/check.h"

namespace penumbra {

EmitterFirstShot::EmitterFirstShot(std::unique_ptr<Solver> inner, const Scene& scene,
                                   const EmitterDirectSettings& settings)
    : inner_(std::move(inner)), scene_(scene), settings_(settings) {
    Shoot();
}

void EmitterFirstShot::Shoot() {
    auto start = std::chrono::steady_clock::now();
    const Surfels& s = inner_->GetSurfels();
    RayScene rays(scene_);
    inner_->SetEmitterDirect(EmitterIrradiance(rays, s.positions, s.normals, settings_));
    msShot_ =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
}

void EmitterFirstShot::UpdateMaterials(const Scene& scene) {
    bool emissionChanged = scene.materials.size() != scene_.materials.size();
    for (size_t m = 0; !emissionChanged && m < scene.materials.size(); ++m)
        emissionChanged = scene.materials[m].emission != scene_.materials[m].emission;
    for (size_t p = 0; !emissionChanged && p < scene.primitives.size(); ++p)
        emissionChanged = scene.primitives[p].material != scene_.primitives[p].material;
    // Only what a material edit changes (no vertex arrays copied on an edit).
    scene_.materials = scene.materials;
    for (size_t p = 0; p < scene.primitives.size() && p < scene_.primitives.size(); ++p)
        scene_.primitives[p].material = scene.primitives[p].material;
    inner_->UpdateMaterials(scene);
    if (emissionChanged) Shoot();
}

void EmitterFirstShot::UpdateLights(const Scene& scene) {
    scene_.lights = scene.lights;
    scene_.environment = scene.environment;
    inner_->UpdateLights(scene);
}

void EmitterFirstShot::UpdateGeometry(const Scene& scene) {
    inner_->UpdateGeometry(scene);
    scene_ = scene;
    Shoot();
}

SolverStats EmitterFirstShot::Stats() const {
    SolverStats s = inner_->Stats();
    s.emitterRays = settings_.rays;
    s.msEmitterDirect = msShot_;
    return s;
}

void CheckEmitterRays(int rays) {
    if (rays < 0 || rays > kMaxEmitterRays)
        throw Error("emitter direct light takes 0 (off) to " + std::to_string(kMaxEmitterRays) +
                    " rays a surfel, not " + std::to_string(rays));
}

std::unique_ptr<Solver> WithEmitterDirect(std::unique_ptr<Solver> solver, const Scene& scene,
                                          int rays, std::string* declined) {
    CheckEmitterRays(rays);
    std::string why;
    const bool glossy = std::any_of(scene.materials.begin(), scene.materials.end(),
                                    [](const Material& m) { return m.Glossy(); });
    const bool emitters = std::any_of(
        scene.materials.begin(), scene.materials.end(),
        [](const Material& m) { return glm::any(glm::greaterThan(m.emission, glm::vec3(0.0f))); });
    if (rays <= 0)
        why = "off";
    else if (!emitters)
        why = "the scene has no emitting surfaces";
    else if (glossy)
        why =
            "not yet for scenes with glossy materials (their lobes would miss it); the solver "
            "carries the emission";
    if (declined) *declined = why;
    if (!why.empty()) return solver;
    EmitterDirectSettings settings;
    settings.rays = rays;
    return std::make_unique<EmitterFirstShot>(std::move(solver), scene, settings);
}

}  // namespace penumbra
