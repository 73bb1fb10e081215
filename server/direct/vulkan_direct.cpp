// Vulkan shadow pass (depth-only raster into an image, copied into the maps buffer view by
// view) and direct pass (compute), timed with timestamps.
#include "direct/vulkan_direct.h"

#include <tbb/parallel_for.h>

#include <chrono>
#include <cstring>

#include "base/check.h"
#include "base/numeric.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "gpu/dispatch.h"
#include "gpu/layout.h"
#include "gpu/pipeline.h"
#include "gpu/render_target.h"
#include "gpu/timestamps.h"
#include "shaders/direct_spv.h"
#include "shaders/shadow_frag_spv.h"
#include "shaders/shadow_vert_spv.h"

namespace penumbra::direct {
namespace {

struct ShadowPush {
    glm::mat4 viewProj;
    uint32_t mapOffset;
    uint32_t size;
};
// shaders/shadow.vert (push constants).
PENUMBRA_GPU_FIELD(ShadowPush, viewProj, 0);
PENUMBRA_GPU_FIELD(ShadowPush, mapOffset, 64);
PENUMBRA_GPU_FIELD(ShadowPush, size, 68);
struct DirectPush {
    uint32_t receiverCount;
    uint32_t lightCount;
    uint32_t size;
};
// shaders/direct.comp (push constants).
PENUMBRA_GPU_WORDS(DirectPush, 3);

}  // namespace

struct VulkanDirect::Impl {
    gpu::Context& ctx;
    int size;
    std::vector<GpuReceiver> receiverList;
    std::vector<glm::vec3> triangles;  // the shadow casters, world space (SceneTriangles)
    uint32_t triangleVertices;
    gpu::Buffer& out;
    gpu::Buffer receivers;
    std::unique_ptr<gpu::Buffer> lights, views, maps, perLight;
    // Each view's triangles (ViewTriangles), view after view, as the shadow pass reads them.
    std::unique_ptr<gpu::Buffer> vertices;
    std::vector<glm::vec4> viewVertices;
    size_t viewCapacity = 0, lightCapacity = 0;
    gpu::RenderTarget shadow;  // R32: each view's nearest depth
    gpu::Pipeline directPass;
    vk::raii::DescriptorSet shadowSet{nullptr}, directSet{nullptr};
    gpu::Timestamps stamps;

    Impl(gpu::Context& c, const Scene& scene, std::vector<GpuReceiver> r, gpu::Buffer& o, int s)
        : ctx(c),
          size(s),
          receiverList(std::move(r)),
          triangles(SceneTriangles(scene)),
          triangleVertices(static_cast<uint32_t>(triangles.size())),
          out(o),
          receivers(c, std::max<size_t>(1, receiverList.size()) * sizeof(GpuReceiver)),
          shadow(c, gpu::Words(kSpirv_shadow_vert), gpu::Words(kSpirv_shadow_frag), 1,
                 sizeof(ShadowPush), static_cast<uint32_t>(s), static_cast<uint32_t>(s),
                 vk::Format::eR32Sfloat),
          directPass(c, gpu::Words(kSpirv_direct),
                     {gpu::Slot::kStorage, gpu::Slot::kStorage, gpu::Slot::kTexelFloat,
                      gpu::Slot::kTexelFloat, gpu::Slot::kStorage, gpu::Slot::kStorage},
                     std::span<const uint32_t>{}, sizeof(DirectPush)),
          stamps(c, 3) {
        receivers.Upload(receiverList);
    }

    // Buffers sized for the plan; sets made again when they grow.
    void Reserve(const Plan& plan) {
        if (plan.views.size() <= viewCapacity && plan.lights.size() <= lightCapacity && maps)
            return;
        viewCapacity = std::max(viewCapacity, plan.views.size());
        lightCapacity = std::max(lightCapacity, plan.lights.size());
        views = std::make_unique<gpu::Buffer>(ctx, viewCapacity * sizeof(GpuShadowView));
        lights = std::make_unique<gpu::Buffer>(ctx, lightCapacity * sizeof(GpuLight));
        maps = std::make_unique<gpu::Buffer>(ctx, viewCapacity * size_t(size) * size * 4);
        perLight = std::make_unique<gpu::Buffer>(
            ctx, lightCapacity * std::max<size_t>(1, receiverList.size()) * sizeof(glm::vec4));
        const gpu::Buffer* d[] = {&receivers, lights.get(), views.get(),
                                  maps.get(), &out,         perLight.get()};
        directSet = directPass.MakeSet(d);
    }

