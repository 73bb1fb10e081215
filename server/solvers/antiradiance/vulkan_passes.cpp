// Upload of the model, descriptor sets for both ping-pong parities, and recording of the
// global (clusters, depth by depth, push folded in) → local (leaves: gather + local pass) →
// pull sequence with a barrier between dependent dispatches.
#include "solvers/antiradiance/vulkan_passes.h"

#include <algorithm>
#include <numeric>

#include "base/check.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/layout.h"
#include "gpu/pipeline.h"
#include "gpu/timestamps.h"
#include "shaders/global_spv.h"
#include "shaders/local_spv.h"
#include "shaders/pull_spv.h"
#include "solvers/antiradiance/cpu_passes.h"
#include "solvers/antiradiance/vulkan_detail.h"
#include "solvers/antiradiance/vulkan_links.h"

namespace penumbra {
namespace {

using namespace vulkan_detail;

constexpr uint32_t kTimestamps = 4;  // start, after global, local, pull

struct LocalPush {
    uint32_t first;
    uint32_t count;
    float binSolidAngle;
    uint32_t envRow;
};
// shaders/local.comp (push constants).
PENUMBRA_GPU_WORDS(LocalPush, 4);
struct RangePush {
    uint32_t first;
    uint32_t count;
};
// shaders/global.comp, pull.comp (push constants).
PENUMBRA_GPU_WORDS(RangePush, 2);

// Receivers are dispatched window by window in node order (depth first, so a window is a
// patch of nearby surfaces), and by link count within a window, so the lanes of a workgroup
// finish together. Nearby receivers read much the same senders' I_ex rows, which stay in
// the cache while a window is gathered: on lavapipe windows of 2,048 nodes took a quarter
// off an iteration against a sort by link count alone, and other widths were within noise
// of it (bench/results/FINDINGS.md, "Constants in the code").
constexpr uint32_t kLocalityWindow = 2048;

// Whether receiver node a goes before node b (see kLocalityWindow).
bool DispatchedBefore(const std::vector<uint32_t>& linkOffsets, uint32_t a, uint32_t b) {
    if (a / kLocalityWindow != b / kLocalityWindow) return a < b;
    return linkOffsets[a + 1] - linkOffsets[a] > linkOffsets[b + 1] - linkOffsets[b];
}

// Bindings 0–5 of both passes that gather (shaders/gather.glsl), then each pass's own.
std::vector<gpu::Slot> GatherSlots(std::vector<gpu::Slot> own) {
    std::vector<gpu::Slot> slots = {gpu::Slot::kStorage,    gpu::Slot::kTexelUint,
                                    gpu::Slot::kTexelUint,  gpu::Slot::kTexelUint,
                                    gpu::Slot::kTexelFloat, gpu::Slot::kTexelFloat};
    for (gpu::Slot slot : own) slots.push_back(slot);
    return slots;
}

}  // namespace

struct VulkanAntiradiance::Impl {
    const AntiradianceModel& m;
    gpu::Context ctx;
    // Model data (read only).
    gpu::Buffer linkOffsets, links, spreadLevels, neighbours, clusterOrder, leafOrder, leaves, dirs,
        children, nodesByDepth;
    // Tables. L_in has one row per node plus the environment row (row Nodes()).
    gpu::Buffer iex0, iex1, lin, irradiance, direct;
    // Glossy data (model.h), remade when it grows: GlossyLeaf, mirror bins, GlossyLobe,
    // lobe weights, reflected direct light.
    std::unique_ptr<gpu::Buffer> glossy, mirror, lobes, lobeWeights, glossyDirect;
    gpu::Pipeline global, local, pull;
    std::unique_ptr<VulkanLinkUpdate> linkUpdate;  // with motion links (Sec. 3.3)
    vk::raii::DescriptorSet globalSet[2]{nullptr, nullptr}, localSet[2]{nullptr, nullptr},
        pullSet[2]{nullptr, nullptr};
    gpu::Timestamps stamps{ctx, kTimestamps};
    // Depth ranges into clusterOrder (root first) and into nodesByDepth (pull: deepest first).
    std::vector<RangePush> globalLevels, pullLevels;
    int cur = 0;
    uint32_t glossyLeaves = 0;        // the first entries of leafOrder
    std::vector<bool> orderedGlossy;  // the glossy flags leafOrder was made for
    double msPass[3] = {0, 0, 0};

