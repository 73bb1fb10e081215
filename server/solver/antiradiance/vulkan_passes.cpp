// Upload of the model, descriptor sets for both ping-pong parities, and recording of the
// global → push → local → pull sequence with a barrier between dependent dispatches.
#include "solver/antiradiance/vulkan_passes.h"

#include <algorithm>
#include <numeric>

#include "base/check.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/pipeline.h"
#include "shaders/global_spv.h"
#include "shaders/links_spv.h"
#include "shaders/local_spv.h"
#include "shaders/pull_spv.h"
#include "shaders/push_spv.h"
#include "solver/antiradiance/cpu_passes.h"

namespace penumbra {
namespace {

constexpr uint32_t kWorkgroup = 64;
constexpr uint32_t kTimestamps = 5;  // start, after global, push, local, pull

uint32_t Groups(uint64_t invocations) {
    return static_cast<uint32_t>((invocations + kWorkgroup - 1) / kWorkgroup);
}

template <typename T>
std::span<const uint32_t> Words(const T& array) {
    return {array, sizeof(array) / sizeof(uint32_t)};
}

struct LocalPush {
    uint32_t count;
    uint32_t mode;
    float binSolidAngle;
};
struct RangePush {
    uint32_t first;
    uint32_t count;
};

// A hierarchy node as the link update reads it. Layout shared with shaders/links.comp
// (struct LinkNode).
struct LinkNode {
    glm::vec3 center;
    float discRadius;
    glm::vec3 normal;
    float area;
    uint32_t surfel;
    uint32_t flags;  // kNodeLeaf | kNodeOriented | motion group << kNodeGroupShift
    float normIn;    // LeafNorms (non-zero exactly for oriented nodes)
    float normOut;
};
static_assert(sizeof(LinkNode) == 48);
constexpr uint32_t kNodeLeaf = 1, kNodeOriented = 2, kNodeGroupShift = 2;

struct LinkPush {
    uint32_t first;
    uint32_t count;
    uint32_t cubeRes;
    uint32_t adjacentWidth;
    float binSolidAngle;
    float sigma0;
};

// Invocations a dispatch of the link update covers (its workgroup count stays far below
// the 65,535 every device allows).
constexpr uint32_t kLinkChunk = 1u << 20;

// Push and pull: a table written as rows, the same table read through texel fetches, and
// two index tables.
const std::vector<gpu::Slot> kRowSlots = {gpu::Slot::kStorage, gpu::Slot::kTexelFloat,
                                          gpu::Slot::kStorage, gpu::Slot::kStorage};

}  // namespace

struct VulkanAntiradiance::Impl {
    const AntiradianceModel& m;
    gpu::Context ctx;
    // Model data (read only).
    gpu::Buffer linkOffsets, links, spreadLevels, neighbours, receivers, leaves, dirs, parents,
        children, nodesByDepth, environment;
    // Tables.
    gpu::Buffer iex0, iex1, lin, irradiance, direct;
    // Glossy data (model.h), remade when it grows: GlossyLeaf, mirror bins, GlossyLobe,
    // lobe weights, reflected direct light.
    std::unique_ptr<gpu::Buffer> glossy, mirror, lobes, lobeWeights, glossyDirect;
    gpu::Pipeline global, push, local, pull;
    // The link update of moves (Sec. 3.3), made when the model has motion links: the
    // dynamic links, nodes and surfels at their current places, moved groups, the bin
    // lookup's tables and the near field.
    struct LinkUpdate {
        gpu::Buffer dynamic, nodes, moved, cube, adjacent, surfels, nearOffsets, nearTriangles,
            triangles;
        gpu::Pipeline pipeline;
        vk::raii::DescriptorSet set{nullptr};
        vk::raii::QueryPool queries{nullptr};
        uint32_t adjacentWidth = 0;
        double ms = 0.0;  // device time of the last update
    };
    std::unique_ptr<LinkUpdate> linkUpdate;
    vk::raii::DescriptorSet globalSet[2]{nullptr, nullptr}, localSet[2]{nullptr, nullptr},
        pullSet[2]{nullptr, nullptr}, pushSet{nullptr};
    vk::raii::QueryPool queries{nullptr};
    // Depth ranges into nodesByDepth (push uses all nodes, pull only clusters).
    std::vector<RangePush> pushLevels, pullLevels;
    int cur = 0;
    double msPass[4] = {0, 0, 0, 0};

