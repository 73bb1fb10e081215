// The shadow and direct passes on a Vulkan device: shadow maps rendered with the raster
// pipeline (shaders/shadow.vert, shadow.frag), then E_d per receiver in a compute pass
// (shaders/direct.comp), written into a buffer the solver's local pass reads.
// direct_light.h has the CPU twins and the layouts.
#pragma once

#include <memory>
#include <vector>

#include "direct/direct_stage.h"
#include "gpu/fwd.h"

namespace penumbra {
namespace direct {

class VulkanDirect : public DirectStage {
  public:
    // `out` holds one vec4 per receiver and outlives this object. Throws penumbra::Error
    // when the device cannot rasterise into storage buffers.
    VulkanDirect(gpu::Context& ctx, const Scene& scene, std::vector<GpuReceiver> receivers,
                 gpu::Buffer& out, int mapSize);
    ~VulkanDirect() override;

    // Plans from the scene's lights (geometry as at construction), renders, waits.
    void Update(const Scene& scene) override;
    // Uploads the scene's triangles and `receivers` into the buffers there are.
    void Move(const Scene& scene, std::vector<GpuReceiver> receivers) override;
    std::vector<float> Irradiance() const override;  // read back from `out`
    std::vector<float> PerLight() const override;
    std::vector<float> ReadMaps() const;  // depths, as RasterShadowMaps writes them

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
    size_t lights_ = 0;  // of the last Update
};

}  // namespace direct
}  // namespace penumbra