    Impl(const AntiradianceModel& model, bool lavapipe, bool validation)
        : m(model),
          ctx(lavapipe ? gpu::DeviceKind::kLavapipe : gpu::DeviceKind::kRealGpu, validation),
          linkOffsets(ctx, m.links.offsets.size() * 4),
          links(ctx, m.links.links.size() * sizeof(Link)),
          spreadLevels(ctx, Directions::kLevels * 8),
          neighbours(ctx, m.dirs.PaddedWeights().size() * sizeof(BinWeight)),
          clusterOrder(ctx, m.Nodes() * sizeof(glm::uvec2)),
          leafOrder(ctx, m.leaves.size() * 4),
          leaves(ctx, m.leaves.size() * sizeof(LeafAttributes)),
          dirs(ctx, m.Bins() * 16),
          children(ctx, m.Nodes() * 8),
          nodesByDepth(ctx, m.Nodes() * 4),
          iex0(ctx, m.TableFloats() * 4),
          iex1(ctx, m.TableFloats() * 4),
          lin(ctx, (m.TableFloats() + m.Bins() * 3) * 4),
          irradiance(ctx, m.leaves.size() * 12),
          direct(ctx, m.leaves.size() * sizeof(glm::vec4)),
          global(ctx, gpu::Words(kSpirv_global),
                 GatherSlots({gpu::Slot::kStorage, gpu::Slot::kStorage}), Spec(),
                 sizeof(RangePush)),
          local(ctx, gpu::Words(kSpirv_local),
                GatherSlots({gpu::Slot::kStorage, gpu::Slot::kTexelFloat, gpu::Slot::kStorage,
                             gpu::Slot::kStorage, gpu::Slot::kTexelFloat, gpu::Slot::kStorage,
                             gpu::Slot::kTexelUint, gpu::Slot::kStorage, gpu::Slot::kTexelUint,
                             gpu::Slot::kTexelFloat, gpu::Slot::kStorage}),
                LocalVariants(), sizeof(LocalPush)),
          pull(ctx, gpu::Words(kSpirv_pull), 3, Spec(), sizeof(RangePush)) {
        Upload();
        const gpu::Buffer* g0[] = {&linkOffsets, &links, &spreadLevels, &neighbours,
                                   &iex0,        &lin,   &lin,          &clusterOrder};
        const gpu::Buffer* g1[] = {&linkOffsets, &links, &spreadLevels, &neighbours,
                                   &iex1,        &lin,   &lin,          &clusterOrder};
        globalSet[0] = global.MakeSet(g0);
        globalSet[1] = global.MakeSet(g1);
        UploadGlossy();
        const gpu::Buffer* p0[] = {&iex0, &children, &nodesByDepth};
        const gpu::Buffer* p1[] = {&iex1, &children, &nodesByDepth};
        pullSet[0] = pull.MakeSet(p0);
        pullSet[1] = pull.MakeSet(p1);
        if (!m.links.dynamic.empty())
            linkUpdate =
                std::make_unique<VulkanLinkUpdate>(ctx, m, links, dirs, spreadLevels, neighbours);
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
        OrderLeaves();
        if (!remade && *localSet[0]) return;
        // Parity p reads I_ex from table p and writes the other.
        for (int p = 0; p < 2; ++p) {
            gpu::Buffer* from = p == 0 ? &iex0 : &iex1;
            gpu::Buffer* to = p == 0 ? &iex1 : &iex0;
            const gpu::Buffer* set[] = {
                &linkOffsets, &links,      &spreadLevels,     &neighbours,
                from,         &lin,        &leaves,           &dirs,
                to,           &irradiance, &direct,           glossy.get(),
                mirror.get(), lobes.get(), lobeWeights.get(), glossyDirect.get(),
                &leafOrder};
            localSet[p] = local.MakeSet(set);
        }
    }