    Impl(const AntiradianceModel& model, bool lavapipe, bool validation)
        : m(model),
          ctx(lavapipe ? gpu::DeviceKind::kLavapipe : gpu::DeviceKind::kRealGpu, validation),
          linkOffsets(ctx, m.links.offsets.size() * 4),
          links(ctx, m.links.links.size() * sizeof(Link)),
          spreadLevels(ctx, Directions::kLevels * 8),
          neighbours(ctx, m.dirs.PaddedWeights().size() * sizeof(BinWeight)),
          receivers(ctx, m.Nodes() * 4),
          leaves(ctx, m.leaves.size() * sizeof(LeafAttributes)),
          dirs(ctx, m.Bins() * 16),
          parents(ctx, m.Nodes() * 4),
          children(ctx, m.Nodes() * 8),
          nodesByDepth(ctx, m.Nodes() * 4 * 2),
          environment(ctx, m.Bins() * sizeof(glm::vec3)),
          iex0(ctx, m.TableFloats() * 4),
          iex1(ctx, m.TableFloats() * 4),
          lin(ctx, m.TableFloats() * 4),
          irradiance(ctx, m.leaves.size() * 12),
          direct(ctx, m.leaves.size() * sizeof(glm::vec4)),
          global(ctx, Words(kSpirv_global),
                 {gpu::Slot::kStorage, gpu::Slot::kTexelUint, gpu::Slot::kTexelUint,
                  gpu::Slot::kTexelUint, gpu::Slot::kTexelFloat, gpu::Slot::kStorage,
                  gpu::Slot::kStorage, gpu::Slot::kStorage},
                 Spec(), sizeof(uint32_t)),
          push(ctx, Words(kSpirv_push), kRowSlots, Spec(), sizeof(RangePush)),
          local(ctx, Words(kSpirv_local),
                {gpu::Slot::kStorage, gpu::Slot::kTexelFloat, gpu::Slot::kTexelFloat,
                 gpu::Slot::kTexelFloat, gpu::Slot::kStorage, gpu::Slot::kStorage,
                 gpu::Slot::kTexelFloat, gpu::Slot::kStorage, gpu::Slot::kTexelUint,
                 gpu::Slot::kStorage, gpu::Slot::kTexelUint, gpu::Slot::kTexelFloat},
                Spec(), sizeof(LocalPush)),
          pull(ctx, Words(kSpirv_pull), 3, Spec(), sizeof(RangePush)) {
        Upload();
        const gpu::Buffer* g0[] = {&linkOffsets, &links, &spreadLevels, &neighbours,
                                   &iex0,        &lin,   &receivers,    &environment};
        const gpu::Buffer* g1[] = {&linkOffsets, &links, &spreadLevels, &neighbours,
                                   &iex1,        &lin,   &receivers,    &environment};
        globalSet[0] = global.MakeSet(g0);
        globalSet[1] = global.MakeSet(g1);
        UploadGlossy();
        const gpu::Buffer* p0[] = {&iex0, &children, &nodesByDepth};
        const gpu::Buffer* p1[] = {&iex1, &children, &nodesByDepth};
        pullSet[0] = pull.MakeSet(p0);
        pullSet[1] = pull.MakeSet(p1);
        const gpu::Buffer* ps[] = {&lin, &lin, &parents, &nodesByDepth};
        pushSet = push.MakeSet(ps);
        if (ctx.TimestampPeriodNs() > 0.0f)
            queries = vk::raii::QueryPool(
                ctx.Device(), vk::QueryPoolCreateInfo({}, vk::QueryType::eTimestamp, kTimestamps));
        if (!m.links.dynamic.empty()) MakeLinkUpdate();
    }

