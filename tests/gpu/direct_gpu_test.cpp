// The Vulkan shadow and direct passes against their CPU twins on lavapipe, validation on:
// the same shadow maps texel for texel (but for raster tie rules on triangle edges) and the
// same direct irradiance per receiver; and the lavapipe solver with lights against the CPU
// solver.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "direct/direct_light.h"
#include "direct/vulkan_direct.h"
#include "gpu/buffer.h"
#include "gpu/context.h"
#include "scene/surfels.h"
#include "solver/solver.h"
#include "solvers/antiradiance/antiradiance_solver.h"
#include "test_util.h"

namespace penumbra {
namespace {

// A floor, a wall, a slab and a box; a point light, a narrow and a wide spot, a sun.
Scene LitScene() {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
    b.AddTiledQuad("floor", grey, {-2, 0, -2}, {4, 0, 0}, {0, 0, 4}, 8, 8, {0, 1, 0});
    b.AddQuad("wall", grey, {2, 0, -2}, {2, 0, 2}, {2, 2, 2}, {2, 2, -2}, {0, 1, 0}, 4);
    b.AddBox("slab", grey, {0, 0.6f, 0}, {0.5f, 0.05f, 0.5f});
    b.AddBox("box", grey, {-1, 0.25f, 0.8f}, {0.5f, 0.5f, 0.5f}, 30.0f, false);
    b.AddLight(
        testing::MakeLight("lamp", LightType::kPoint, {0.2f, 1.4f, 0.1f}, {0, -1, 0}, 20.0f));
    b.AddLight(testing::MakeLight("narrow", LightType::kSpot, {1.5f, 1.8f, -1}, {-0.5f, -1, 0.3f},
                                  30.0f, 0.5f));
    b.AddLight(testing::MakeLight("wide", LightType::kSpot, {-1, 1.5f, -1}, {0.2f, -1, 0.1f}, 30.0f,
                                  1.3f));
    b.AddLight(
        testing::MakeLight("sun", LightType::kDirectional, {0, 4, 0}, {0.3f, -1, 0.2f}, 500.0f));
    return b.Build();
}

TEST(VulkanDirect, ShadowAndDirectPassesMatchTheirCpuTwins) {
    Scene scene = LitScene();
    Surfels surfels = RefineScene(scene, 0.1f);
    std::vector<uint32_t> order(surfels.size());
    for (uint32_t i = 0; i < order.size(); ++i) order[i] = i;
    auto receivers = direct::MakeReceivers(surfels, order);
    const int size = 256;

    direct::Plan plan = direct::PlanShadows(scene, size);
    ASSERT_EQ(plan.views.size(), 6u + 1u + 6u + 1u);
    std::vector<float> cpuMaps;
    direct::RasterShadowMaps(plan, direct::SceneTriangles(scene), cpuMaps);
    std::vector<float> cpuE(receivers.size() * 4);
    direct::DirectIrradiance(plan, cpuMaps.data(), receivers, cpuE.data());

    gpu::Context ctx(gpu::DeviceKind::kLavapipe, /*validation=*/true);
    gpu::Buffer out(ctx, receivers.size() * 16);
    direct::VulkanDirect gpuDirect(ctx, scene, receivers, out, size);
    std::vector<float> gpuMaps = gpuDirect.ReadMaps();
    std::vector<float> gpuE = gpuDirect.Irradiance();

    // Maps: texels covered on one side only sit on triangle edges (tie rules differ).
    ASSERT_GE(gpuMaps.size(), cpuMaps.size());
    size_t covered = 0, differ = 0;
    for (size_t i = 0; i < cpuMaps.size(); ++i) {
        if (cpuMaps[i] < 1.0f) ++covered;
        if (std::abs(gpuMaps[i] - cpuMaps[i]) > 1e-5f) ++differ;
    }
    std::printf("maps: %zu texels covered, %zu differ (%.3f%%)\n", covered, differ,
                100.0 * differ / covered);
    EXPECT_GT(covered, cpuMaps.size() / 4);
    EXPECT_LT(differ, covered / 200);

    // Direct light: equal where no tap lands on a differing texel.
    float peak = 0.0f;
    for (float v : cpuE) peak = std::max(peak, v);
    size_t close = 0, lit = 0;
    float worst = 0.0f;
    for (size_t i = 0; i < cpuE.size(); ++i) {
        float e = std::abs(gpuE[i] - cpuE[i]);
        worst = std::max(worst, e);
        if (cpuE[i] > 0.0f) ++lit;
        if (e <= 1e-4f * peak + 1e-4f * std::abs(cpuE[i])) ++close;
    }
    std::printf("direct: %zu of %zu values within 1e-4, worst difference %.4f of peak %.2f\n",
                close, cpuE.size(), worst, peak);
    EXPECT_GT(lit, cpuE.size() / 8);
    EXPECT_GE(close, cpuE.size() * 995 / 1000);
    EXPECT_LE(worst, 0.07f * peak);  // at most one tap of sixteen flips at a shadow edge

    for (const auto& m : ctx.ValidationMessages()) ADD_FAILURE() << "validation: " << m;
}

// The solver with lights on lavapipe (shadow and direct passes on the device) converges to
// what the CPU back end gives.
TEST(VulkanDirect, LavapipeSolverWithLightsMatchesTheCpuSolver) {
    Scene scene = LitScene();
    SolverSettings s;
    s.solver = "antiradiance";
    SetOption(s.options, "bins", 64);
    s.elementSize = 0.15f;
    s.validation = true;
    s.shadowMapSize = 256;
    s.device = DeviceChoice::kCpu;
    auto cpu = CreateSolver(scene, s);
    s.device = DeviceChoice::kLavapipe;
    auto gpu = CreateSolver(scene, s);
    cpu->Iterate(4);
    gpu->Iterate(4);
    for (Channel c : {Channel::kDirect, Channel::kIndirect, Channel::kTotal}) {
        double rel = testing::RelativeRms(gpu->SurfelIrradiance(c), cpu->SurfelIrradiance(c));
        std::printf("%s: relative RMS difference CPU vs lavapipe %.2e\n", ChannelName(c), rel);
        EXPECT_LT(rel, 2e-3) << ChannelName(c);
    }
    // Moving a light runs the device passes again.
    scene.lights[0].position += glm::vec3(0.5f, 0, 0);
    cpu->UpdateLights(scene);
    gpu->UpdateLights(scene);
    EXPECT_LT(testing::RelativeRms(gpu->SurfelIrradiance(Channel::kDirect),
                                   cpu->SurfelIrradiance(Channel::kDirect)),
              2e-3);
    EXPECT_GT(gpu->Stats().lighting.msShadow, 0.0);
    for (const auto& m : dynamic_cast<AntiradianceSolver&>(*gpu).ValidationMessages())
        ADD_FAILURE() << "validation: " << m;
}

}  // namespace
}  // namespace penumbra

