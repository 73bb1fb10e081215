// The implicit solver's compositing on a Vulkan device (vulkan_composite.h).
#include "solvers/implicit/vulkan_composite.h"

#include <algorithm>
#include <bit>
#include <chrono>
#include <cmath>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/dispatch.h"
#include "gpu/layout.h"
#include "gpu/pipeline.h"
#include "gpu/timestamps.h"
#include "hierarchy/directions_device.h"
#include "shaders/implicit_composite_spv.h"

namespace penumbra {
namespace {

// shaders/implicit_composite.comp: struct CompositeNode, Leaf.
struct CompositeNode {
    glm::vec3 center;
    float coneCos;
    glm::vec3 normal;
    uint32_t right;  // the second child; 0 for a leaf
    uint32_t solid;
    uint32_t pad[3];
};
PENUMBRA_GPU_FIELD(CompositeNode, center, 0);
PENUMBRA_GPU_FIELD(CompositeNode, coneCos, 12);
PENUMBRA_GPU_FIELD(CompositeNode, normal, 16);
PENUMBRA_GPU_FIELD(CompositeNode, right, 28);
PENUMBRA_GPU_FIELD(CompositeNode, solid, 32);
static_assert(sizeof(CompositeNode) == 48);
struct CompositeLeaf {
    glm::vec3 center;
    float norm;
    glm::vec3 normal;
    uint32_t node;
};
PENUMBRA_GPU_FIELD(CompositeLeaf, center, 0);
PENUMBRA_GPU_FIELD(CompositeLeaf, norm, 12);
PENUMBRA_GPU_FIELD(CompositeLeaf, normal, 16);
PENUMBRA_GPU_FIELD(CompositeLeaf, node, 28);
static_assert(sizeof(CompositeLeaf) == 32);
// shaders/implicit_composite.comp (push constants).
struct CompositePush {
    uint32_t mode, bins, leafCount, endCount, slots, scanFirst, scanCount, mergedAt, environmentAt,
        cubeRes, adjacentWidth, hasSolids;
    float binSolidAngle, thin, cosBinRadius, sinBinRadius, aboveHorizon;
};
PENUMBRA_GPU_WORDS(CompositePush, 17);

// The shader's limits: the deepest chain, a scan's block.
constexpr size_t kMaxDepth = 64;
constexpr uint32_t kBlock = 4096;
constexpr size_t kMostBlocks = 32768;
// A share's mark keeps a closed solid's number in its low 30 bits.
constexpr uint32_t kMostSolid = 0x3fffffffu;

}  // namespace

struct VulkanCompositing::Impl {
    gpu::Context& ctx;
    const Directions& dirs;
    float binRadius;
    gpu::Pipeline pipeline;
    DeviceDirections tables;
    gpu::Buffer opposite;
    std::unique_ptr<gpu::Buffer> status;
    // Grown as needed (each with its capacity in bytes).
    struct Grown {
        std::unique_ptr<gpu::Buffer> buffer;
        size_t bytes = 0;
    };
    // The ends and the scattered ends field by field (slot, sender, dist, omega), the shares'
    // fields (bin, sender, weight, mark): 4 bytes an entry, each list in its own buffer.
    Grown ends[4], scattered[4], shares[4];
    Grown counts, blockSums, nodes, leaves, cover, partial, boxes, travel, offsets;
    gpu::BusyTime busy;

    Impl(gpu::Context& c, const Directions& d, float r, uint32_t mostSolids)
        : ctx(c),
          dirs(d),
          binRadius(r),
          pipeline(c, gpu::Words(kSpirv_implicit_composite), 27,
                   std::span<const uint32_t>(&mostSolids, 1), sizeof(CompositePush)),
          tables(c, d),
          opposite(c, size_t(d.Count()) * sizeof(uint32_t)),
          busy(c) {
        std::vector<uint32_t> opp(size_t(d.Count()));
        for (uint32_t b = 0; b < opp.size(); ++b) opp[b] = d.Opposite(b);
        opposite.Upload(opp);
        status = MakeBuffer(c, 4 * sizeof(uint32_t));
    }