    void MakeLinkUpdate() {
        const Surfels& sf = m.surfels;
        uint32_t width = 0;
        std::vector<uint32_t> adjacency = m.dirs.PaddedAdjacency(width);
        const auto size = [](const auto& v) {
            return std::max<size_t>(1, v.size()) * sizeof(v[0]);
        };
        linkUpdate.reset(new LinkUpdate{
            gpu::Buffer(ctx, m.links.dynamic.size() * sizeof(glm::uvec2)),
            gpu::Buffer(ctx, m.Nodes() * sizeof(LinkNode)),
            gpu::Buffer(ctx, (m.motion.size() + 1) * sizeof(uint32_t)),
            gpu::Buffer(ctx, m.dirs.CubeTable().size() * sizeof(uint32_t)),
            gpu::Buffer(ctx, adjacency.size() * sizeof(uint32_t)),
            gpu::Buffer(ctx, sf.size() * 2 * sizeof(glm::vec4)),
            gpu::Buffer(ctx, size(m.near.offsets)),
            gpu::Buffer(ctx, size(m.near.triangles)),
            gpu::Buffer(ctx, size(sf.refinedTriangles)),
            gpu::Pipeline(ctx, Words(kSpirv_links), 13, Spec(), sizeof(LinkPush)),
        });
        LinkUpdate& u = *linkUpdate;
        u.adjacentWidth = width;
        std::vector<glm::uvec2> pairs(m.links.dynamic.size());
        for (size_t k = 0; k < pairs.size(); ++k)
            pairs[k] = {m.links.dynamic[k], m.links.dynamicReceivers[k]};
        u.dynamic.Upload(pairs);
        u.cube.Upload(m.dirs.CubeTable());
        u.adjacent.Upload(adjacency);
        u.nearOffsets.Upload(m.near.offsets);
        u.nearTriangles.Upload(m.near.triangles);
        u.triangles.Upload(sf.refinedTriangles);
        UploadPlaces(std::vector<uint8_t>(m.motion.size() + 1, 0));
        const gpu::Buffer* set[] = {&links,      &u.dynamic, &u.nodes,       &u.moved,
                                    &dirs,       &u.cube,    &u.adjacent,    &spreadLevels,
                                    &neighbours, &u.surfels, &u.nearOffsets, &u.nearTriangles,
                                    &u.triangles};
        u.set = u.pipeline.MakeSet(set);
        if (ctx.TimestampPeriodNs() > 0.0f)
            u.queries = vk::raii::QueryPool(
                ctx.Device(), vk::QueryPoolCreateInfo({}, vk::QueryType::eTimestamp, 2));
    }

    // The nodes and surfels where the model has them now, and which groups moved.
    void UploadPlaces(const std::vector<uint8_t>& moved) {
        LinkUpdate& u = *linkUpdate;
        const auto& nodes = m.hierarchy.nodes;
        std::vector<LinkNode> ln(nodes.size());
        for (size_t i = 0; i < nodes.size(); ++i) {
            const HierarchyNode& n = nodes[i];
            // Mixed clusters are never linked; their group is clipped to fit the flags.
            const uint32_t group = n.group == kMixedGroup ? 0u : n.group;
            ln[i] = {n.center,
                     n.discRadius,
                     n.normal,
                     n.area,
                     n.IsLeaf() ? n.surfel : 0u,
                     (n.IsLeaf() ? kNodeLeaf : 0u) | (m.norms.in[i] != 0.0f ? kNodeOriented : 0u) |
                         group << kNodeGroupShift,
                     m.norms.in[i],
                     m.norms.out[i]};
        }
        u.nodes.Upload(ln);
        const Surfels& sf = m.surfels;
        std::vector<glm::vec4> pn(sf.size() * 2);
        for (size_t i = 0; i < sf.size(); ++i) {
            pn[2 * i] = glm::vec4(sf.positions[i], 1.0f);
            pn[2 * i + 1] = glm::vec4(sf.normals[i], 0.0f);
        }
        u.surfels.Upload(pn);
        u.moved.Upload(std::vector<uint32_t>(moved.begin(), moved.end()));
    }

    void UpdateLinks(const std::vector<uint8_t>& moved) {
        PENUMBRA_CHECK(linkUpdate != nullptr);
        LinkUpdate& u = *linkUpdate;
        UploadPlaces(moved);
        const uint32_t total = static_cast<uint32_t>(m.links.dynamic.size());
        ctx.RunNow([&](const vk::raii::CommandBuffer& cb) {
            if (*u.queries) {
                cb.resetQueryPool(*u.queries, 0, 2);
                cb.writeTimestamp(vk::PipelineStageFlagBits::eComputeShader, *u.queries, 0);
            }
            cb.bindPipeline(vk::PipelineBindPoint::eCompute, u.pipeline.Handle());
            cb.bindDescriptorSets(vk::PipelineBindPoint::eCompute, u.pipeline.Layout(), 0, {*u.set},
                                  {});
            for (uint32_t first = 0; first < total; first += kLinkChunk) {
                LinkPush pc{first,
                            std::min(kLinkChunk, total - first),
                            static_cast<uint32_t>(m.dirs.CubeRes()),
                            u.adjacentWidth,
                            m.dirs.BinSolidAngle(),
                            m.dirs.LevelSigma(0)};
                cb.pushConstants<LinkPush>(u.pipeline.Layout(), vk::ShaderStageFlagBits::eCompute,
                                           0, pc);
                cb.dispatch(Groups(pc.count), 1, 1);
            }
            if (*u.queries)
                cb.writeTimestamp(vk::PipelineStageFlagBits::eComputeShader, *u.queries, 1);
        });
        if (*u.queries) {
            const std::vector<uint64_t> ticks = Ticks(u.queries, 2);
            u.ms = (ticks[1] - ticks[0]) * ctx.TimestampPeriodNs() * 1e-6;
        }
    }