    std::vector<uint32_t> Spec() const { return vulkan_detail::Spec(m.Bins()); }
    // The local pass's variants, LocalVariant(mode, glossy) → its specialization. The
    // symmetric scheme's diffuse variant comes first: the pipeline compiles it at set-up
    // (lavapipe takes tens of milliseconds a variant), the others on first use.
    static size_t LocalVariant(LocalMode mode, bool glossy) {
        return (mode == kBoth ? 0 : static_cast<size_t>(mode)) * 2 + (glossy ? 1 : 0);
    }
    std::vector<std::vector<uint32_t>> LocalVariants() const {
        std::vector<std::vector<uint32_t>> v;
        for (LocalMode mode : {kBoth, kReflect, kAntiradiance})
            for (uint32_t glossy : {0u, 1u}) {
                PENUMBRA_CHECK_EQ(LocalVariant(mode, glossy != 0), v.size());
                v.push_back({kWorkgroup, static_cast<uint32_t>(m.Bins()),
                             static_cast<uint32_t>(mode), glossy});
            }
        return v;
    }

    // The local pass's leaves: glossy ones first (their variant), then the diffuse ones, each
    // in DispatchedBefore order. Redone whenever leaf flags may have changed.
    // Only the glossy flags change the order after set-up (material edits, moves): the
    // leaves are sorted again only when those changed.
    void OrderLeaves() {
        const auto& lo = m.links.offsets;
        const auto glossy = [&](uint32_t i) { return (m.leaves[i].flags & kLeafGlossy) != 0; };
        std::vector<bool> flags(m.leaves.size());
        for (uint32_t i = 0; i < flags.size(); ++i) flags[i] = glossy(i);
        if (flags == orderedGlossy) return;
        orderedGlossy = std::move(flags);
        std::vector<uint32_t> order(m.leaves.size());
        std::iota(order.begin(), order.end(), 0u);
        std::stable_sort(order.begin(), order.end(), [&](uint32_t a, uint32_t b) {
            if (glossy(a) != glossy(b)) return glossy(a);
            return DispatchedBefore(lo, m.leaves[a].node, m.leaves[b].node);
        });
        glossyLeaves = static_cast<uint32_t>(std::count_if(order.begin(), order.end(), glossy));
        leafOrder.Upload(order);
    }