    void Update(const Scene& scene, double& msShadow, double& msDirect, int& viewCount) {
        Plan plan = PlanShadows(scene, size);
        viewCount = static_cast<int>(plan.views.size());
        if (plan.lights.empty()) return;
        Reserve(plan);
        views->Upload(plan.views);
        lights->Upload(plan.lights);
        // Each view draws only the triangles that can reach its map (ViewTriangles), from
        // its own run of vertices: lavapipe draws an index buffer slower than the vertices.
        std::vector<uint32_t> first(plan.views.size() + 1, 0);
        {
            std::vector<std::vector<uint32_t>> lists(plan.views.size());
            tbb::parallel_for(size_t(0), plan.views.size(), [&](size_t v) {
                ViewTriangles(plan.views[v].viewProj, triangles, lists[v]);
            });
            viewVertices.clear();
            for (size_t v = 0; v < lists.size(); ++v) {
                for (uint32_t i : lists[v]) viewVertices.emplace_back(triangles[i], 1.0f);
                first[v + 1] = static_cast<uint32_t>(viewVertices.size());
            }
            if (viewVertices.empty()) viewVertices.emplace_back(0.0f);
            if (!vertices || vertices->Bytes() < viewVertices.size() * sizeof(glm::vec4)) {
                vertices =
                    std::make_unique<gpu::Buffer>(ctx, viewVertices.size() * sizeof(glm::vec4));
                const gpu::Buffer* sv[] = {vertices.get()};
                shadowSet = shadow.MakeSet(sv);
            }
            vertices->Upload(viewVertices);
        }
        auto start = std::chrono::steady_clock::now();
        ctx.RunNow([&](const vk::raii::CommandBuffer& cb) {
            stamps.Reset(cb);
            stamps.Write(cb, 0, vk::PipelineStageFlagBits::eTopOfPipe);
            for (size_t v = 0; v < plan.views.size(); ++v) {
                const float far[4] = {1.0f, 1.0f, 1.0f, 1.0f};  // nothing drawn: depth 1
                shadow.Begin(cb, shadowSet, far);
                ShadowPush push{plan.views[v].viewProj,
                                static_cast<uint32_t>(v * size_t(size) * size),
                                static_cast<uint32_t>(size)};
                shadow.Push(cb, push);
                if (first[v + 1] > first[v]) cb.draw(first[v + 1] - first[v], 1, first[v], 0);
                shadow.EndAndCopy(cb, *maps, v * size_t(size) * size * sizeof(float));
            }
            gpu::Barrier(cb, vk::PipelineStageFlagBits::eTransfer,
                         vk::AccessFlagBits::eTransferWrite,
                         vk::PipelineStageFlagBits::eComputeShader);
            stamps.Write(cb, 1, vk::PipelineStageFlagBits::eTransfer);
            directPass.Bind(cb, directSet);
            directPass.Dispatch(
                cb,
                DirectPush{static_cast<uint32_t>(receiverList.size()),
                           static_cast<uint32_t>(plan.lights.size()), static_cast<uint32_t>(size)},
                gpu::Groups(receiverList.size()));
            gpu::ComputeBarrier(cb);
            stamps.Write(cb, 2);
        });
        if (stamps) {
            const std::vector<double> ms = stamps.Milliseconds();
            msShadow = ms[0];
            msDirect = ms[1];
        } else {
            msShadow = MsSince(start);
            msDirect = 0.0;
        }
    }
};

VulkanDirect::VulkanDirect(gpu::Context& ctx, const Scene& scene,
                           std::vector<GpuReceiver> receivers, gpu::Buffer& out, int mapSize) {
    if (!ctx.Graphics())
        throw Error("Vulkan device " + ctx.DeviceName() +
                    " has no graphics queue (needed by the shadow pass); use --device cpu");
    if (mapSize < 16 || mapSize > 8192) throw Error("shadow map size must be 16…8192 texels");
    impl_ = std::make_unique<Impl>(ctx, scene, std::move(receivers), out, mapSize);
    Update(scene);
}

VulkanDirect::~VulkanDirect() = default;

void VulkanDirect::Update(const Scene& scene) {
    impl_->Update(scene, msShadow, msDirect, views);
    lights_ = scene.lights.size();
}

void VulkanDirect::Move(const Scene& scene, std::vector<GpuReceiver> receivers) {
    Impl& s = *impl_;
    PENUMBRA_CHECK(receivers.size() == s.receiverList.size() &&
                   scene.TriangleCount() * 3 == s.triangleVertices);
    s.receiverList = std::move(receivers);
    s.receivers.Upload(s.receiverList);
    s.triangles = SceneTriangles(scene);
    Update(scene);
}

std::vector<float> VulkanDirect::Irradiance() const {
    std::vector<float> v(impl_->receiverList.size() * 4);
    impl_->out.Download(v.data(), v.size() * sizeof(float));
    return v;
}

std::vector<float> VulkanDirect::PerLight() const {
    std::vector<float> v(size_t(lights_) * impl_->receiverList.size() * 4);
    if (!v.empty()) impl_->perLight->Download(v.data(), v.size() * sizeof(float));
    return v;
}

std::vector<float> VulkanDirect::ReadMaps() const {
    std::vector<float> v;
    if (!impl_->maps) return v;
    v.resize(impl_->maps->Bytes() / 4);
    impl_->maps->Download(v.data(), v.size() * sizeof(float));
    return v;
}

}  // namespace penumbra::direct