    // Glossy buffers sized for the model's data (at least one element each), uploaded, and
    // the local pass's sets made again when a buffer was remade.
    void UploadGlossy() {
        bool remade = false;
        auto fit = [&](std::unique_ptr<gpu::Buffer>& b, const auto& data) {
            size_t bytes = std::max<size_t>(1, data.size()) * sizeof(data[0]);
            if (!b || b->Bytes() < bytes) {
                b = std::make_unique<gpu::Buffer>(ctx, bytes);
                remade = true;
            }
            if (!data.empty()) b->Upload(data);
        };
        fit(glossy, m.glossy);
        fit(mirror, m.mirror);
        fit(lobes, m.lobes);
        fit(lobeWeights, m.lobeWeights);
        fit(glossyDirect, m.glossyDirect);
        if (!remade && *localSet[0]) return;
        // Parity p reads I_ex from table p and writes the other.
        for (int p = 0; p < 2; ++p) {
            gpu::Buffer* from = p == 0 ? &iex0 : &iex1;
            gpu::Buffer* to = p == 0 ? &iex1 : &iex0;
            const gpu::Buffer* set[] = {&leaves,
                                        &dirs,
                                        &lin,
                                        from,
                                        to,
                                        &irradiance,
                                        &direct,
                                        glossy.get(),
                                        mirror.get(),
                                        lobes.get(),
                                        lobeWeights.get(),
                                        glossyDirect.get()};
            localSet[p] = local.MakeSet(set);
        }
    }

    std::vector<uint32_t> Spec() const { return {kWorkgroup, static_cast<uint32_t>(m.Bins())}; }

