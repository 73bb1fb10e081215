// The light field's walk on a Vulkan device (vulkan_walk.h).
#include "solvers/lightfield/vulkan_walk.h"

#include <algorithm>
#include <chrono>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/dispatch.h"
#include "gpu/layout.h"
#include "gpu/pipeline.h"
#include "shaders/lf_flush_spv.h"
#include "shaders/lf_walk_spv.h"

namespace penumbra {
namespace {

struct WalkPush {
    uint32_t firstLine, lineCount, directions, surfels, firstDirection, group, glossy;
};
// shaders/lf_walk.comp (push constants).
PENUMBRA_GPU_WORDS(WalkPush, 7);
struct FlushPush {
    uint32_t surfels, directions, firstDirection, group;
    float cellArea, ratioCells;
    uint32_t glossy;
};
// shaders/lf_flush.comp (push constants).
PENUMBRA_GPU_WORDS(FlushPush, 7);

}  // namespace

struct VulkanWalk::Impl {
    gpu::Context& ctx;
    size_t surfels, sumBytes;
    gpu::Pipeline walk, flush;
    gpu::Buffer corners;
    std::unique_ptr<gpu::Buffer> facetOffsets, facets;
    // Per kept batch: its lines on the device (hits, lineHits, lineDirection, directions).
    struct Lines {
        std::unique_ptr<gpu::Buffer> hits, lineHits, lineDirection, directions;
        bool current = false;
    };
    std::vector<Lines> batches;
    // Per walk: radiance, sky, sums, weighted, slots, exitant, incoming.
    std::unique_ptr<gpu::Buffer> radiance, sky, sums, weighted, slots, exitant, incoming;
    size_t group = 0;

    Impl(gpu::Context& c, const RayScene& rays, size_t n, size_t budget)
        : ctx(c),
          surfels(n),
          sumBytes(budget),
          walk(c, gpu::Words(kSpirv_lf_walk), 9, std::span<const uint32_t>{}, sizeof(WalkPush)),
          flush(c, gpu::Words(kSpirv_lf_flush), 7, std::span<const uint32_t>{}, sizeof(FlushPush)),
          corners(c, std::max<size_t>(1, rays.Triangles().size()) * sizeof(glm::uvec4)) {
        std::vector<glm::uvec4> cs(rays.Triangles().size());
        for (uint32_t t = 0; t < cs.size(); ++t) cs[t] = glm::uvec4(rays.Corners(t), 0u);
        corners.Upload(cs);
        radiance = MakeBuffer(c, n * sizeof(glm::vec4));
        weighted = MakeBuffer(c, n * sizeof(glm::vec4));
        slots = MakeBuffer(c, n * sizeof(int32_t));
    }