namespace penumbra {
namespace {

// The environment on lavapipe: the root's L_in starts from the sky (global.comp binding 7)
// and open surfaces send light arriving at their backs on through their fronts
// (local.comp, kLeafTwoSided). The solver must match the CPU one, before and after the sky
// is turned and dimmed.
TEST(VulkanDirect, LavapipeSolverWithASkyMatchesTheCpuSolver) {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", glm::vec3(0.6f));
    const glm::vec3 inside(0.5f, 0.5f, 0.5f);
    b.AddQuad("floor", grey, {0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}, inside, 4);
    b.AddQuad("w0", grey, {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, inside, 4);
    b.AddQuad("w1", grey, {0, 0, 0}, {0, 0, 1}, {0, 1, 1}, {0, 1, 0}, inside, 4);
    b.AddBox("box", grey, {0.6f, 0.2f, 0.6f}, {0.3f, 0.4f, 0.3f});
    Scene scene = b.Build();
    Environment sky;
    sky.image = std::make_shared<Image>(64, 32);
    for (int y = 0; y < 32; ++y)
        for (int x = 0; x < 64; ++x)  // a bright band low in the sky, a dim zenith
            const_cast<Image&>(*sky.image).At(x, y) =
                glm::vec3(y < 12 ? 0.3f : 2.0f, 1.0f, 0.5f + x / 64.0f);
    scene.environment = sky;
    SolverSettings s;
    s.solver = "antiradiance";
    SetOption(s.options, "bins", 64);
    s.elementSize = 0.1f;
    s.validation = true;
    s.device = DeviceChoice::kCpu;
    auto cpu = CreateSolver(scene, s);
    s.device = DeviceChoice::kLavapipe;
    auto gpu = CreateSolver(scene, s);
    auto compare = [&](const char* when) {
        cpu->Iterate(3);
        gpu->Iterate(3);
        std::vector<glm::vec3> x = cpu->SurfelIrradiance(), y = gpu->SurfelIrradiance();
        double rel = testing::RelativeRms(y, x);
        std::printf("sky, %s: relative RMS difference CPU vs lavapipe %.2e\n", when, rel);
        EXPECT_LT(rel, 2e-3) << when;  // NaN (no light at all) fails too
    };
    compare("as loaded");
    scene.environment.rotation = 1.0f;
    scene.environment.intensity = 0.5f;
    cpu->UpdateLights(scene);
    gpu->UpdateLights(scene);
    compare("turned and dimmed");
    for (const auto& m : dynamic_cast<AntiradianceSolver&>(*gpu).ValidationMessages())
        ADD_FAILURE() << "validation: " << m;
}

}  // namespace
}  // namespace penumbra