    // The hierarchy's nodes and leaves, the solids' boxes and the ends (field by field) on the
    // device, and room for what the passes write: the slots' and cells' counts (the
    // environment's cells' last, at environmentAt), the scan's block sums, the cells'
    // cover and partial marks, the leaves' first shares.
    void Upload(const Hierarchy& h, const std::vector<uint32_t>& solid,
                const std::vector<glm::vec4>& boxes, std::span<const ImplicitLinker::End> ends,
                size_t environmentAt) {
        const size_t bins = size_t(dirs.Count()), nodeCount = h.size(), leafCount = h.leaves.size();
        const size_t slots = nodeCount * bins, cells = leafCount * bins;
        std::vector<CompositeNode> nodes(nodeCount);
        for (size_t i = 0; i < nodeCount; ++i) {
            const HierarchyNode& n = h.nodes[i];
            nodes[i] = {n.center,
                        n.coneCos,
                        n.normal,
                        n.IsLeaf() ? 0u : h.nodes[i + 1].end,
                        solid.empty() ? kNoSolid : solid[i],
                        {0, 0, 0}};
        }
        std::vector<CompositeLeaf> leaves(leafCount);
        for (size_t i = 0; i < leafCount; ++i) {
            const HierarchyNode& n = h.nodes[h.leaves[i]];
            leaves[i] = {n.center, dirs.CosineNorm(n.normal), n.normal, h.leaves[i]};
        }
        Reserve(this->nodes, nodes.size() * sizeof(CompositeNode)).Upload(nodes);
        Reserve(this->leaves, leaves.size() * sizeof(CompositeLeaf)).Upload(leaves);
        Reserve(this->boxes, std::max<size_t>(1, boxes.size()) * sizeof(glm::vec4));
        if (!boxes.empty()) this->boxes.buffer->Upload(boxes);
        {
            std::vector<uint32_t> field(ends.size());
            for (int f = 0; f < 4; ++f) {
                for (size_t k = 0; k < ends.size(); ++k) {
                    const ImplicitLinker::End& e = ends[k];
                    field[k] = f == 0   ? e.slot
                               : f == 1 ? e.sender
                               : f == 2 ? std::bit_cast<uint32_t>(e.dist)
                                        : std::bit_cast<uint32_t>(e.omega);
                }
                Reserve(this->ends[f], ends.size() * sizeof(uint32_t))
                    .Upload(field.data(), field.size() * sizeof(uint32_t));
                Reserve(scattered[f], ends.size() * sizeof(uint32_t));
            }
        }
        Reserve(counts, (environmentAt + cells + 1) * sizeof(uint32_t));
        const size_t mostBlocks = (std::max(slots, cells) + kBlock - 1) / kBlock;
        Reserve(blockSums, (mostBlocks + 1) * sizeof(uint32_t));
        Reserve(cover, cells * sizeof(float));
        Reserve(partial, cells * sizeof(uint32_t));
        Reserve(offsets, (leafCount + 1) * sizeof(uint32_t));
        for (auto& field : shares) Reserve(field, sizeof(uint32_t));
        Reserve(travel, sizeof(uint32_t));
    }

    // The passes' constants (each pass sets its mode, a scan its range).
    CompositePush Push(const Hierarchy& h, const std::vector<uint32_t>& solid, float thin,
                       size_t endCount, size_t mergedAt, size_t environmentAt) const {
        const size_t bins = size_t(dirs.Count());
        CompositePush push{};
        push.bins = uint32_t(bins);
        push.leafCount = uint32_t(h.leaves.size());
        push.endCount = uint32_t(endCount);
        push.slots = uint32_t(h.size() * bins);
        push.mergedAt = uint32_t(mergedAt);
        push.environmentAt = uint32_t(environmentAt);
        push.cubeRes = uint32_t(dirs.CubeRes());
        push.adjacentWidth = tables.adjacentWidth;
        push.hasSolids = solid.empty() ? 0u : 1u;
        push.binSolidAngle = dirs.BinSolidAngle();
        push.thin = thin;
        // As SolidBox::Holds and Build's compositing compute them.
        push.cosBinRadius = std::cos(binRadius);
        push.sinBinRadius = std::sin(binRadius);
        push.aboveHorizon = std::sin(dirs.Spacing());
        return push;
    }

    // Every buffer the pipeline binds, in its bindings' order.
    std::vector<const gpu::Buffer*> Bound(const gpu::Buffer& frontArea) const {
        std::vector<const gpu::Buffer*> b;
        for (auto& f : ends) b.push_back(f.buffer.get());
        for (auto& f : scattered) b.push_back(f.buffer.get());
        for (const auto* g : {&counts, &blockSums, &nodes, &leaves, &cover, &partial, &boxes})
            b.push_back(g->buffer.get());
        for (const gpu::Buffer* t : {&tables.dirs, &tables.cube}) b.push_back(t);
        b.push_back(tables.adjacent.get());
        b.push_back(&opposite);
        for (auto& f : shares) b.push_back(f.buffer.get());
        b.push_back(travel.buffer.get());
        b.push_back(offsets.buffer.get());
        b.push_back(status.get());
        b.push_back(&frontArea);
        return b;
    }

