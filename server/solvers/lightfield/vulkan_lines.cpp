// The light field's lines by depth peeling on a Vulkan device (vulkan_lines.h).
#include "solvers/lightfield/vulkan_lines.h"

#include <algorithm>
#include <chrono>
#include <cmath>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/layout.h"
#include "gpu/pipeline.h"
#include "gpu/render_target.h"
#include "shaders/peel_frag_spv.h"
#include "shaders/peel_vert_spv.h"

namespace penumbra {
namespace {

struct PeelPush {
    glm::mat4 view;
    uint32_t layer;
    uint32_t size;
    uint32_t previousOffset;
};
// shaders/peel.{vert,frag} (push constants).
PENUMBRA_GPU_FIELD(PeelPush, view, 0);
PENUMBRA_GPU_FIELD(PeelPush, layer, 64);
PENUMBRA_GPU_FIELD(PeelPush, size, 68);
PENUMBRA_GPU_FIELD(PeelPush, previousOffset, 72);

// The layers a direction keeps on the device at once (and the one before them) stay under
// this many bytes.
constexpr size_t kLayerBudget = size_t(512) << 20;

// World → the direction's view: x, y in NDC with cell (i, j)'s line (jittered by `jitter`)
// through pixel (i, j)'s centre, z the distance along the line over its length (0 … 1).
glm::mat4 ViewOf(const DirectionGrid& g, const glm::vec2& jitter) {
    const float n = float(g.n);
    auto row = [&](const glm::vec3& axis, float scale, float offset) {
        return glm::vec4(axis * scale, offset - scale * glm::dot(g.corner, axis));
    };
    // x_ndc = (2 (x_cell − a) + 1) / n − 1, x_cell = (p − corner) · t / side.
    const float xy = 2.0f / (n * g.side);
    const glm::vec4 rows[4] = {row(g.t, xy, (1.0f - 2.0f * jitter.x) / n - 1.0f),
                               row(g.s, xy, (1.0f - 2.0f * jitter.y) / n - 1.0f),
                               row(g.d, 1.0f / g.length, 0.0f), glm::vec4(0, 0, 0, 1)};
    glm::mat4 m(0.0f);
    for (int r = 0; r < 4; ++r)
        for (int c = 0; c < 4; ++c) m[c][r] = rows[r][c];
    return m;
}

}  // namespace

struct VulkanLines::Impl {
    gpu::Context& ctx;
    LineGrid grid;
    const RayScene& rays;
    uint32_t vertexCount;
    int chunk;  // layers peeled a submission
    size_t texels;
    gpu::Buffer vertices, layers;  // layers: chunk + 1 slots (slot 0: the layer before)
    gpu::RenderTarget target;
    vk::raii::DescriptorSet set{nullptr};

    Impl(gpu::Context& c, const RayScene& r, const LineGrid& g, int k)
        : ctx(c),
          grid(g),
          rays(r),
          vertexCount(static_cast<uint32_t>(r.Triangles().size() * 3)),
          chunk(std::clamp(int(kLayerBudget / (size_t(g.cells) * g.cells * 16)) - 1, 1, k)),
          texels(size_t(g.cells) * g.cells),
          vertices(c, std::max<size_t>(1, vertexCount) * sizeof(glm::vec4)),
          layers(c, (size_t(chunk) + 1) * texels * sizeof(glm::vec4)),
          target(c, gpu::Words(kSpirv_peel_vert), gpu::Words(kSpirv_peel_frag), 2, sizeof(PeelPush),
                 uint32_t(g.cells), uint32_t(g.cells), vk::Format::eR32G32B32A32Sfloat) {
        Upload(r);
        const gpu::Buffer* b[] = {&vertices, &layers};
        set = target.MakeSet(b);
    }

    void Upload(const RayScene& r) {
        std::vector<glm::vec4> v;
        v.reserve(vertexCount);
        for (const glm::vec3& p : r.Vertices()) v.emplace_back(p, 1.0f);
        if (v.empty()) v.emplace_back(0.0f);
        vertices.Upload(v);
    }

