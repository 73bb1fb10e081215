// The implicit solver's bounces on a Vulkan device (vulkan_bounce.h).
#include "solvers/implicit/vulkan_bounce.h"

#include <algorithm>
#include <chrono>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/dispatch.h"
#include "gpu/layout.h"
#include "gpu/pipeline.h"
#include "gpu/timestamps.h"
#include "shaders/implicit_bounce_spv.h"
#include "solvers/implicit/implicit_links.h"

namespace penumbra {
namespace {

// shaders/implicit_bounce.comp (push constants).
struct BouncePush {
    uint32_t mode, bins, leaves, first, count, sumsAt, environmentAt;
};
PENUMBRA_GPU_WORDS(BouncePush, 7);

}  // namespace

struct VulkanBounce::Impl {
    gpu::Context& ctx;
    const Directions& dirs;
    gpu::Pipeline pipeline;
    gpu::Buffer dirBuffer;
    size_t nodes = 0, leaves = 0, bins = 0;
    // The pull's levels, deepest first: each level's first entry and count in `levels`.
    std::vector<std::pair<uint32_t, uint32_t>> levelRanges;
    std::unique_ptr<gpu::Buffer> table, leafNormalArea, leafNode, radiance, levels, offsets, at,
        factor, gathered;
    size_t shareCapacity = 0;
    gpu::BusyTime busy;