    // The shares (`total`) and each leaf's first into `out`.
    void ReadShares(size_t total, size_t leafCount, ImplicitLinks& out) {
        out.offsets.resize(leafCount + 1);
        offsets.buffer->Download(out.offsets.data(), (leafCount + 1) * sizeof(uint32_t));
        PENUMBRA_CHECK_EQ(out.offsets[leafCount], total);
        out.bin.resize(total);
        out.sender.resize(total);
        out.weight.resize(total);
        out.travel.resize(total);
        if (total > 0) travel.buffer->Download(out.travel.data(), total * sizeof(uint32_t));
        if (total > 0) {
            shares[0].buffer->Download(out.bin.data(), total * sizeof(uint32_t));
            shares[1].buffer->Download(out.sender.data(), total * sizeof(uint32_t));
            shares[2].buffer->Download(out.weight.data(), total * sizeof(float));
        }
    }

    // Grows `g` to hold `bytes` with room, the room kept inside the device's storage-buffer
    // range (each buffer is bound whole).
    gpu::Buffer& Reserve(Grown& g, size_t bytes) {
        if (!g.buffer || g.bytes < bytes) {
            const size_t range = ctx.Limits().maxStorageBufferRange;
            g.bytes = std::max<size_t>({std::min(bytes + bytes / 4, range), bytes, 64});
            g.buffer = MakeBuffer(ctx, g.bytes);
        }
        return *g.buffer;
    }
};

VulkanCompositing::VulkanCompositing(gpu::Context& ctx, const Directions& dirs, float binRadius,
                                     uint32_t mostSolids)
    : impl_(std::make_unique<Impl>(ctx, dirs, binRadius, mostSolids)) {
    PENUMBRA_CHECK(mostSolids > 0);
}

VulkanCompositing::~VulkanCompositing() = default;

std::string VulkanCompositing::Unfit(const Hierarchy& h, size_t ends) const {
    const Impl& s = *impl_;
    if (h.byDepth.size() > kMaxDepth)
        return "the hierarchy is " + std::to_string(h.byDepth.size()) +
               " levels deep (the device's compositing holds " + std::to_string(kMaxDepth) + ")";
    const size_t range = s.ctx.Limits().maxStorageBufferRange;
    const size_t bins = size_t(s.dirs.Count());
    const size_t counts = h.size() * bins + 1 + 2 * (h.leaves.size() * bins + 1);
    if (counts >= 0xffffffffu || counts * sizeof(uint32_t) > range)
        return "the compositing's slot counts exceed the device's storage-buffer range";
    // The scan's one invocation walks the blocks' sums: kept well inside the 65,535 loop
    // iterations llvmpipe allows a shader.
    if (counts / kBlock > kMostBlocks)
        return "the compositing's slot counts exceed what its scan takes";
    if (ends >= 0xffffffffu || ends * sizeof(uint32_t) > range)  // a field of the ends
        return "the links' ends exceed the device's storage-buffer range";
    return {};
}

bool VulkanCompositing::Composite(const Hierarchy& h, const gpu::Buffer& frontArea,
                                  const std::vector<uint32_t>& solid,
                                  const std::vector<glm::vec4>& boxes, float thin,
                                  std::span<const ImplicitLinker::End> ends, ImplicitLinks& out) {
    Impl& s = *impl_;
    const auto start = std::chrono::steady_clock::now();
    PENUMBRA_CHECK(Unfit(h, ends.size()).empty());
    PENUMBRA_CHECK(solid.empty() || solid.size() == h.size());
    why_.clear();
    s.busy.Clear();
    auto fail = [&](const char* why) {
        why_ = why;
        msDevice = MsSince(start);
        msBusy = s.busy.Ms();
        return false;
    };
    for (uint32_t of : solid)
        if (of != kNoSolid && of >= kMostSolid)
            return fail("a closed solid's number exceeds what the device's shares mark");
    const size_t bins = size_t(s.dirs.Count()), nodeCount = h.size(), leafCount = h.leaves.size();
    const size_t slots = nodeCount * bins, cells = leafCount * bins;

    const size_t mergedAt = slots + 1, environmentAt = mergedAt + cells + 1;
    PENUMBRA_CHECK_LE(nodeCount * bins * sizeof(float), frontArea.Bytes());
    s.Upload(h, solid, boxes, ends, environmentAt);
    CompositePush push = s.Push(h, solid, thin, ends.size(), mergedAt, environmentAt);

    auto record = [&](const vk::raii::CommandBuffer& cb, const vk::raii::DescriptorSet& set) {
        s.pipeline.Bind(cb, set);
    };
    auto run = [&](const vk::raii::CommandBuffer& cb, uint32_t mode, uint32_t groups) {
        push.mode = mode;
        s.pipeline.Dispatch(cb, push, groups);
        gpu::ComputeBarrier(cb);
    };
    // An exclusive scan of counts[first, first + n), the total after it.
    auto scan = [&](const vk::raii::CommandBuffer& cb, size_t first, size_t n) {
        push.scanFirst = uint32_t(first);
        push.scanCount = uint32_t(n);
        const size_t blocks = (n + kBlock - 1) / kBlock;
        run(cb, 1, gpu::StridedGroups(blocks));
        run(cb, 2, 1);
        run(cb, 3, gpu::StridedGroups(blocks));
    };
    {
        const std::vector<const gpu::Buffer*> bound = s.Bound(frontArea);
        vk::raii::DescriptorSet set = s.pipeline.MakeSet(bound);
        s.busy.Run([&](const vk::raii::CommandBuffer& cb) {
            cb.fillBuffer(s.counts.buffer->Handle(), 0, VK_WHOLE_SIZE, 0);
            cb.fillBuffer(s.status->Handle(), 0, VK_WHOLE_SIZE, 0);
            gpu::Barrier(cb, vk::PipelineStageFlagBits::eTransfer,
                         vk::AccessFlagBits::eTransferWrite,
                         vk::PipelineStageFlagBits::eComputeShader);
            record(cb, set);
            run(cb, 0, gpu::StridedGroups(ends.size()));  // the slots' counts
            scan(cb, 0, slots);                           // their starts
            run(cb, 4, gpu::StridedGroups(ends.size()));  // the ends by slot
            run(cb, 5, gpu::StridedGroups(ends.size()));  // each slot nearest first
            run(cb, 6, gpu::StridedGroups(cells));        // the merges counted
            run(cb, 7, gpu::StridedGroups(cells));        // the bins showing the environment
            scan(cb, mergedAt, cells);
            scan(cb, environmentAt, cells);
            gpu::HostReadBarrier(cb);
        });
    }
    uint32_t state[4] = {0, 0, 0, 0}, merged = 0, shown = 0;
    s.status->Download(state, sizeof(state));
    if (state[1] != 0)
        return fail("a bin met more closed solids than the device's compositing holds");
    if (state[2] != 0)
        return fail("a (node, bin) slot holds more ends than the device's sort takes");
    s.counts.buffer->Download(&merged, sizeof(uint32_t), (mergedAt + cells) * sizeof(uint32_t));
    s.counts.buffer->Download(&shown, sizeof(uint32_t), (environmentAt + cells) * sizeof(uint32_t));
    const size_t total = size_t(merged) + shown;
    if (total >= 0xffffffffu || total * sizeof(uint32_t) > s.ctx.Limits().maxStorageBufferRange)
        return fail("the shares exceed the device's storage-buffer range");
    for (auto& field : s.shares) s.Reserve(field, total * sizeof(uint32_t));
    s.Reserve(s.travel, total * sizeof(uint32_t));
    {
        const std::vector<const gpu::Buffer*> bound = s.Bound(frontArea);
        vk::raii::DescriptorSet set = s.pipeline.MakeSet(bound);
        s.busy.Run([&](const vk::raii::CommandBuffer& cb) {
            record(cb, set);
            run(cb, 8, gpu::StridedGroups(cells));          // the shares written
            run(cb, 9, gpu::StridedGroups(leafCount + 1));  // the leaves' first shares
            run(cb, 10, gpu::StridedGroups(total));         // the far faces' fronts, travel
            gpu::HostReadBarrier(cb);
        });
    }
    s.status->Download(state, sizeof(state));
    if (state[3] != 0) return fail("the device's merges wrote other counts than they counted");
    s.ReadShares(total, leafCount, out);
    size_t empty = 0;
    for (uint32_t sender : out.sender) empty += sender == kNoSender;
    out.empty = empty;
    ++runs;
    msDevice = MsSince(start);
    msBusy = s.busy.Ms();
    return true;
}

}  // namespace penumbra