    // Peels direction `g`'s layers into `out` (layer after layer, texels each); returns how
    // many it holds.
    int Peel(const DirectionGrid& g, const glm::vec2& jitter, std::vector<glm::vec4>& out,
             double& ms) {
        const glm::mat4 view = ViewOf(g, jitter);
        const float clear[4] = {1.0f, 0.0f, 0.0f, 0.0f};  // nothing met: depth 1, triangle 0
        const size_t slotBytes = texels * sizeof(glm::vec4);
        out.clear();
        for (int done = 0;; done += chunk) {
            const auto start = std::chrono::steady_clock::now();
            ctx.RunNow([&](const vk::raii::CommandBuffer& cb) {
                if (done > 0) {
                    // The last layer peeled becomes the one the next is peeled behind.
                    cb.copyBuffer(layers.Handle(), layers.Handle(),
                                  vk::BufferCopy(size_t(chunk) * slotBytes, 0, slotBytes));
                    gpu::Barrier(cb, vk::PipelineStageFlagBits::eTransfer,
                                 vk::AccessFlagBits::eTransferWrite,
                                 vk::PipelineStageFlagBits::eFragmentShader);
                }
                for (int l = 0; l < chunk; ++l) {
                    target.Begin(cb, set, clear);
                    const PeelPush push{view, uint32_t(done + l), uint32_t(g.n),
                                        uint32_t(size_t(l) * texels)};
                    target.Push(cb, push);
                    cb.draw(vertexCount, 1, 0, 0);
                    target.EndAndCopy(cb, layers, size_t(l + 1) * slotBytes);
                    gpu::Barrier(cb, vk::PipelineStageFlagBits::eTransfer,
                                 vk::AccessFlagBits::eTransferWrite,
                                 vk::PipelineStageFlagBits::eFragmentShader);
                }
            });
            // Slots 1 … chunk, after the layers before.
            const size_t before = out.size();
            out.resize(before + size_t(chunk) * texels);
            layers.Download(out.data() + before, size_t(chunk) * slotBytes, slotBytes);
            ms += MsSince(start);
            // Go on while some line met a surface in the last layer (it may have more).
            const auto last = out.end() - std::ptrdiff_t(texels);
            const bool more =
                std::any_of(last, out.end(), [](const glm::vec4& t) { return t.y != 0.0f; });
            if (!more || done + chunk > int(rays.Triangles().size())) break;
        }
        return int(out.size() / texels);
    }
};

VulkanLines::VulkanLines(gpu::Context& ctx, const RayScene& rays, const LineGrid& grid,
                         int layers) {
    if (!ctx.Graphics())
        throw Error("Vulkan device " + ctx.DeviceName() +
                    " has no graphics queue (the light field's lines are rasterised); use "
                    "--device cpu");
    if (grid.jitter != LineJitter::kPerDirection)
        throw Error("the light field's Vulkan lines need one jitter a direction");
    if (uint32_t(grid.cells) > ctx.Limits().maxImageDimension2D)
        throw Error("lightfield: " + std::to_string(grid.cells) + " cells a side is more than " +
                    ctx.DeviceName() + "'s images hold (" +
                    std::to_string(ctx.Limits().maxImageDimension2D) + "); lower --cells");
    if (rays.Triangles().size() >= (size_t(1) << 24))
        throw Error("lightfield: " + std::to_string(rays.Triangles().size()) +
                    " refined triangles are more than the Vulkan lines name (2^24); use a "
                    "larger element size or --device cpu");
    if (layers < 1) throw Error("lightfield: --layers must be at least 1");
    impl_ = std::make_unique<Impl>(ctx, rays, grid, layers);
}

VulkanLines::~VulkanLines() = default;

void VulkanLines::Update(const RayScene& rays) { impl_->Upload(rays); }

LineBatch VulkanLines::TraceBatch(const std::vector<glm::vec3>& base, uint32_t seed,
                                  uint32_t batch) {
    Impl& s = *impl_;
    LineBatch b;
    b.batch = batch;
    b.directions = RotatedDirections(base, seed, batch);
    const std::vector<RayTriangle>& tris = s.rays.Triangles();
    std::vector<glm::vec4> peeled;
    b.lineHits.push_back(0);
    for (size_t k = 0; k < b.directions.size(); ++k) {
        const DirectionGrid g(s.grid, b.directions[k]);
        const glm::vec2 jitter =
            DirectionGrid::Jitter(LineJitter::kPerDirection, seed, batch, k, 0);
        const int count = s.Peel(g, jitter, peeled, msDevice);
        b.directionLines.push_back(static_cast<uint32_t>(b.lineCells.size()));
        for (uint32_t cell = 0; cell < s.texels; ++cell) {
            int l = 0;
            for (; l < count; ++l) {
                const glm::vec4& t = peeled[size_t(l) * s.texels + cell];
                if (t.y == 0.0f) break;
                LineHit h;
                h.triangle = static_cast<uint32_t>(t.y) - 1;
                PENUMBRA_CHECK_LT(h.triangle, tris.size());
                if (glm::dot(tris[h.triangle].normal, g.d) > 0.0f) h.triangle |= kFacesAlong;
                h.u = static_cast<uint16_t>(std::lround(std::clamp(t.z, 0.0f, 1.0f) * 65535.0f));
                h.v = static_cast<uint16_t>(std::lround(std::clamp(t.w, 0.0f, 1.0f) * 65535.0f));
                b.hits.push_back(h);
            }
            if (l == 0) continue;
            mostLayers_ = std::max(mostLayers_, l);
            b.lineCells.push_back(cell);
            b.lineHits.push_back(static_cast<uint32_t>(b.hits.size()));
        }
    }
    b.directionLines.push_back(static_cast<uint32_t>(b.lineCells.size()));
    return b;
}

}  // namespace penumbra