    Impl(gpu::Context& c, const Directions& d, const Hierarchy& h)
        : ctx(c),
          dirs(d),
          pipeline(c, gpu::Words(kSpirv_implicit_bounce), 10, std::span<const uint32_t>{},
                   sizeof(BouncePush)),
          dirBuffer(c, size_t(d.Count()) * sizeof(glm::vec4)),
          busy(c) {
        std::vector<glm::vec4> up;
        for (const glm::vec3& w : d.All()) up.emplace_back(w, 0.0f);
        dirBuffer.Upload(up);
        nodes = h.size();
        leaves = h.leaves.size();
        bins = size_t(d.Count());
        std::vector<glm::uvec2> all;
        for (size_t depth = h.byDepth.size(); depth-- > 0;) {
            const uint32_t first = uint32_t(all.size());
            for (uint32_t n : h.byDepth[depth])
                if (!h.nodes[n].IsLeaf()) all.push_back({n, h.nodes[n + 1].end});
            if (all.size() > first) levelRanges.push_back({first, uint32_t(all.size()) - first});
        }
        levels = MakeBuffer(c, std::max<size_t>(1, all.size()) * sizeof(glm::uvec2));
        if (!all.empty()) levels->Upload(all);
        table = MakeBuffer(c, Table().Entries() * sizeof(glm::vec4));
        leafNormalArea = MakeBuffer(c, leaves * sizeof(glm::vec4));
        leafNode = MakeBuffer(c, leaves * sizeof(uint32_t));
        leafNode->Upload(h.leaves);
        radiance = MakeBuffer(c, (leaves + bins) * sizeof(glm::vec4));
        offsets = MakeBuffer(c, (leaves + 1) * sizeof(uint32_t));
        gathered = MakeBuffer(c, leaves * sizeof(glm::vec4));
    }
    ShareTable Table() const { return {nodes, bins}; }
};

VulkanBounce::VulkanBounce(gpu::Context& ctx, const Directions& dirs, const Hierarchy& h)
    : impl_(std::make_unique<Impl>(ctx, dirs, h)) {}

VulkanBounce::~VulkanBounce() = default;

std::string VulkanBounce::Unfit(size_t shares) const {
    const Impl& s = *impl_;
    const size_t range = s.ctx.Limits().maxStorageBufferRange;
    const size_t tableBytes = s.Table().Entries() * sizeof(glm::vec4);
    if (tableBytes > range)
        return "the bounce's table (" + std::to_string(tableBytes >> 20) +
               " MiB) exceeds the device's storage-buffer range";
    if (shares * sizeof(uint32_t) > range)
        return "the shares' list exceeds the device's storage-buffer range";
    return {};
}

void VulkanBounce::SetShares(const Hierarchy& h, const std::vector<uint32_t>& offsets,
                             const std::vector<uint32_t>& at, const std::vector<float>& factor) {
    Impl& s = *impl_;
    PENUMBRA_CHECK_EQ(h.leaves.size(), s.leaves);
    PENUMBRA_CHECK_EQ(offsets.size(), s.leaves + 1);
    PENUMBRA_CHECK_EQ(at.size(), factor.size());
    PENUMBRA_CHECK(Unfit(at.size()).empty());
    std::vector<glm::vec4> leaves(s.leaves);
    for (size_t i = 0; i < s.leaves; ++i) {
        const HierarchyNode& n = h.nodes[h.leaves[i]];
        leaves[i] = glm::vec4(n.normal, n.area);
    }
    s.leafNormalArea->Upload(leaves);
    s.offsets->Upload(offsets);
    if (!s.at || s.shareCapacity < at.size()) {
        // With room, inside the storage-buffer range (Unfit held the shares to it).
        const size_t most = s.ctx.Limits().maxStorageBufferRange / sizeof(uint32_t);
        s.shareCapacity =
            std::max<size_t>({1, std::min(at.size() + at.size() / 8, most), at.size()});
        s.at = MakeBuffer(s.ctx, s.shareCapacity * sizeof(uint32_t));
        s.factor = MakeBuffer(s.ctx, s.shareCapacity * sizeof(float));
    }
    if (!at.empty()) {
        s.at->Upload(at);
        s.factor->Upload(factor);
    }
}

std::vector<glm::vec3> VulkanBounce::Gather(const std::vector<glm::vec3>& radiance,
                                            const std::vector<glm::vec3>& environment) {
    Impl& s = *impl_;
    PENUMBRA_CHECK(s.at);  // SetShares first
    PENUMBRA_CHECK_EQ(radiance.size(), s.leaves);
    PENUMBRA_CHECK_EQ(environment.size(), s.bins);
    const auto start = std::chrono::steady_clock::now();
    std::vector<glm::vec4> up;
    up.reserve(s.leaves + s.bins);
    for (const glm::vec3& l : radiance) up.emplace_back(l, 0.0f);
    for (const glm::vec3& l : environment) up.emplace_back(l, 0.0f);
    s.radiance->Upload(up);
    const gpu::Buffer* buffers[] = {s.table.get(),    s.leafNormalArea.get(), s.leafNode.get(),
                                    s.radiance.get(), s.levels.get(),         s.offsets.get(),
                                    s.at.get(),       s.factor.get(),         s.gathered.get(),
                                    &s.dirBuffer};
    vk::raii::DescriptorSet set = s.pipeline.MakeSet(buffers);
    BouncePush push{};
    push.bins = uint32_t(s.bins);
    push.leaves = uint32_t(s.leaves);
    push.sumsAt = uint32_t(s.Table().SumsAt());
    push.environmentAt = uint32_t(s.Table().EnvironmentAt());
    s.busy.Clear();
    s.busy.Run([&](const vk::raii::CommandBuffer& cb) {
        s.pipeline.Bind(cb, set);
        auto run = [&](uint32_t mode, size_t items) {
            push.mode = mode;
            s.pipeline.Dispatch(cb, push, gpu::StridedGroups(items));
            gpu::ComputeBarrier(cb);
        };
        run(0, s.leaves * (s.bins + 1) + s.bins);
        for (const auto& [first, count] : s.levelRanges) {
            push.first = first;
            push.count = count;
            run(1, size_t(count) * (s.bins + 1));
        }
        run(2, s.leaves);
        gpu::HostReadBarrier(cb);
    });
    std::vector<glm::vec4> down(s.leaves);
    s.gathered->Download(down.data(), down.size() * sizeof(glm::vec4));
    std::vector<glm::vec3> out(s.leaves);
    for (size_t i = 0; i < s.leaves; ++i) out[i] = glm::vec3(down[i]);
    msDevice = MsSince(start);
    msBusy = s.busy.Ms();
    return out;
}

}  // namespace penumbra
