// The implicit solver's link creation on a Vulkan device (vulkan_links.h).
#include "solvers/implicit/vulkan_links.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <numbers>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/dispatch.h"
#include "gpu/layout.h"
#include "gpu/pipeline.h"
#include "gpu/timestamps.h"
#include "hierarchy/directions_device.h"
#include "shaders/implicit_closest_spv.h"
#include "shaders/implicit_pairs_spv.h"

namespace penumbra {
namespace {

// shaders/implicit_pairs.comp: struct PairNode.
struct PairNode {
    glm::vec3 center;
    float radius;
    glm::vec3 normal;
    float coneCos;
    float area;
    uint32_t right;  // the second child; 0 for a leaf
    float slab;      // ImplicitLinker::Build's slab thickness (0 for a leaf)
    float discRadius;
};
PENUMBRA_GPU_FIELD(PairNode, center, 0);
PENUMBRA_GPU_FIELD(PairNode, radius, 12);
PENUMBRA_GPU_FIELD(PairNode, normal, 16);
PENUMBRA_GPU_FIELD(PairNode, coneCos, 28);
PENUMBRA_GPU_FIELD(PairNode, area, 32);
PENUMBRA_GPU_FIELD(PairNode, right, 36);
PENUMBRA_GPU_FIELD(PairNode, slab, 40);
PENUMBRA_GPU_FIELD(PairNode, discRadius, 44);
static_assert(sizeof(PairNode) == 48);
static_assert(sizeof(ImplicitLinker::End) == 16);
PENUMBRA_GPU_FIELD(ImplicitLinker::End, slot, 0);
PENUMBRA_GPU_FIELD(ImplicitLinker::End, sender, 4);
PENUMBRA_GPU_FIELD(ImplicitLinker::End, dist, 8);
PENUMBRA_GPU_FIELD(ImplicitLinker::End, omega, 12);

struct PairPush {
    uint32_t count, nextCapacity, endCapacity, bins, cubeRes, adjacentWidth;
    float limit, binSolidAngle, splat, adjacentAngle, binRadius;
};
// shaders/implicit_pairs.comp (push constants).
PENUMBRA_GPU_WORDS(PairPush, 11);

}  // namespace

struct VulkanLinkCreation::Impl {
    gpu::Context& ctx;
    const Directions& dirs;
    float threshold;
    size_t bufferBytes;
    bool closest;
    gpu::Pipeline pairs;  // implicit_pairs.comp, or implicit_closest.comp with `closest`
    DeviceDirections tables;
    // The nodes and their projected areas; a chunk of a round's pairs, its next pairs and
    // ends; the three counters; the closest rule's table.
    std::unique_ptr<gpu::Buffer> nodes, frontArea, round, next, ends, counts, best;
    size_t roundCapacity = 0, nextCapacity = 0, endCapacity = 0;
    gpu::BusyTime busy;

    Impl(gpu::Context& c, const Directions& d, float t, size_t bytes, bool closestRule)
        : ctx(c),
          dirs(d),
          threshold(t),
          bufferBytes(bytes > 0 ? std::min<size_t>(bytes, c.Limits().maxStorageBufferRange)
                                : c.Limits().maxStorageBufferRange),
          closest(closestRule),
          pairs(
              c,
              closestRule ? gpu::Words(kSpirv_implicit_closest) : gpu::Words(kSpirv_implicit_pairs),
              closestRule ? 10 : 9, std::span<const uint32_t>{}, sizeof(PairPush)),
          tables(c, d),
          busy(c) {
        counts = MakeBuffer(c, 4 * sizeof(uint32_t));
    }

    // The rounds from the root's self-pair; with `closest` into `best` (filled with all ones
    // first), else appending the ends to `endsOut`.
    void Rounds(const Hierarchy& h, const std::vector<float>& frontArea,
                const std::vector<float>& slab, std::vector<ImplicitLinker::End>* endsOut,
                size_t& pairs, size_t& linked, size_t& rounds);

