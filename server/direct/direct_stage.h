// The direct-light stage every solver shares (docs/ARCHITECTURE.md): the punctual lights' shadowed
// direct irradiance E_d at a solver's receivers, on the CPU (CpuDirect, direct_light.h) or a
// Vulkan device (VulkanDirect, vulkan_direct.h) behind one interface, and the sky binned on a
// solver's directions, redone only when the sky changed. A solver names its receivers (its
// elements' surfels, in its own order) and reads E_d back; it never picks a back end.
#pragma once

#include <memory>
#include <vector>

#include "direct/direct_light.h"
#include "gpu/fwd.h"
#include "hierarchy/directions.h"
#include "scene/environment.h"
#include "scene/scene.h"
#include "solver/solver.h"

namespace penumbra {
namespace direct {

class DirectStage {
  public:
    virtual ~DirectStage() = default;
    // Re-plans from the scene's lights (geometry as at construction), renders, waits.
    virtual void Update(const Scene& scene) = 0;
    // After a rigid move (same triangles and receivers, at new places): takes the scene's
    // triangles and `receivers` again, then Update.
    virtual void Move(const Scene& scene, std::vector<GpuReceiver> receivers) = 0;
    // E_d per receiver (RGB, stride 4) and each light's share (lights × receivers × 4), as
    // the last Update left them.
    virtual std::vector<float> Irradiance() const = 0;
    virtual std::vector<float> PerLight() const = 0;
    double msShadow = 0.0, msDirect = 0.0;  // last update (device time on a device)
    int views = 0;                          // shadow maps the last update rendered
};

// Both passes on the CPU (the twins of direct_light.h), with their wall times.
class CpuDirect : public DirectStage {
  public:
    CpuDirect(const Scene& scene, std::vector<GpuReceiver> receivers, int mapSize);
    // Re-plans from the scene's lights (geometry as at construction) and recomputes.
    void Update(const Scene& scene) override;
    void Move(const Scene& scene, std::vector<GpuReceiver> receivers) override;
    std::vector<float> Irradiance() const override { return out_; }
    std::vector<float> PerLight() const override { return perLight_; }
    const std::vector<float>& Maps() const { return maps_; }

  private:
    std::vector<glm::vec3> triangles_;
    std::vector<GpuReceiver> receivers_;
    int mapSize_;
    std::vector<float> maps_;
    std::vector<float> out_;
    std::vector<float> perLight_;
};

// The stage for `scene`'s lights at `receivers`: on `device` when given, rendering E_d into
// `out` (one vec4 per receiver, outliving the stage) where the solver's passes read it,
// else on the CPU. Throws penumbra::Error for a bad map size or a device without graphics.
std::unique_ptr<DirectStage> MakeDirectStage(const Scene& scene, std::vector<GpuReceiver> receivers,
                                             int mapSize, gpu::Context* device = nullptr,
                                             gpu::Buffer* out = nullptr);

// Re-reads `scene`'s punctual lights into `stage` (null: the solver was built without any;
// `lights`: how many it was built with). False when there is no stage and no light; throws
// penumbra::Error for lights added to a scene loaded without, or a changed count.
bool UpdateDirectStage(DirectStage* stage, int lights, const Scene& scene);

// The sky as a solver's bins see it (EnvironmentBins), re-binned only when it changed (a map
// costs a pass over its pixels).
class SkyBins {
  public:
    // Bins `sky` on `dirs` into `bins` when it differs from the sky last binned (or none was
    // yet); returns whether it did. Throws penumbra::Error for an invalid environment.
    bool Update(const Environment& sky, const Directions& dirs, std::vector<glm::vec3>& bins);
    // Records `sky` as binned already (by whoever made the bins).
    void Binned(const Environment& sky) { last_ = sky, binned_ = true; }
    const Environment& Last() const { return last_; }

  private:
    Environment last_;
    bool binned_ = false;
};

// The direct stage's figures (null: none; `mapSize` its maps') and the sky's in `stats`.
void DescribeLighting(const DirectStage* stage, int mapSize, const SkyBins& sky,
                      SolverStats& stats);

}  // namespace direct
}  // namespace penumbra