    void Upload(Lines& l, const LineBatch& b) {
        std::vector<glm::uvec2> hits(b.hits.size());
        for (size_t i = 0; i < hits.size(); ++i)
            hits[i] =
                glm::uvec2(b.hits[i].triangle, uint32_t(b.hits[i].u) | uint32_t(b.hits[i].v) << 16);
        std::vector<uint32_t> dirOf(b.Lines());
        for (size_t k = 0; k + 1 < b.directionLines.size(); ++k)
            std::fill(dirOf.begin() + b.directionLines[k], dirOf.begin() + b.directionLines[k + 1],
                      uint32_t(k));
        std::vector<glm::vec4> dirs;
        for (const glm::vec3& d : b.directions) dirs.emplace_back(d, 0.0f);
        l.hits = MakeBuffer(ctx, hits.size() * sizeof(glm::uvec2));
        l.lineHits = MakeBuffer(ctx, b.lineHits.size() * sizeof(uint32_t));
        l.lineDirection = MakeBuffer(ctx, dirOf.size() * sizeof(uint32_t));
        l.directions = MakeBuffer(ctx, dirs.size() * sizeof(glm::vec4));
        l.hits->Upload(hits);
        l.lineHits->Upload(b.lineHits);
        l.lineDirection->Upload(dirOf);
        l.directions->Upload(dirs);
        l.current = true;
    }
};

VulkanWalk::VulkanWalk(gpu::Context& ctx, const RayScene& rays, size_t surfels, size_t sumBytes) {
    if (!ctx.FloatAtomics())
        throw Error("Vulkan device " + ctx.DeviceName() +
                    " has no float atomics in storage buffers (VK_EXT_shader_atomic_float), "
                    "which the light field's walk needs; use --device cpu");
    impl_ = std::make_unique<Impl>(ctx, rays, surfels, sumBytes);
}

VulkanWalk::~VulkanWalk() = default;

void VulkanWalk::SetFacets(const SurfelFacets& f) {
    Impl& s = *impl_;
    std::vector<glm::vec4> facets;
    for (const glm::vec3& v : f.facets) facets.emplace_back(v, 0.0f);
    s.facetOffsets = MakeBuffer(s.ctx, f.offsets.size() * sizeof(uint32_t));
    s.facets = MakeBuffer(s.ctx, facets.size() * sizeof(glm::vec4));
    s.facetOffsets->Upload(f.offsets);
    s.facets->Upload(facets);
}

void VulkanWalk::Invalidate(size_t index) {
    if (index < impl_->batches.size()) impl_->batches[index].current = false;
}

void VulkanWalk::Walk(size_t index, const LineBatch& b, float cellArea,
                      const std::vector<glm::vec3>& radiance, const Environment* sky,
                      std::vector<glm::vec3>& weighted, std::vector<float>& sampled,
                      const GlossyLines* glossy) {
    Impl& s = *impl_;
    PENUMBRA_CHECK(s.facets);
    PENUMBRA_CHECK_EQ(radiance.size(), s.surfels);
    const auto start = std::chrono::steady_clock::now();
    const size_t d = b.directions.size(), columns = 2 * d;
    if (s.batches.size() <= index) s.batches.resize(index + 1);
    Impl::Lines& lines = s.batches[index];
    if (!lines.current) s.Upload(lines, b);

    // The sums of as many directions at once as fit the budget.
    const size_t group = std::clamp<size_t>(s.sumBytes / (2 * s.surfels * 16), 1, d);
    if (!s.sums || s.group < group) {
        s.sums = MakeBuffer(s.ctx, 2 * group * s.surfels * 16);  // zero-filled; flush re-zeros
        s.group = group;
    }
    std::vector<glm::vec4> up(s.surfels);
    for (size_t i = 0; i < s.surfels; ++i) up[i] = glm::vec4(radiance[i], 0.0f);
    s.radiance->Upload(up);
    std::vector<glm::vec4> skyUp(columns, glm::vec4(0.0f));
    if (sky)
        for (size_t k = 0; k < d; ++k) {
            skyUp[k] = glm::vec4(sky->Radiance(-b.directions[k]), 0.0f);  // travel along +d
            skyUp[d + k] = glm::vec4(sky->Radiance(b.directions[k]), 0.0f);
        }
    if (!s.sky || s.sky->Bytes() < columns * sizeof(glm::vec4))
        s.sky = MakeBuffer(s.ctx, columns * sizeof(glm::vec4));
    s.sky->Upload(skyUp);
    const bool gloss = glossy && glossy->slots > 0;
    const size_t glossyTexels = gloss ? glossy->slots * columns : 1;
    if (!s.exitant || s.exitant->Bytes() < glossyTexels * sizeof(glm::vec4)) {
        s.exitant = MakeBuffer(s.ctx, glossyTexels * sizeof(glm::vec4));
        s.incoming = MakeBuffer(s.ctx, glossyTexels * sizeof(glm::vec4));
    }
    if (gloss) {
        s.slots->Upload(*glossy->slot);
        std::vector<glm::vec4> ex(glossyTexels);
        for (size_t i = 0; i < glossyTexels; ++i) ex[i] = glm::vec4(glossy->exitant[i], 0.0f);
        s.exitant->Upload(ex);
    }
    const gpu::Buffer* walkBuffers[] = {
        lines.hits.get(), lines.lineHits.get(), lines.lineDirection.get(),
        &s.corners,       s.radiance.get(),     s.sky.get(),
        s.sums.get(),     s.slots.get(),        s.exitant.get()};
    const gpu::Buffer* flushBuffers[] = {
        s.sums.get(),     s.facetOffsets.get(), s.facets.get(),  lines.directions.get(),
        s.weighted.get(), s.slots.get(),        s.incoming.get()};
    vk::raii::DescriptorSet walkSet = s.walk.MakeSet(walkBuffers);
    vk::raii::DescriptorSet flushSet = s.flush.MakeSet(flushBuffers);
    s.ctx.RunNow([&](const vk::raii::CommandBuffer& cb) {
        cb.fillBuffer(s.weighted->Handle(), 0, VK_WHOLE_SIZE, 0);
        cb.fillBuffer(s.incoming->Handle(), 0, VK_WHOLE_SIZE, 0);
        gpu::Barrier(cb, vk::PipelineStageFlagBits::eTransfer, vk::AccessFlagBits::eTransferWrite,
                     vk::PipelineStageFlagBits::eComputeShader);
        for (size_t first = 0; first < d; first += group) {
            const size_t n = std::min(group, d - first);
            const uint32_t line0 = b.directionLines[first], line1 = b.directionLines[first + n];
            s.walk.Bind(cb, walkSet);
            const WalkPush wp{line0,           line1 - line0, uint32_t(d),    uint32_t(s.surfels),
                              uint32_t(first), uint32_t(n),   gloss ? 1u : 0u};
            if (line1 > line0) s.walk.Dispatch(cb, wp, gpu::Groups(line1 - line0));
            gpu::ComputeBarrier(cb);
            s.flush.Bind(cb, flushSet);
            const FlushPush fp{uint32_t(s.surfels), uint32_t(d), uint32_t(first),
                               uint32_t(n),         cellArea,    kRatioCells,
                               gloss ? 1u : 0u};
            s.flush.Dispatch(cb, fp, gpu::Groups(s.surfels));
            gpu::ComputeBarrier(cb);
        }
        gpu::HostReadBarrier(cb);
    });
    s.weighted->Download(up.data(), up.size() * sizeof(glm::vec4));
    for (size_t i = 0; i < s.surfels; ++i) weighted[i] += glm::vec3(up[i]), sampled[i] += up[i].w;
    if (gloss) {
        std::vector<glm::vec4> in(glossyTexels);
        s.incoming->Download(in.data(), in.size() * sizeof(glm::vec4));
        for (size_t i = 0; i < glossyTexels; ++i) glossy->incoming[i] = glm::vec3(in[i]);
    }
    msDevice += MsSince(start);
}

}  // namespace penumbra