    void Upload() {
        linkOffsets.Upload(m.links.offsets);
        links.Upload(m.links.links);
        std::vector<glm::uvec2> spread;
        for (int k = 0; k < Directions::kLevels; ++k)
            spread.emplace_back(m.dirs.PaddedStart(k), m.dirs.PaddedWidth(k));
        spreadLevels.Upload(spread);
        neighbours.Upload(m.dirs.PaddedWeights());
        leaves.Upload(m.leaves);
        direct.Upload(m.leafDirect);
        UploadEnvironment();
        std::vector<glm::vec4> d;
        for (const auto& v : m.dirs.All()) d.emplace_back(v, 0.0f);
        dirs.Upload(d);
        // Receivers in DispatchedBefore order: clusters depth by depth (each starting from its
        // parent's row, the root from the environment row), leaves all at once.
        const auto& lo = m.links.offsets;
        const auto inOrder = [&](uint32_t a, uint32_t b) { return DispatchedBefore(lo, a, b); };
        const auto& nodes = m.hierarchy.nodes;
        const auto& byDepth = m.hierarchy.byDepth;
        const uint32_t envRow = static_cast<uint32_t>(m.Nodes());
        std::vector<glm::uvec2> clusters;
        for (const auto& depth : byDepth) {
            std::vector<uint32_t> level;
            for (uint32_t n : depth)
                if (!nodes[n].IsLeaf()) level.push_back(n);
            if (level.empty()) continue;
            std::stable_sort(level.begin(), level.end(), inOrder);
            globalLevels.push_back(
                {static_cast<uint32_t>(clusters.size()), static_cast<uint32_t>(level.size())});
            for (uint32_t n : level)
                clusters.emplace_back(n, nodes[n].parent == kNoParent ? envRow : nodes[n].parent);
        }
        clusterOrder.Upload(clusters);
        OrderLeaves();
        std::vector<glm::uvec2> ch(m.Nodes());
        for (size_t i = 0; i < m.Nodes(); ++i)
            ch[i] = glm::uvec2(m.leftChild[i] == kNoParent ? 0 : m.leftChild[i],
                               m.rightChild[i] == kNoParent ? 0 : m.rightChild[i]);
        children.Upload(ch);
        // Pull: clusters, deepest first.
        std::vector<uint32_t> flat;
        for (size_t d = byDepth.size(); d-- > 0;) {
            RangePush range{static_cast<uint32_t>(flat.size()), 0};
            for (uint32_t n : byDepth[d])
                if (!nodes[n].IsLeaf()) flat.push_back(n), range.count++;
            if (range.count) pullLevels.push_back(range);
        }
        nodesByDepth.Upload(flat);
        // Initial exitant intensity: the emitters' (CPU twin computes it once).
        std::vector<float> init(m.TableFloats());
        cpu::InitEmission(m, init.data());
        iex0.Upload(init);
        iex1.Upload(init);
    }

    // The environment row of the L_in table, where the root's gather starts.
    void UploadEnvironment() {
        static_assert(sizeof(m.environment[0]) == 3 * sizeof(float));
        PENUMBRA_CHECK_EQ(m.environment.size(), static_cast<size_t>(m.Bins()));
        lin.Upload(m.environment.data(), m.environment.size() * sizeof(m.environment[0]),
                   m.TableFloats() * sizeof(float));
    }

    // Clusters depth by depth from the root down: each depth starts from the rows the
    // previous one wrote.
    void RecordGlobal(const vk::raii::CommandBuffer& cb) {
        global.Bind(cb, globalSet[cur]);
        for (const auto& level : globalLevels) {
            global.Dispatch(cb, level, Groups(level.count));
            gpu::ComputeBarrier(cb);
        }
    }
    void RecordLocal(const vk::raii::CommandBuffer& cb, LocalMode mode) {
        cb.bindDescriptorSets(vk::PipelineBindPoint::eCompute, local.Layout(), 0, {*localSet[cur]},
                              {});
        const uint32_t total = static_cast<uint32_t>(m.leaves.size());
        for (bool glossy : {true, false}) {
            LocalPush pc{glossy ? 0u : glossyLeaves, glossy ? glossyLeaves : total - glossyLeaves,
                         m.dirs.BinSolidAngle(), static_cast<uint32_t>(m.Nodes())};
            if (pc.count == 0) continue;
            local.BindVariant(cb, LocalVariant(mode, glossy));
            local.Dispatch(cb, pc, Groups(pc.count));
        }
    }
    // Pulls into the table the local pass just wrote (`target` parity).
    void RecordPull(const vk::raii::CommandBuffer& cb, int target) {
        pull.Bind(cb, pullSet[target]);
        for (const auto& level : pullLevels) {
            pull.Dispatch(cb, level, Groups(level.count));
            // The next (shallower) depth sums the rows this one wrote.
            gpu::ComputeBarrier(cb);
        }
    }

