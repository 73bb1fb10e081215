// The emitters' direct light as a solver's first shot (first_shot.h).
#include "gather/first_shot.h"

#include <chrono>

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
    scene_ = scene;
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

}  // namespace penumbra
