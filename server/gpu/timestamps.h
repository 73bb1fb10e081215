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

// The device's own time of whole submissions, summed: each Run records a stamp before and
// after what `record` records, submits and waits (Context::RunNow), then adds the time
// between them. Beside a pass's wall time it says how much of it the device worked and how
// much went to the host's uploads, submissions, waits and read-backs. Without timestamps
// the sum stays 0.
class BusyTime {
  public:
    explicit BusyTime(Context& ctx) : ctx_(ctx), stamps_(ctx, 2) {}
    template <typename F>
    void Run(F&& record) {
        ctx_.RunNow([&](const vk::raii::CommandBuffer& cb) {
            stamps_.Reset(cb);
            stamps_.Write(cb, 0, vk::PipelineStageFlagBits::eTopOfPipe);
            record(cb);
            stamps_.Write(cb, 1, vk::PipelineStageFlagBits::eBottomOfPipe);
        });
        const std::vector<double> ms = stamps_.Milliseconds();
        if (!ms.empty()) ms_ += ms[0];
    }
    void Clear() { ms_ = 0.0; }
    double Ms() const { return ms_; }

  private:
    Context& ctx_;
    Timestamps stamps_;
    double ms_ = 0.0;
};

}  // namespace penumbra::gpu
