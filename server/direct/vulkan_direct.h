// The shadow and direct passes on a Vulkan device: shadow maps rendered with the raster
// pipeline (shaders/shadow.vert, shadow.frag), then E_d per receiver in a compute pass
// (shaders/direct.comp), written into a buffer the solver's local pass reads.
// direct_light.h has the CPU twins and the layouts.
#pragma once

#include <memory>
#include <vector>

#include "direct/direct_light.h"

namespace penumbra {
namespace gpu {
class Buffer;
class Context;
}  // namespace gpu

namespace direct {

class VulkanDirect {
  public:
    // `out` holds one vec4 per receiver and outlives this object. Throws penumbra::Error
    // when the device cannot rasterise into storage buffers.
    VulkanDirect(gpu::Context& ctx, const Scene& scene, std::vector<GpuReceiver> receivers,
                 gpu::Buffer& out, int mapSize);
    ~VulkanDirect();

    // Plans from the scene's lights (geometry as at construction), renders, waits.
    void Update(const Scene& scene);
    // After a rigid move (same triangles and receivers, at new places): uploads the scene's
    // triangles and `receivers` into the buffers there are, then Update.
    void Move(const Scene& scene, std::vector<GpuReceiver> receivers);
    std::vector<float> ReadIrradiance() const;  // stride 4, as the CPU twin's
    // Each of the first `lights` lights' share, as CpuDirect::PerLight.
    std::vector<float> ReadPerLight(size_t lights) const;
    std::vector<float> ReadMaps() const;    // depths, as RasterShadowMaps writes them
    double msShadow = 0.0, msDirect = 0.0;  // last update, device time
    int views = 0;                          // shadow maps the last update rendered

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace direct
}  // namespace penumbra
