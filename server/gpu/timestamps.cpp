// Timestamp queries with a companion write after each stamp (see timestamps.h).
#include "gpu/timestamps.h"

#include "base/check.h"

namespace penumbra::gpu {

Timestamps::Timestamps(Context& ctx, uint32_t count) : ctx_(ctx), count_(count) {
    if (ctx.TimestampPeriodNs() > 0.0f)
        pool_ = vk::raii::QueryPool(
            ctx.Device(), vk::QueryPoolCreateInfo({}, vk::QueryType::eTimestamp, 2 * count));
}

void Timestamps::Reset(const vk::raii::CommandBuffer& cb) const {
    if (*this) cb.resetQueryPool(*pool_, 0, 2 * count_);
}

void Timestamps::Write(const vk::raii::CommandBuffer& cb, uint32_t i,
                       vk::PipelineStageFlagBits stage) const {
    PENUMBRA_CHECK_LT(i, count_);
    if (!*this) return;
    cb.writeTimestamp(stage, *pool_, 2 * i);
    cb.writeTimestamp(stage, *pool_, 2 * i + 1);
}

std::vector<double> Timestamps::Milliseconds() const {
    if (!*this) return {};
    auto [result, ticks] =
        pool_.getResults<uint64_t>(0, 2 * count_, 2 * count_ * sizeof(uint64_t), sizeof(uint64_t),
                                   vk::QueryResultFlagBits::e64 | vk::QueryResultFlagBits::eWait);
    if (result != vk::Result::eSuccess) ThrowVulkan("vkGetQueryPoolResults", result);
    const double ns = ctx_.TimestampPeriodNs();
    std::vector<double> ms;
    for (uint32_t i = 0; i + 1 < count_; ++i)
        ms.push_back(static_cast<double>(ticks[2 * i + 2] - ticks[2 * i]) * ns * 1e-6);
    return ms;
}

}  // namespace penumbra::gpu
