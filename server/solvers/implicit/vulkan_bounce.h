// The implicit solver's bounces on a Vulkan device (shaders/implicit_bounce.comp): the
// leaves' exitant rows, the pull up the hierarchy level by level and each leaf's gather over
// its shares, the device twin of ImplicitSolver::ExitantTables and Bounce. The host hands it
// the shares at each relink (their indices into the table and their factors, Relink's) and
// the leaves' radiance at each bounce, and reads back what each leaf gathered. Glossy leaves
// are not on it: a scene with any bounces on the host.
#pragma once

#include <glm/vec3.hpp>
#include <memory>
#include <string>
#include <vector>

#include "gpu/fwd.h"
#include "hierarchy/directions.h"
#include "hierarchy/hierarchy.h"

namespace penumbra {

class VulkanBounce {
  public:
    VulkanBounce(gpu::Context& ctx, const Directions& dirs, const Hierarchy& h);
    ~VulkanBounce();
    VulkanBounce(const VulkanBounce&) = delete;
    VulkanBounce& operator=(const VulkanBounce&) = delete;

    // Why the shares of this many nodes and shares do not fit on the device (a table or a
    // list over its storage-buffer range), or empty when they do.
    std::string Unfit(size_t shares) const;
    // The shares as the last relink left them (ImplicitLinks::offsets; ImplicitSolver's
    // gatherAt_ and gatherFactor_) and the leaves as placed now (their normals and areas).
    void SetShares(const Hierarchy& h, const std::vector<uint32_t>& offsets,
                   const std::vector<uint32_t>& at, const std::vector<float>& factor);
    // One bounce: per leaf (hierarchy leaf order) its radiance, per bin the environment's
    // radiance along it; returns per leaf the irradiance gathered.
    std::vector<glm::vec3> Gather(const std::vector<glm::vec3>& radiance,
                                  const std::vector<glm::vec3>& environment);

    double msDevice = 0.0;  // the last Gather's upload, dispatches and readback
    double msBusy = 0.0;    // the device's own time in them (0: no timestamps)

  private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace penumbra