    void Upload() {
        linkOffsets.Upload(m.links.offsets);
        links.Upload(m.links.links);
        std::vector<glm::uvec2> spread;
        for (int k = 0; k < Directions::kLevels; ++k)
            spread.emplace_back(m.dirs.PaddedStart(k), m.dirs.PaddedWidth(k));
        spreadLevels.Upload(spread);
        neighbours.Upload(m.dirs.PaddedWeights());
        // Receivers with the most links first: neighbouring lanes do similar work.
        std::vector<uint32_t> order(m.Nodes());
        std::iota(order.begin(), order.end(), 0u);
        const auto& lo = m.links.offsets;
        std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
            return lo[a + 1] - lo[a] > lo[b + 1] - lo[b];
        });
        receivers.Upload(order);
        leaves.Upload(m.leaves);
        direct.Upload(m.leafDirect);
        environment.Upload(m.environment);
        std::vector<glm::vec4> d;
        for (const auto& v : m.dirs.All()) d.emplace_back(v, 0.0f);
        dirs.Upload(d);
        std::vector<uint32_t> par(m.Nodes());
        std::vector<glm::uvec2> ch(m.Nodes());
        for (size_t i = 0; i < m.Nodes(); ++i) {
            par[i] = m.hierarchy.nodes[i].parent == kNoParent ? 0 : m.hierarchy.nodes[i].parent;
            ch[i] = glm::uvec2(m.leftChild[i] == kNoParent ? 0 : m.leftChild[i],
                               m.rightChild[i] == kNoParent ? 0 : m.rightChild[i]);
        }
        parents.Upload(par);
        children.Upload(ch);
        // Push: every node below the root, depth by depth. Pull: clusters, deepest first.
        std::vector<uint32_t> flat;
        const auto& byDepth = m.hierarchy.byDepth;
        for (size_t d = 1; d < byDepth.size(); ++d) {
            pushLevels.push_back(
                {static_cast<uint32_t>(flat.size()), static_cast<uint32_t>(byDepth[d].size())});
            flat.insert(flat.end(), byDepth[d].begin(), byDepth[d].end());
        }
        for (size_t d = byDepth.size(); d-- > 0;) {
            RangePush range{static_cast<uint32_t>(flat.size()), 0};
            for (uint32_t n : byDepth[d])
                if (!m.hierarchy.nodes[n].IsLeaf()) flat.push_back(n), range.count++;
            if (range.count) pullLevels.push_back(range);
        }
        nodesByDepth.Upload(flat);
        // Initial exitant intensity: the emitters' (CPU twin computes it once).
        std::vector<float> init(m.TableFloats());
        cpu::InitEmission(m, init.data());
        iex0.Upload(init);
        iex1.Upload(init);
    }

    void Stamp(const vk::raii::CommandBuffer& cb, uint32_t i) {
        if (*queries) cb.writeTimestamp(vk::PipelineStageFlagBits::eComputeShader, *queries, i);
    }

    void RecordGlobal(const vk::raii::CommandBuffer& cb) {
        cb.bindPipeline(vk::PipelineBindPoint::eCompute, global.Handle());
        cb.bindDescriptorSets(vk::PipelineBindPoint::eCompute, global.Layout(), 0,
                              {*globalSet[cur]}, {});
        uint32_t count = static_cast<uint32_t>(m.Nodes());
        cb.pushConstants<uint32_t>(global.Layout(), vk::ShaderStageFlagBits::eCompute, 0, count);
        cb.dispatch(Groups(count), 1, 1);
    }
    void RecordPush(const vk::raii::CommandBuffer& cb) {
        cb.bindPipeline(vk::PipelineBindPoint::eCompute, push.Handle());
        cb.bindDescriptorSets(vk::PipelineBindPoint::eCompute, push.Layout(), 0, {*pushSet}, {});
        for (const auto& level : pushLevels) {
            cb.pushConstants<RangePush>(push.Layout(), vk::ShaderStageFlagBits::eCompute, 0, level);
            cb.dispatch(Groups(level.count), 1, 1);
            // Each depth reads the rows the previous depth wrote.
            gpu::ComputeBarrier(cb);
        }
    }
    void RecordLocal(const vk::raii::CommandBuffer& cb, LocalMode mode) {
        cb.bindPipeline(vk::PipelineBindPoint::eCompute, local.Handle());
        cb.bindDescriptorSets(vk::PipelineBindPoint::eCompute, local.Layout(), 0, {*localSet[cur]},
                              {});
        LocalPush pc{static_cast<uint32_t>(m.leaves.size()), mode, m.dirs.BinSolidAngle()};
        cb.pushConstants<LocalPush>(local.Layout(), vk::ShaderStageFlagBits::eCompute, 0, pc);
        cb.dispatch(Groups(pc.count), 1, 1);
    }
    // Pulls into the table the local pass just wrote (`target` parity).
    void RecordPull(const vk::raii::CommandBuffer& cb, int target) {
        cb.bindPipeline(vk::PipelineBindPoint::eCompute, pull.Handle());
        cb.bindDescriptorSets(vk::PipelineBindPoint::eCompute, pull.Layout(), 0, {*pullSet[target]},
                              {});
        for (const auto& level : pullLevels) {
            cb.pushConstants<RangePush>(pull.Layout(), vk::ShaderStageFlagBits::eCompute, 0, level);
            cb.dispatch(Groups(level.count), 1, 1);
            // The next (shallower) depth sums the rows this one wrote.
            gpu::ComputeBarrier(cb);
        }
    }

    void Iterate(LocalMode mode) {
        vk::raii::CommandBuffer cb = ctx.AllocateCommandBuffer();
        cb.begin({vk::CommandBufferUsageFlagBits::eOneTimeSubmit});
        if (*queries) cb.resetQueryPool(*queries, 0, kTimestamps);
        Stamp(cb, 0);
        RecordGlobal(cb);
        // L_in written by the global pass is read and updated by push.
        gpu::ComputeBarrier(cb);
        Stamp(cb, 1);
        RecordPush(cb);
        Stamp(cb, 2);
        RecordLocal(cb, mode);
        // The local pass's I_ex rows are summed by pull.
        gpu::ComputeBarrier(cb);
        Stamp(cb, 3);
        RecordPull(cb, 1 - cur);
        Stamp(cb, 4);
        cb.end();
        ctx.SubmitAndWait(cb);
        ReadTimestamps();
        cur = 1 - cur;
    }

    // The first `count` timestamps of `pool`, waiting for them.
    static std::vector<uint64_t> Ticks(const vk::raii::QueryPool& pool, uint32_t count) {
        auto [result, ticks] = pool.getResults<uint64_t>(
            0, count, count * sizeof(uint64_t), sizeof(uint64_t),
            vk::QueryResultFlagBits::e64 | vk::QueryResultFlagBits::eWait);
        if (result != vk::Result::eSuccess) gpu::ThrowVulkan("vkGetQueryPoolResults", result);
        return ticks;
    }

    void ReadTimestamps() {
        if (!*queries) return;
        const std::vector<uint64_t> ticks = Ticks(queries, kTimestamps);
        double ns = ctx.TimestampPeriodNs();
        for (int p = 0; p < 4; ++p) msPass[p] += (ticks[p + 1] - ticks[p]) * ns * 1e-6;
    }
};

