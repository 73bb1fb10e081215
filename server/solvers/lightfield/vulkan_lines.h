// The light field's lines traced on a Vulkan device without ray tracing (lavapipe has none),
// as the paper does (Mortensen, Khanna, Slater 2008, Sec. 3.2): per direction an orthographic
// view of the lines' ball, one pixel a cell, its centre the cell's line; the surfaces along
// each line peeled layer by layer with the fixed-function depth test (Everitt 2001), each
// layer storing per pixel the triangle and its barycentrics (shaders/peel.{vert,frag}). A
// direction peels `layers` at a time and goes on while a line still has a surface left, so
// no line loses its far surfaces. The grid's jitter is one per direction (LineJitter::
// kPerDirection: a rasteriser samples pixel centres), so TraceBatch on the CPU with the same
// grid traces the same lines through Embree.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "gpu/fwd.h"
#include "rays/ray_scene.h"
#include "solvers/lightfield/lines.h"

namespace penumbra {

class VulkanLines {
  public:
    // Over `rays`' triangles (the refined mesh). Throws penumbra::Error for a device without
    // graphics, a grid wider than its images, or more triangles than a float names exactly.
    VulkanLines(gpu::Context& ctx, const RayScene& rays, const LineGrid& grid, int layers);
    ~VulkanLines();
    VulkanLines(const VulkanLines&) = delete;
    VulkanLines& operator=(const VulkanLines&) = delete;

    // TraceBatch (lines.h) on the device: `grid.jitter` must be kPerDirection.
    LineBatch TraceBatch(const std::vector<glm::vec3>& base, uint32_t seed, uint32_t batch);
    // The triangles again after surfaces moved (the same triangles, at new places).
    void Update(const RayScene& rays);

    int MostLayers() const { return mostLayers_; }  // the most surfaces a line met so far
    double msDevice = 0.0;                          // submissions and waits, all batches

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
    int mostLayers_ = 0;
};

}  // namespace penumbra
