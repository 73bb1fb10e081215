// The direct-light stage every solver shares (docs/ARCHITECTURE.md): the punctual lights' shadowed
// direct irradiance E_d at a solver's receivers, by shadow rays on the CPU (CpuDirect), for a
// solver on a Vulkan device uploaded where its passes read it (UploadedDirect), behind one
// interface, and the sky binned on a solver's directions, redone only when the sky changed. A
// solver names its receivers (its elements' surfels, in its own order) and reads E_d back; it
// never picks a back end. VulkanDirect (vulkan_direct.h: shadow maps on the device) is not
// used by the solvers: its maps let light through surfaces thinner than a texel and where
// two surfaces meet (docs/SOLVER.md "Direct light").
#pragma once

#include <memory>
#include <string>
#include <vector>

#include "direct/direct_light.h"
#include "gpu/fwd.h"
#include "hierarchy/directions.h"
#include "scene/environment.h"
#include "scene/scene.h"
#include "solver/stage_figures.h"

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

// The CPU back end: the direct pass with shadow rays (DirectIrradianceByRays), timed.
class CpuDirect : public DirectStage {
  public:
    // Shadow rays through an Embree BVH of the scene's triangles (DirectIrradianceByRays);
    // `mapSize` is kept for the stats only (no maps are drawn). `views` stays 0, msShadow is
    // the BVH's build.
    CpuDirect(const Scene& scene, std::vector<GpuReceiver> receivers, int mapSize);
    // Re-plans from the scene's lights (geometry as at construction) and recomputes.
    void Update(const Scene& scene) override;
    void Move(const Scene& scene, std::vector<GpuReceiver> receivers) override;
    std::vector<float> Irradiance() const override { return out_; }
    std::vector<float> PerLight() const override { return perLight_; }

  private:
    void Trace(const Scene& scene);  // the BVH of the scene's triangles, timed
    // The scene's geometry as last built (the BVH reads it): its primitives and materials.
    Scene geometry_;
    std::unique_ptr<RayScene> rays_;
    std::vector<GpuReceiver> receivers_;
    std::vector<float> out_;
    std::vector<float> perLight_;
};

// CpuDirect for a solver on a Vulkan device: each update's E_d uploaded into `out` (one vec4
// per receiver, outliving the stage), where the solver's passes read it.
class UploadedDirect : public DirectStage {
  public:
    UploadedDirect(const Scene& scene, std::vector<GpuReceiver> receivers, gpu::Buffer& out,
                   int mapSize);
    void Update(const Scene& scene) override;
    void Move(const Scene& scene, std::vector<GpuReceiver> receivers) override;
    std::vector<float> Irradiance() const override { return cpu_.Irradiance(); }
    std::vector<float> PerLight() const override { return cpu_.PerLight(); }

  private:
    void Upload();
    CpuDirect cpu_;
    gpu::Buffer& out_;
};

// The stage for `scene`'s lights at `receivers`: with `device` and `out`, E_d uploaded into
// `out` (UploadedDirect), else on the CPU. Throws penumbra::Error for a bad map size.
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

// The direct stage's figures (null: none; `mapSize` its maps') and the sky's: their part of a
// solver's stats (SolverStats::lighting).
LightingFigures DescribeLighting(const DirectStage* stage, int mapSize, const SkyBins& sky);

}  // namespace direct
}  // namespace penumbra
