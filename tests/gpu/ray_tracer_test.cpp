// Issue 19's hardware ray tracing (gpu/ray_tracer.h) and the final gather traced with it: the
// hits are Embree's (rays/ray_scene.h) and the gathered answer is the CPU one, on a device
// that can trace rays; skipped, with what each device lacks, where none can (lavapipe, and
// the CI machine). What runs everywhere: a device without it is refused with a message that
// says what it lacks, and the gather traces on Embree and says why.
#include "gpu/ray_tracer.h"

#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "base/check.h"
#include "base/pcg.h"
#include "gather/gather_stage.h"
#include "gpu/context.h"
#include "rays/ray_scene.h"
#include "scene/gltf_loader.h"
#include "solvers/antiradiance/settings.h"
#include "test_util.h"

namespace penumbra {
namespace {

Scene Load(const std::string& name) {
    return LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/" + name);
}

// The tracer on a GPU that can trace rays, or null with why not in `why`.
std::unique_ptr<gpu::RayTracer> GpuTracer(std::string* why) {
    try {
        return std::make_unique<gpu::RayTracer>(gpu::DeviceKind::kAnyPreferGpu, true);
    } catch (const Error& e) {
        *why = e.what();
        return nullptr;
    }
}

TEST(RayTracing, LavapipeSaysWhatItLacks) {
    try {
        gpu::RayTracer tracer(gpu::DeviceKind::kLavapipe, true);
        GTEST_SKIP() << "this lavapipe (" << tracer.DeviceName()
                     << ") traces rays: the refusal cannot be shown here";
    } catch (const Error& e) {
        const std::string what = e.what();
        if (what.find("no CPU Vulkan device") != std::string::npos)
            GTEST_SKIP() << "no lavapipe here: " << what;
        EXPECT_NE(what.find("no Vulkan device can trace rays"), std::string::npos) << what;
        EXPECT_NE(what.find("llvmpipe"), std::string::npos) << what;
        EXPECT_NE(what.find("lacks"), std::string::npos) << what;
    }
}

// 200,000 rays from points inside the office in uniform directions: the GPU's nearest hit is
// Embree's triangle for all but a few grazing rays, at the same distance.
TEST(RayTracing, HitsMatchEmbree) {
    std::string why;
    auto tracer = GpuTracer(&why);
    if (!tracer) GTEST_SKIP() << "no device traces rays here: " << why;
    const Scene scene = Load("office.gltf");
    const RayScene embree(scene);
    tracer->Build(embree.Vertices());
    const glm::vec3 lo = scene.BoundsMin(), hi = scene.BoundsMax();
    Pcg32 rng(7, 0);
    std::vector<gpu::TraceRay> rays(200000);
    for (gpu::TraceRay& r : rays) {
        r.origin = lo + (hi - lo) * glm::vec3(rng.Uniform(), rng.Uniform(), rng.Uniform());
        const float z = 2.0f * rng.Uniform() - 1.0f, phi = 6.2831853f * rng.Uniform();
        const float s = std::sqrt(std::max(0.0f, 1.0f - z * z));
        r.dir = glm::vec3(s * std::cos(phi), s * std::sin(phi), z);
    }
    const std::vector<gpu::TraceHit> hits = tracer->Trace(rays);
    ASSERT_EQ(hits.size(), rays.size());
    size_t same = 0, missedBoth = 0, far = 0;
    for (size_t k = 0; k < rays.size(); ++k) {
        const RayHit h = embree.Intersect(rays[k].origin, rays[k].dir, 3.0e38f);
        if (!h.hit) {
            missedBoth += hits[k].triangle == gpu::TraceHit::kMissed;
            continue;
        }
        if (hits[k].triangle == h.triangle) {
            ++same;
            if (std::abs(hits[k].t - h.t) > 1e-4f * std::max(1.0f, h.t) ||
                std::abs(hits[k].u - h.u) > 1e-3f || std::abs(hits[k].v - h.v) > 1e-3f)
                ++far;
        }
    }
    const size_t agree = same + missedBoth;
    std::printf(
        "%s: %zu of %zu rays agree with Embree (%zu misses), %zu at another t or (u, v); "
        "build %.1f ms, trace %.1f ms\n",
        tracer->DeviceName().c_str(), agree, rays.size(), missedBoth, far, tracer->BuildMs(),
        tracer->TraceMs());
    EXPECT_GE(agree, rays.size() - rays.size() / 1000) << "more than 0.1% of the rays differ";
    EXPECT_LE(far, rays.size() / 1000);
    // The office gather's load (2.9M rays): what tracing costs at that size, transfers in.
    std::vector<gpu::TraceRay> many;
    for (int k = 0; k < 15; ++k) many.insert(many.end(), rays.begin(), rays.end());
    const std::vector<gpu::TraceHit> again = tracer->Trace(many);
    EXPECT_EQ(again[many.size() - 1].triangle, hits.back().triangle);
    std::printf("%zu rays traced in %.1f ms\n", many.size(), tracer->TraceMs());
    const auto messages = tracer->ValidationMessages();
    EXPECT_TRUE(messages.empty()) << messages.front();
}

SolverSettings On(DeviceChoice device) {
    SolverSettings s;
    s.solver = "antiradiance";
    s.device = device;
    s.elementSize = 0.1f;
    s.validation = device != DeviceChoice::kCpu;
    return s;
}

// The Cornell box gathered with its rays traced on the GPU and on Embree: the same answer
// (the same rays; a grazing ray may meet a neighbouring triangle), and the stats say where.
TEST(FinalGather, GpuTracingMatchesEmbree) {
    std::string why;
    if (!GpuTracer(&why)) GTEST_SKIP() << "no device traces rays here: " << why;
    const Scene scene = Load("cornell-box.gltf");
    // The solver on the CPU both times: only the gather's tracing differs.
    GatherSettings onGpu;
    onGpu.device = DeviceChoice::kGpu;
    onGpu.validation = true;
    GatherStage gpu(CreateSolver(scene, On(DeviceChoice::kCpu)), scene, onGpu);
    GatherStage cpu(CreateSolver(scene, On(DeviceChoice::kCpu)), scene, GatherSettings{});
    IterateUntilConverged(gpu, 1e-3, 200);
    IterateUntilConverged(cpu, 1e-3, 200);
    const std::string device = gpu.Stats().gather.device;
    EXPECT_NE(device.find("ray tracing pipeline"), std::string::npos) << device;
    EXPECT_EQ(cpu.Stats().gather.device, "cpu (Embree)");
    const double rms = testing::RelativeRms(gpu.SurfelIrradiance(Channel::kIndirect),
                                            cpu.SurfelIrradiance(Channel::kIndirect));
    std::printf(
        "Cornell box gathered on %s vs Embree: %.4f%% relative RMS; traced in %.1f vs "
        "%.1f ms\n",
        device.c_str(), 100 * rms, gpu.Stats().gather.msTrace, cpu.Stats().gather.msTrace);
    EXPECT_LT(rms, 1e-3);
}

// Where the device has no ray tracing the gather traces on Embree, and the stats say why.
TEST(FinalGather, OnLavapipeTheGatherSaysWhyItTracesOnTheCpu) {
    const Scene scene = Load("cornell-box.gltf");
    GatherSettings g;
    g.device = DeviceChoice::kLavapipe;
    g.gatherRays = 16;
    g.emitterRays = 16;
    GatherStage stage(CreateSolver(scene, On(DeviceChoice::kCpu)), scene, g);
    const std::string device = stage.Stats().gather.device;
    if (device.find("ray tracing pipeline") != std::string::npos)
        GTEST_SKIP() << "this lavapipe traces rays: " << device;
    if (device.find("no CPU Vulkan device") != std::string::npos)
        GTEST_SKIP() << "no lavapipe here: " << device;
    EXPECT_EQ(device.rfind("cpu (Embree); no GPU ray tracing: ", 0), 0u) << device;
    EXPECT_NE(device.find("llvmpipe"), std::string::npos) << device;
}

}  // namespace
}  // namespace penumbra
