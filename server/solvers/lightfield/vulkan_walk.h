// The light field's walk on a Vulkan device with float atomics (shaders/lf_walk.comp and
// lf_flush.comp; WalkBatch in lines.h is the CPU twin, and the answer is the same up to the
// order of float additions). A batch's lines are uploaded once and kept on the device until
// they change (a move's re-trace); the surfels' radiance, the sky per direction and the glossy
// surfels' exitant light go up each walk, the weighted sums come back.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "gpu/fwd.h"
#include "rays/ray_scene.h"
#include "scene/environment.h"
#include "solvers/lightfield/lines.h"

namespace penumbra {

class VulkanWalk {
  public:
    // For `rays`' triangles (the refined mesh) and its `surfels`; a walk takes as many
    // directions at a time as their (direction, surfel) sums fit in `sumBytes`. Throws
    // penumbra::Error for a device without float atomics.
    VulkanWalk(gpu::Context& ctx, const RayScene& rays, size_t surfels,
               size_t sumBytes = size_t(256) << 20);
    ~VulkanWalk();
    VulkanWalk(const VulkanWalk&) = delete;
    VulkanWalk& operator=(const VulkanWalk&) = delete;

    // After surfaces moved: the hats' facets again (SurfelFacets over the moved mesh).
    void SetFacets(const SurfelFacets& facets);
    // Batch `index`'s lines changed (re-traced after a move): uploaded again at its next walk.
    void Invalidate(size_t index);
    // WalkBatch (lines.h) for kept batch `index` (`b`).
    void Walk(size_t index, const LineBatch& b, float cellArea,
              const std::vector<glm::vec3>& radiance, const Environment* sky,
              std::vector<glm::vec3>& weighted, std::vector<float>& sampled,
              const GlossyLines* glossy = nullptr);

    double msDevice = 0.0;  // uploads, submissions and waits, all walks

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace penumbra
