// Timestamp queries for device time between points of a command buffer.
#pragma once

#include <cstdint>
#include <vector>

#include "gpu/context.h"

namespace penumbra::gpu {

// `count` timestamps, each written together with a companion query right after it.
// lavapipe (Mesa 22.3) flushes *before* it records a timestamp; once a render pass has
// run in the device's context (the shadow pass of punctual lights), the recording is
// binned with the rasteriser's scene and only happens at the next flush, so without the
// companion every stamp would read the time of the one after it (passes reported one
// pass late). Devices without timestamps give an empty pool: Write is a no-op, and
// Milliseconds returns nothing.
class Timestamps {
  public:
    Timestamps(Context& ctx, uint32_t count);
    explicit operator bool() const { return static_cast<bool>(*pool_); }

    void Reset(const vk::raii::CommandBuffer& cb) const;
    void Write(const vk::raii::CommandBuffer& cb, uint32_t i,
               vk::PipelineStageFlagBits stage = vk::PipelineStageFlagBits::eComputeShader) const;
    // Milliseconds from stamp i to stamp i + 1 for each i, waiting for the results (the
    // command buffer must have been submitted); empty without timestamps.
    std::vector<double> Milliseconds() const;

  private:
    Context& ctx_;
    uint32_t count_;
    vk::raii::QueryPool pool_{nullptr};
};

}  // namespace penumbra::gpu