    // Grows `buffer` (kept in `capacity` elements of `size` bytes) to hold `want`, with room.
    // (at most `limit` bytes: the device's storage-buffer range).
    void Reserve(std::unique_ptr<gpu::Buffer>& buffer, size_t& capacity, size_t want, size_t size,
                 size_t limit) {
        if (buffer && capacity >= want) return;
        capacity = std::min(std::max<size_t>(want + want / 2, 1024), limit / size);
        buffer = MakeBuffer(ctx, capacity * size);
    }
};

VulkanLinkCreation::VulkanLinkCreation(gpu::Context& ctx, const Directions& dirs,
                                       float linkThreshold, size_t bufferBytes, bool closest)
    : impl_(std::make_unique<Impl>(ctx, dirs, linkThreshold, bufferBytes, closest)) {
    if (closest) PENUMBRA_CHECK(ClosestUnsupported(ctx).empty());
}

std::string VulkanLinkCreation::ClosestUnsupported(const gpu::Context& ctx) {
    if (ctx.Int64Atomics()) return "";
    return ctx.DeviceName() +
           " has no 64-bit atomics in storage buffers (shaderInt64, "
           "shaderBufferInt64Atomics)";
}

std::string VulkanLinkCreation::ClosestUnfit(size_t nodes) const {
    const size_t bytes = nodes * size_t(impl_->dirs.Count()) * sizeof(uint64_t);
    if (bytes <= impl_->bufferBytes) return "";
    return "the closest links' table (" + std::to_string(bytes) +
           " bytes) is larger than a storage buffer may be on " + impl_->ctx.DeviceName() + " (" +
           std::to_string(impl_->bufferBytes) + " bytes)";
}

VulkanLinkCreation::~VulkanLinkCreation() = default;

const gpu::Buffer& VulkanLinkCreation::FrontArea() const {
    PENUMBRA_CHECK(impl_->frontArea != nullptr);
    return *impl_->frontArea;
}

void VulkanLinkCreation::Create(const Hierarchy& h, const std::vector<float>& frontArea,
                                const std::vector<float>& slab,
                                std::vector<ImplicitLinker::End>& ends, size_t& pairs,
                                size_t& linked) {
    PENUMBRA_CHECK(!impl_->closest);
    const auto start = std::chrono::steady_clock::now();
    impl_->busy.Clear();
    impl_->Rounds(h, frontArea, slab, &ends, pairs, linked, rounds);
    msDevice = MsSince(start);
    msBusy = impl_->busy.Ms();
}

void VulkanLinkCreation::CreateClosest(const Hierarchy& h, const std::vector<float>& frontArea,
                                       const std::vector<float>& slab, std::vector<uint64_t>& best,
                                       size_t& pairs, size_t& linked) {
    Impl& s = *impl_;
    PENUMBRA_CHECK(s.closest);
    PENUMBRA_CHECK(ClosestUnfit(h.nodes.size()).empty());
    const auto start = std::chrono::steady_clock::now();
    const size_t bytes = h.nodes.size() * size_t(s.dirs.Count()) * sizeof(uint64_t);
    if (!s.best || s.best->Bytes() < bytes) s.best = MakeBuffer(s.ctx, bytes);
    s.busy.Clear();
    s.busy.Run([&](const vk::raii::CommandBuffer& cb) {
        cb.fillBuffer(s.best->Handle(), 0, VK_WHOLE_SIZE, 0xffffffffu);  // no link yet
        gpu::Barrier(cb, vk::PipelineStageFlagBits::eTransfer, vk::AccessFlagBits::eTransferWrite,
                     vk::PipelineStageFlagBits::eComputeShader);
    });
    s.Rounds(h, frontArea, slab, nullptr, pairs, linked, rounds);
    best.resize(bytes / sizeof(uint64_t));
    s.best->Download(best.data(), bytes);
    msDevice = MsSince(start);
    msBusy = s.busy.Ms();
}

void VulkanLinkCreation::Impl::Rounds(const Hierarchy& h, const std::vector<float>& frontArea,
                                      const std::vector<float>& slab,
                                      std::vector<ImplicitLinker::End>* endsOut, size_t& pairs,
                                      size_t& linked, size_t& rounds) {
    Impl& s = *this;
    const size_t bins = size_t(s.dirs.Count());
    PENUMBRA_CHECK_EQ(frontArea.size(), h.nodes.size() * bins);
    PENUMBRA_CHECK_EQ(slab.size(), h.nodes.size());
    std::vector<PairNode> up(h.nodes.size());
    for (size_t i = 0; i < up.size(); ++i) {
        const HierarchyNode& n = h.nodes[i];
        const bool leaf = n.IsLeaf();
        up[i] = {n.center, n.radius,    n.normal, n.coneCos, n.area, leaf ? 0u : h.nodes[i + 1].end,
                 slab[i],  n.discRadius};
    }
    if (!s.nodes || s.nodes->Bytes() < up.size() * sizeof(PairNode)) {
        s.nodes = MakeBuffer(s.ctx, up.size() * sizeof(PairNode));
        s.frontArea = MakeBuffer(s.ctx, frontArea.size() * sizeof(float));
    }
    s.nodes->Upload(up);
    s.frontArea->Upload(frontArea);

    const float omegaBin = s.dirs.BinSolidAngle();
    PairPush push{};
    push.bins = uint32_t(bins);
    push.cubeRes = uint32_t(s.dirs.CubeRes());
    push.adjacentWidth = s.tables.adjacentWidth;
    push.limit = s.threshold * omegaBin;
    push.binSolidAngle = omegaBin;
    push.splat = std::sin(0.5f * s.dirs.Spacing());
    push.adjacentAngle = s.dirs.AdjacentAngle();
    push.binRadius = std::sqrt(omegaBin / std::numbers::pi_v<float>);

    // The rounds: the pairs of a round go up in chunks that fit the device's storage-buffer
    // limit with their next pairs (4 at most a pair: both ends split) and ends; a chunk whose ends
    // overflow runs again with a larger end list, or, at the limit, as two halves.
    const size_t limit = s.bufferBytes;
    const size_t endLimit = limit / sizeof(ImplicitLinker::End);
    const size_t chunkLimit = limit / (4 * sizeof(glm::uvec2));
    std::vector<glm::uvec2> round{{0u, 0u}}, next;
    pairs = 0;
    linked = 0;
    rounds = 0;
    while (!round.empty()) {
        pairs += round.size();
        next.clear();
        size_t chunk = std::min(round.size(), chunkLimit);
        for (size_t at = 0; at < round.size();) {
            const size_t n = std::min(chunk, round.size() - at);
            s.Reserve(s.round, s.roundCapacity, n, sizeof(glm::uvec2), limit);
            s.Reserve(s.next, s.nextCapacity, 4 * n, sizeof(glm::uvec2), limit);
            s.Reserve(s.ends, s.endCapacity, s.closest ? 1 : std::min(4 * n, endLimit),
                      sizeof(ImplicitLinker::End), limit);
            s.round->Upload(round.data() + at, n * sizeof(glm::uvec2));
            push.count = uint32_t(n);
            push.nextCapacity = uint32_t(s.nextCapacity);
            push.endCapacity = uint32_t(s.endCapacity);
            const gpu::Buffer* buffers[] = {s.nodes.get(),  s.round.get(),  s.next.get(),
                                            s.ends.get(),   s.counts.get(), s.frontArea.get(),
                                            &s.tables.dirs, &s.tables.cube, s.tables.adjacent.get(),
                                            s.best.get()};
            vk::raii::DescriptorSet set =
                s.pairs.MakeSet(std::span<const gpu::Buffer* const>(buffers, s.closest ? 10 : 9));
            s.busy.Run([&](const vk::raii::CommandBuffer& cb) {
                cb.fillBuffer(s.counts->Handle(), 0, VK_WHOLE_SIZE, 0);
                gpu::Barrier(cb, vk::PipelineStageFlagBits::eTransfer,
                             vk::AccessFlagBits::eTransferWrite,
                             vk::PipelineStageFlagBits::eComputeShader);
                s.pairs.Bind(cb, set);
                s.pairs.Dispatch(cb, push, gpu::Groups(n));
                gpu::HostReadBarrier(cb);
            });
            ++rounds;
            uint32_t got[3] = {0, 0, 0};  // next pairs, ends, pairs linked
            s.counts->Download(got, sizeof(got));
            PENUMBRA_CHECK_LE(got[0], s.nextCapacity);
            if (got[1] > s.endCapacity) {
                if (got[1] <= endLimit) {
                    s.Reserve(s.ends, s.endCapacity, got[1], sizeof(ImplicitLinker::End), limit);
                } else {
                    PENUMBRA_CHECK(n > 1);
                    chunk = n / 2;
                }
                continue;
            }
            linked += got[2];
            next.resize(next.size() + got[0]);
            if (got[0] > 0)
                s.next->Download(next.data() + next.size() - got[0],
                                 size_t(got[0]) * sizeof(glm::uvec2));
            PENUMBRA_CHECK(got[1] == 0 || endsOut);  // the closest rule appends no ends
            if (got[1] > 0) {
                endsOut->resize(endsOut->size() + got[1]);
                s.ends->Download(endsOut->data() + endsOut->size() - got[1],
                                 size_t(got[1]) * sizeof(ImplicitLinker::End));
            }
            at += n;
        }
        std::swap(round, next);
    }
}

}  // namespace penumbra
