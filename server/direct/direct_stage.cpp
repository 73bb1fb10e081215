// The direct-light stage's back-end choice and the sky's re-binning.
#include "direct/direct_stage.h"

#include "base/check.h"
#include "direct/environment_light.h"
#include "gpu/buffer.h"

namespace penumbra::direct {

std::unique_ptr<DirectStage> MakeDirectStage(const Scene& scene, std::vector<GpuReceiver> receivers,
                                             int mapSize, gpu::Context* device, gpu::Buffer* out) {
    if (device && out)
        return std::make_unique<UploadedDirect>(scene, std::move(receivers), *out, mapSize);
    return std::make_unique<CpuDirect>(scene, std::move(receivers), mapSize);
}

UploadedDirect::UploadedDirect(const Scene& scene, std::vector<GpuReceiver> receivers,
                               gpu::Buffer& out, int mapSize)
    : cpu_(scene, std::move(receivers), mapSize), out_(out) {
    Upload();
}

void UploadedDirect::Update(const Scene& scene) {
    cpu_.Update(scene);
    Upload();
}

void UploadedDirect::Move(const Scene& scene, std::vector<GpuReceiver> receivers) {
    cpu_.Move(scene, std::move(receivers));
    Upload();
}

void UploadedDirect::Upload() {
    const std::vector<float> e = cpu_.Irradiance();
    PENUMBRA_CHECK_LE(e.size() * sizeof(float), out_.Bytes());
    out_.Upload(e);
    msShadow = cpu_.msShadow;
    msDirect = cpu_.msDirect;
    views = 0;
}

bool SkyBins::Update(const Environment& sky, const Directions& dirs, std::vector<glm::vec3>& bins) {
    ValidateEnvironment(sky);
    if (binned_ && sky.image == last_.image && sky.constant == last_.constant &&
        sky.intensity == last_.intensity && sky.rotation == last_.rotation)
        return false;
    bins = EnvironmentBins(sky, dirs);
    last_ = sky;
    binned_ = true;
    return true;
}

bool UpdateDirectStage(DirectStage* stage, int lights, const Scene& scene) {
    if (!stage) {
        if (scene.lights.empty()) return false;
        throw Error("the scene was loaded without punctual lights; lights cannot be added");
    }
    if (scene.lights.size() != static_cast<size_t>(lights))
        throw Error("the number of punctual lights cannot change in a loaded scene");
    stage->Update(scene);
    return true;
}

LightingFigures DescribeLighting(const DirectStage* stage, int mapSize, const SkyBins& sky) {
    LightingFigures s;
    if (stage) {
        s.direct = true;
        s.shadowViews = stage->views;
        s.shadowMapSize = mapSize;
        s.msShadow = stage->msShadow;
        s.msDirect = stage->msDirect;
    }
    if (const Environment& env = sky.Last(); env.Active()) {
        s.environment = env.source;
        s.environmentIntensity = env.intensity;
        s.environmentRotation = env.rotation;
    }
    return s;
}

}  // namespace penumbra::direct