VulkanAntiradiance::VulkanAntiradiance(const AntiradianceModel& model, bool lavapipe,
                                       bool validation) {
    try {
        impl_ = std::make_unique<Impl>(model, lavapipe, validation);
    } catch (const vk::SystemError& e) {
        throw Error(std::string("Vulkan back end set-up failed: ") + e.what());
    }
}

VulkanAntiradiance::~VulkanAntiradiance() = default;

void VulkanAntiradiance::Iterate(LocalMode mode) { impl_->Iterate(mode); }

std::vector<float> VulkanAntiradiance::ReadLeafIrradiance() {
    return impl_->irradiance.Download<float>();
}

void VulkanAntiradiance::UploadLeaves() { impl_->leaves.Upload(impl_->m.leaves); }

void VulkanAntiradiance::UpdateLinks(const std::vector<uint8_t>& moved) {
    impl_->UpdateLinks(moved);
}

double VulkanAntiradiance::LinkUpdateMs() const {
    return impl_->linkUpdate ? impl_->linkUpdate->ms : 0.0;
}

std::vector<Link> VulkanAntiradiance::ReadLinks() const { return impl_->links.Download<Link>(); }

void VulkanAntiradiance::UploadDirect() { impl_->direct.Upload(impl_->m.leafDirect); }

void VulkanAntiradiance::UploadGlossy() { impl_->UploadGlossy(); }

void VulkanAntiradiance::UploadGlossyDirect() {
    impl_->glossyDirect->Upload(impl_->m.glossyDirect);
}

void VulkanAntiradiance::UploadEnvironment() { impl_->environment.Upload(impl_->m.environment); }

gpu::Context& VulkanAntiradiance::Context() { return impl_->ctx; }

gpu::Buffer& VulkanAntiradiance::DirectBuffer() { return impl_->direct; }

std::string VulkanAntiradiance::DeviceName() const { return "vulkan:" + impl_->ctx.DeviceName(); }

std::vector<PassTiming> VulkanAntiradiance::PassTimings() const {
    return {{"global", impl_->msPass[0]},
            {"push", impl_->msPass[1]},
            {"local", impl_->msPass[2]},
            {"pull", impl_->msPass[3]}};
}

size_t VulkanAntiradiance::TableBytes() const {
    return impl_->iex0.Bytes() + impl_->iex1.Bytes() + impl_->lin.Bytes() +
           impl_->irradiance.Bytes();
}

std::vector<std::string> VulkanAntiradiance::ValidationMessages() const {
    return impl_->ctx.ValidationMessages();
}

void VulkanAntiradiance::RunPass(Pass pass, LocalMode mode) {
    Impl& s = *impl_;
    s.ctx.RunNow([&](const vk::raii::CommandBuffer& cb) {
        switch (pass) {
            case Pass::kGlobal:
                s.RecordGlobal(cb);
                break;
            case Pass::kPush:
                s.RecordPush(cb);
                break;
            case Pass::kLocal:
                s.RecordLocal(cb, mode);
                break;
            case Pass::kPull:
                s.RecordPull(cb, s.cur);
                break;
        }
    });
}

std::vector<float> VulkanAntiradiance::ReadIex(bool next) const {
    const Impl& s = *impl_;
    return ((s.cur == 0) != next ? s.iex0 : s.iex1).Download<float>();
}

std::vector<float> VulkanAntiradiance::ReadLin() const { return impl_->lin.Download<float>(); }

void VulkanAntiradiance::WriteIex(const std::vector<float>& iex, bool next) {
    Impl& s = *impl_;
    ((s.cur == 0) != next ? s.iex0 : s.iex1).Upload(iex);
}

void VulkanAntiradiance::WriteLin(const std::vector<float>& lin) { impl_->lin.Upload(lin); }

}  // namespace penumbra
