// Sec. 3.3 on the device: after a move (PlaceGroups), the links touching a moved group get
// their bins, spread levels and form factors again from the nodes and surfels at their new
// places (shaders/links.comp, the same rules as MakeLink on the host). Part of the Vulkan
// back end (vulkan_passes.h), which owns it when the model has motion links.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "gpu/fwd.h"
#include "solvers/antiradiance/model.h"

namespace penumbra {

class VulkanLinkUpdate {
  public:
    // Uploads what the update reads and never changes (the dynamic links' ends, the bin
    // lookup's tables, the near field) and the places as they are. `links`, `dirs`,
    // `spreadLevels`, `neighbours`: the back end's buffers, which it writes and reads.
    VulkanLinkUpdate(gpu::Context& ctx, const AntiradianceModel& model, gpu::Buffer& links,
                     gpu::Buffer& dirs, gpu::Buffer& spreadLevels, gpu::Buffer& neighbours);
    ~VulkanLinkUpdate();
    // Recomputes the links touching a group with moved[group] set, waited for.
    void Update(const std::vector<uint8_t>& moved);
    double Ms() const;  // device time of the last Update (0 without timestamps)

  private:
    struct State;
    // The nodes and surfels where the model has them now, and which groups moved.
    void UploadPlaces(const std::vector<uint8_t>& moved);
    gpu::Context& ctx_;
    const AntiradianceModel& m;
    std::unique_ptr<State> s_;
};

}  // namespace penumbra