    void Iterate(LocalMode mode) {
        vk::raii::CommandBuffer cb = ctx.AllocateCommandBuffer();
        cb.begin({vk::CommandBufferUsageFlagBits::eOneTimeSubmit});
        stamps.Reset(cb);
        stamps.Write(cb, 0);
        RecordGlobal(cb);  // ends with a barrier: the leaves read their parents' rows
        stamps.Write(cb, 1);
        RecordLocal(cb, mode);
        // The local pass's I_ex rows are summed by pull.
        gpu::ComputeBarrier(cb);
        stamps.Write(cb, 2);
        RecordPull(cb, 1 - cur);
        stamps.Write(cb, 3);
        cb.end();
        ctx.SubmitAndWait(cb);
        ReadTimestamps();
        cur = 1 - cur;
    }

    void ReadTimestamps() {
        const std::vector<double> ms = stamps.Milliseconds();
        for (size_t p = 0; p < ms.size(); ++p) msPass[p] += ms[p];
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

void VulkanAntiradiance::UploadLeaves() {
    impl_->leaves.Upload(impl_->m.leaves);
    impl_->OrderLeaves();
}

void VulkanAntiradiance::UpdateLinks(const std::vector<uint8_t>& moved) {
    PENUMBRA_CHECK(impl_->linkUpdate != nullptr);
    impl_->linkUpdate->Update(moved);
}

double VulkanAntiradiance::LinkUpdateMs() const {
    return impl_->linkUpdate ? impl_->linkUpdate->Ms() : 0.0;
}

std::vector<Link> VulkanAntiradiance::ReadLinks() const { return impl_->links.Download<Link>(); }

void VulkanAntiradiance::UploadLinks() { impl_->links.Upload(impl_->m.links.links); }

void VulkanAntiradiance::SetIex(const std::vector<float>& iex) {
    WriteIex(iex, false);
    WriteIex(iex, true);
}

void VulkanAntiradiance::InputsChanged(uint32_t inputs) {
    if (inputs & kLinks) UploadLinks();
    if (inputs & kLeaves) UploadLeaves();
    if (inputs & kDirect) UploadDirect();
    if (inputs & kGlossy) {
        UploadGlossy();
    } else if (inputs & kGlossyDirect) {
        UploadGlossyDirect();
    }
    if (inputs & kEnvironment) UploadEnvironment();
}

bool VulkanAntiradiance::OnCpu() const { return impl_->ctx.IsLavapipe(); }

void VulkanAntiradiance::UploadDirect() { impl_->direct.Upload(impl_->m.leafDirect); }

void VulkanAntiradiance::UploadGlossy() { impl_->UploadGlossy(); }

void VulkanAntiradiance::UploadGlossyDirect() {
    impl_->glossyDirect->Upload(impl_->m.glossyDirect);
}

void VulkanAntiradiance::UploadEnvironment() { impl_->UploadEnvironment(); }

gpu::Context& VulkanAntiradiance::Context() { return impl_->ctx; }

gpu::Buffer& VulkanAntiradiance::DirectBuffer() { return impl_->direct; }

std::string VulkanAntiradiance::DeviceName() const { return "vulkan:" + impl_->ctx.DeviceName(); }

std::vector<PassTiming> VulkanAntiradiance::PassTimings() const {
    return {{"global", impl_->msPass[0]}, {"local", impl_->msPass[1]}, {"pull", impl_->msPass[2]}};
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

std::vector<float> VulkanAntiradiance::ReadLin() const {
    std::vector<float> lin(impl_->m.TableFloats());
    impl_->lin.Download(lin.data(), lin.size() * sizeof(float));
    return lin;
}

void VulkanAntiradiance::WriteIex(const std::vector<float>& iex, bool next) {
    Impl& s = *impl_;
    ((s.cur == 0) != next ? s.iex0 : s.iex1).Upload(iex);
}

void VulkanAntiradiance::WriteLin(const std::vector<float>& lin) { impl_->lin.Upload(lin); }

}  // namespace penumbra
