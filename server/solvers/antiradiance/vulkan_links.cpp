// The link update of moves on the device (vulkan_links.h, shaders/links.comp).
#include "solvers/antiradiance/vulkan_links.h"

#include <algorithm>

#include "base/check.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/layout.h"
#include "gpu/pipeline.h"
#include "gpu/timestamps.h"
#include "shaders/links_spv.h"
#include "solvers/antiradiance/vulkan_detail.h"

namespace penumbra {
namespace {

using namespace vulkan_detail;

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
PENUMBRA_GPU_FIELD(LinkNode, center, 0);
PENUMBRA_GPU_FIELD(LinkNode, discRadius, 12);
PENUMBRA_GPU_FIELD(LinkNode, normal, 16);
PENUMBRA_GPU_FIELD(LinkNode, area, 28);
PENUMBRA_GPU_FIELD(LinkNode, surfel, 32);
PENUMBRA_GPU_FIELD(LinkNode, flags, 36);
PENUMBRA_GPU_FIELD(LinkNode, normIn, 40);
PENUMBRA_GPU_FIELD(LinkNode, normOut, 44);
constexpr uint32_t kNodeLeaf = 1, kNodeOriented = 2, kNodeGroupShift = 2;

struct LinkPush {
    uint32_t first;
    uint32_t count;
    uint32_t cubeRes;
    uint32_t adjacentWidth;
    float binSolidAngle;
    float sigma0;
};
// shaders/links.comp (push constants).
PENUMBRA_GPU_WORDS(LinkPush, 6);

// Invocations a dispatch of the link update covers (its workgroup count stays far below
// the 65,535 every device allows).
constexpr uint32_t kLinkChunk = 1u << 20;

}  // namespace

// The dynamic links, nodes and surfels at their current places, moved groups, the bin
// lookup's tables and the near field.
struct VulkanLinkUpdate::State {
    gpu::Buffer dynamic, nodes, moved, cube, adjacent, surfels, nearOffsets, nearTriangles,
        triangles;
    gpu::Pipeline pipeline;
    vk::raii::DescriptorSet set{nullptr};
    gpu::Timestamps stamps;
    uint32_t adjacentWidth = 0;
    double ms = 0.0;  // device time of the last update
};

VulkanLinkUpdate::VulkanLinkUpdate(gpu::Context& ctx, const AntiradianceModel& model,
                                   gpu::Buffer& links, gpu::Buffer& dirs, gpu::Buffer& spreadLevels,
                                   gpu::Buffer& neighbours)
    : ctx_(ctx), m(model) {
    const Surfels& sf = m.surfels;
    uint32_t width = 0;
    std::vector<uint32_t> adjacency = m.dirs.PaddedAdjacency(width);
    const auto size = [](const auto& v) { return std::max<size_t>(1, v.size()) * sizeof(v[0]); };
    s_.reset(new State{
        gpu::Buffer(ctx, m.links.dynamic.size() * sizeof(glm::uvec2)),
        gpu::Buffer(ctx, m.Nodes() * sizeof(LinkNode)),
        gpu::Buffer(ctx, (m.motion.size() + 1) * sizeof(uint32_t)),
        gpu::Buffer(ctx, m.dirs.CubeTable().size() * sizeof(uint32_t)),
        gpu::Buffer(ctx, adjacency.size() * sizeof(uint32_t)),
        gpu::Buffer(ctx, sf.size() * 2 * sizeof(glm::vec4)),
        gpu::Buffer(ctx, size(m.near.offsets)),
        gpu::Buffer(ctx, size(m.near.triangles)),
        gpu::Buffer(ctx, size(sf.refinedTriangles)),
        gpu::Pipeline(ctx, gpu::Words(kSpirv_links), 13, Spec(m.Bins()), sizeof(LinkPush)),
        {nullptr},
        gpu::Timestamps(ctx, 2),
    });
    State& u = *s_;
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
}

VulkanLinkUpdate::~VulkanLinkUpdate() = default;

double VulkanLinkUpdate::Ms() const { return s_->ms; }

// The nodes and surfels where the model has them now, and which groups moved.
void VulkanLinkUpdate::UploadPlaces(const std::vector<uint8_t>& moved) {
    State& u = *s_;
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

void VulkanLinkUpdate::Update(const std::vector<uint8_t>& moved) {
    State& u = *s_;
    UploadPlaces(moved);
    const uint32_t total = static_cast<uint32_t>(m.links.dynamic.size());
    ctx_.RunNow([&](const vk::raii::CommandBuffer& cb) {
        u.stamps.Reset(cb);
        u.stamps.Write(cb, 0);
        u.pipeline.Bind(cb, u.set);
        for (uint32_t first = 0; first < total; first += kLinkChunk) {
            LinkPush pc{first,
                        std::min(kLinkChunk, total - first),
                        static_cast<uint32_t>(m.dirs.CubeRes()),
                        u.adjacentWidth,
                        m.dirs.BinSolidAngle(),
                        m.dirs.LevelSigma(0)};
            u.pipeline.Dispatch(cb, pc, Groups(pc.count));
        }
        u.stamps.Write(cb, 1);
    });
    if (u.stamps) u.ms = u.stamps.Milliseconds()[0];
}

}  // namespace penumbra
