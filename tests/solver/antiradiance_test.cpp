// Closed-form checks of the antiradiance solver on the CPU back end: Eq. 17's form
// factor, the white furnace (antiradiance must cancel what U lets through blockers), and
// a blocker's shadow appearing as antiradiance iterations proceed.
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <numbers>
#include <thread>

#include "bundled_scenes.h"
#include "scene/gltf_loader.h"
#include "scene/scene_builder.h"
#include "solver/solver.h"
#include "solvers/antiradiance/cpu_passes.h"
#include "solvers/antiradiance/model.h"
#include "test_util.h"

namespace penumbra {
namespace {

using testing::AddUnitRoom;
using testing::Mean;
using testing::NearestSurfel;

SolverSettings CpuSettings(int bins = 128, float elementSize = 0.05f) {
    SolverSettings s;
    s.solver = "antiradiance";
    SetOption(s.options, "bins", bins);
    s.elementSize = elementSize;
    s.device = DeviceChoice::kCpu;
    return s;
}

// A small emitting patch of area A over a black receiver plane:
// E = L · A · cosθr · cosθe / d². Tolerance 2% (the issue's); the patch is small
// (0.06 m at ≥ 1 m), so the point-source formula itself is accurate to < 0.1%.
struct FormFactorCase {
    float tiltDegrees;  // emitter normal tilted away from −y about +z
    float offsetX;      // receiver point offset from below the emitter
    int bins;
    // AntiradianceSettings::receiverOracle, here 1 (receivers held to the senders' threshold)
    // unless said. Off-axis at 256 bins that gives +9.8%: the floor cluster that takes the
    // link hands its centre's transfer to the point, which is farther from the patch
    // (docs/SOLVER.md, "Receiver size"); 0.25 holds it to 2%.
    float receiverOracle = 1.0f;
};

class FormFactor : public ::testing::TestWithParam<FormFactorCase> {};

TEST_P(FormFactor, SmallPatchMatchesPointToPointFormula) {
    const FormFactorCase c = GetParam();
    const float L = 3.0f, side = 0.06f, height = 1.0f;
    SceneBuilder b;
    uint32_t black = b.AddMaterial("black", glm::vec3(0.0f));
    uint32_t emit = b.AddMaterial("emit", glm::vec3(0.0f), glm::vec3(L));
    b.AddQuad("floor", black, {-2, 0, -2}, {2, 0, -2}, {2, 0, 2}, {-2, 0, 2}, {0, 1, 0});
    // Emitter centred at (0, h, 0), normal = −y rotated by the tilt about z.
    const glm::vec3 n = testing::AddTiltedEmitter(b, emit, c.tiltDegrees, side, height);
    const glm::vec3 o(0, height, 0);
    Scene scene = b.Build();
    SolverSettings settings = CpuSettings(c.bins, 0.1f);
    SetOption(settings.options, "receiver-oracle", c.receiverOracle);
    auto solver = CreateSolver(scene, settings);
    solver->Iterate(1);
    auto irr = solver->SurfelIrradiance();
    size_t i = NearestSurfel(solver->GetSurfels(), {c.offsetX, 0, 0}, {0, 1, 0});
    glm::vec3 p = solver->GetSurfels().positions[i];
    glm::vec3 d = o - p;
    float dist = glm::length(d);
    float cosR = d.y / dist, cosE = glm::dot(n, -d / dist);
    float expected = L * side * side * cosR * cosE / (dist * dist);
    float actual = Mean(irr[i]);
    EXPECT_NEAR(actual, expected, 0.02f * expected)
        << "tilt " << c.tiltDegrees << "° at x=" << p.x << ": expected " << expected << ", got "
        << actual;
}

INSTANTIATE_TEST_SUITE_P(Antiradiance, FormFactor,
                         ::testing::Values(FormFactorCase{0, 0, 128}, FormFactorCase{0, 0, 512},
                                           FormFactorCase{30, 0, 256},
                                           FormFactorCase{0, 0.5f, 1024},
                                           FormFactorCase{0, 0.3f, 256},
                                           FormFactorCase{0, 0.5f, 256, 0.25f}));

// Closed box with blockers inside; every surface emits Le with albedo ρ. The exact
// solution is L = Le/(1−ρ) everywhere, so E = π Le/(1−ρ) at every surfel.
// Settings: 256 bins, 5 cm elements, oracle 0.25 for senders and 0.0625 (receiverOracle
// 0.25) for receivers. A receiver cluster hands the same L_in to all its members, so a
// member nearer the sender than the cluster's centre gets too little and one farther too
// much: an error of the first order in the receiver's size over the distance, where the
// sender's size costs only the second. Surfels next to a junction of walls, lit mostly from
// one side by the wall beside them, keep that error: with the receivers held to the
// senders' threshold (receiverOracle 1) the worst surfel is 3.9% low (mean 1.1%, 9M links);
// at 0.25 every surfel is within 2% (30M links). docs/SOLVER.md, "Known limits".
TEST(Antiradiance, WhiteFurnaceConvergesWithBlockers) {
    const float Le = 1.0f, rho = 0.5f;
    SceneBuilder b;
    uint32_t m = b.AddMaterial("furnace", glm::vec3(rho), glm::vec3(Le));
    AddUnitRoom(b, m, m);
    b.AddBox("blocker_a", m, {0.3f, 0.4f, 0.35f}, {0.2f, 0.3f, 0.25f});
    b.AddBox("blocker_b", m, {0.7f, 0.6f, 0.6f}, {0.25f, 0.1f, 0.3f}, 30.0f);
    Scene scene = b.Build();
    SolverSettings settings = CpuSettings(256, 0.05f);
    SetOption(settings.options, "oracle", 0.25f);
    SetOption(settings.options, "receiver-oracle", 0.25f);
    auto solver = CreateSolver(scene, settings);
    solver->Iterate(24);
    auto irr = solver->SurfelIrradiance();
    const auto& s = solver->GetSurfels();
    const float expected = std::numbers::pi_v<float> * Le / (1.0f - rho);
    double sumErr = 0.0, maxErr = 0.0;
    size_t n = 0, worst = 0;
    for (size_t i = 0; i < s.size(); ++i) {
        if (s.areas[i] <= 0.0f) continue;
        double err = std::abs(Mean(irr[i]) - expected) / expected;
        sumErr += err;
        if (err > maxErr) maxErr = err, worst = i;
        ++n;
    }
    double meanErr = sumErr / n;
    std::printf("furnace: %zu surfels, mean |E−πLe/(1−ρ)|/E %.4f, max %.4f at (%.3f %.3f %.3f)\n",
                n, meanErr, maxErr, s.positions[worst].x, s.positions[worst].y,
                s.positions[worst].z);
    EXPECT_LT(meanErr, 0.02) << "expected E = " << expected;
    EXPECT_LT(maxErr, 0.02) << "expected E = " << expected << ", worst surfel got "
                            << Mean(irr[worst]);
}

// Sec. 2.2: the asymmetric scheme (one radiance step, then antiradiance steps with L
// frozen) converges to the same solution as the symmetric one. Compared per surfel
// after both have converged (ρ = 0.5: 40 radiance steps leave < 1e-6 of the light).
TEST(Antiradiance, AsymmetricSchemeConvergesToTheSymmetricSolution) {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
    uint32_t light = b.AddMaterial("light", glm::vec3(0.5f), glm::vec3(4.0f));
    AddUnitRoom(b, grey, light);
    b.AddBox("blocker", grey, {0.5f, 0.5f, 0.5f}, {0.3f, 0.05f, 0.3f});
    Scene scene = b.Build();
    SolverSettings settings = CpuSettings(128, 0.1f);
    auto symmetric = CreateSolver(scene, settings);
    SetOption(settings.options, "scheme",
              "asymmetric");  // 1 radiance + 3 antiradiance steps a round
    auto asymmetric = CreateSolver(scene, settings);
    // Early on the two schedules must differ (else this test would compare one scheme
    // with itself): after 2 iterations the asymmetric scheme has done no K step on the
    // light the first antiradiance step let through.
    symmetric->Iterate(2);
    asymmetric->Iterate(2);
    double early = 0.0;
    {
        auto a = symmetric->SurfelIrradiance(), c = asymmetric->SurfelIrradiance();
        for (size_t i = 0; i < a.size(); ++i)
            early = std::max(early, double(std::abs(Mean(a[i]) - Mean(c[i]))));
    }
    std::printf("asymmetric vs symmetric after 2 iterations: max |ΔE| %.3g\n", early);
    EXPECT_GT(early, 1e-3);
    symmetric->Iterate(38);
    asymmetric->Iterate(4 * 40 - 2);
    auto a = symmetric->SurfelIrradiance();
    auto c = asymmetric->SurfelIrradiance();
    double maxDiff = 0.0, scale = 0.0;
    for (size_t i = 0; i < a.size(); ++i) scale = std::max(scale, double(Mean(a[i])));
    for (size_t i = 0; i < a.size(); ++i)
        maxDiff = std::max(maxDiff, double(std::abs(Mean(a[i]) - Mean(c[i]))));
    std::printf("asymmetric vs symmetric: max |ΔE| %.3g of max E %.3g\n", maxDiff, scale);
    // Both iterate the same linear system to its fixed point; 1e-3 of the largest value
    // leaves room for fp32 summation differences over 40 vs 160 iterations.
    EXPECT_LT(maxDiff, 1e-3 * scale);
}

// An opaque box between an emitter and the floor. The paper's symmetric scheme: after one
// iteration U lets the light through; antiradiance iterations must carve out the shadow
// (Fig. 2 of the paper). The adaptive scheme (the default) settles the antiradiance before it
// reports anything: the shadow is there from the first iteration.
TEST(Antiradiance, BlockerShadowAppearsWithIterations) {
    SceneBuilder open, blocked;
    for (SceneBuilder* b : {&open, &blocked}) {
        uint32_t grey = b->AddMaterial("grey", glm::vec3(0.5f));
        uint32_t light = b->AddMaterial("light", glm::vec3(0.0f), glm::vec3(10.0f));
        b->AddQuad("floor", grey, {-1, 0, -1}, {1, 0, -1}, {1, 0, 1}, {-1, 0, 1}, {0, 1, 0});
        b->AddQuad("emitter", light, {-0.15f, 1, -0.15f}, {0.15f, 1, -0.15f}, {0.15f, 1, 0.15f},
                   {-0.15f, 1, 0.15f}, {0, 0, 0});
        if (b == &blocked) b->AddBox("blocker", grey, {0, 0.5f, 0}, {0.5f, 0.05f, 0.5f});
    }
    SolverSettings settings = CpuSettings(256, 0.04f);
    auto reference = CreateSolver(open.Build(), settings);
    reference->Iterate(8);
    size_t ri = NearestSurfel(reference->GetSurfels(), {0, 0, 0}, {0, 1, 0});
    float unblocked = Mean(reference->SurfelIrradiance()[ri]);

    SolverSettings adaptive = settings;
    SetOption(adaptive.options, "scheme", "adaptive");
    auto settled = CreateSolver(blocked.Build(), adaptive);
    settled->Iterate(1);
    const size_t si = NearestSurfel(settled->GetSurfels(), {0, 0, 0}, {0, 1, 0});
    const float first = Mean(settled->SurfelIrradiance()[si]) / unblocked;
    std::printf("shadow, adaptive: iteration 1, E(under blocker)/E(unblocked) = %.4f\n", first);
    EXPECT_LT(std::abs(first), 0.1f) << "the adaptive scheme reports settled antiradiance only";

    SetOption(settings.options, "scheme", "symmetric");
    auto solver = CreateSolver(blocked.Build(), settings);
    size_t i = NearestSurfel(solver->GetSurfels(), {0, 0, 0}, {0, 1, 0});
    int needed = -1;
    float ratio = 1.0f;
    for (int it = 1; it <= 8; ++it) {
        solver->Iterate(1);
        ratio = Mean(solver->SurfelIrradiance()[i]) / unblocked;
        std::printf("shadow: iteration %d, E(under blocker)/E(unblocked) = %.4f\n", it, ratio);
        if (it == 1) {
            EXPECT_GT(ratio, 0.9f) << "after one iteration U has no shadow yet";
        }
        if (needed < 0 && std::abs(ratio) < 0.1f) needed = it;
    }
    std::printf("shadow: below 10%% of the unblocked value after %d iterations\n", needed);
    EXPECT_GT(needed, 0) << "final ratio " << ratio;
    EXPECT_LT(std::abs(ratio), 0.1f);
}

// Solver::SetInterrupt: a raised flag stops Iterate before its next pass, and the iteration
// goes on where it stopped. Cut at random places (a thread toggling the flag), bounces give
// bit for bit what uncut ones give, since the passes run in the same order.
TEST(Antiradiance, InterruptedIterationsResumeWhereTheyStopped) {
    SceneBuilder b;
    const uint32_t grey = b.AddMaterial("grey", glm::vec3(0.6f));
    const uint32_t light = b.AddMaterial("light", glm::vec3(0.0f), glm::vec3(10.0f));
    AddUnitRoom(b, grey, grey, 2);
    b.AddQuad("emitter", light, {0.4f, 0.99f, 0.4f}, {0.6f, 0.99f, 0.4f}, {0.6f, 0.99f, 0.6f},
              {0.4f, 0.99f, 0.6f}, {0.5f, 0.5f, 0.5f});
    for (int k = 0; k < 4; ++k)  // a row of boxes: bounces of many antiradiance steps
        b.AddBox("box" + std::to_string(k), grey, {0.2f + 0.15f * k, 0.15f, 0.5f},
                 {0.1f, 0.3f, 0.4f});
    const Scene scene = b.Build();
    const SolverSettings settings = CpuSettings(64, 0.08f);
    auto uncut = CreateSolver(scene, settings);
    uncut->Iterate(6);

    auto cut = CreateSolver(scene, settings);
    std::atomic<bool> flag{true};
    cut->SetInterrupt(&flag);
    cut->Iterate(3);  // raised before the first pass: nothing happens
    EXPECT_EQ(cut->Stats().iterations, 0);
    EXPECT_EQ(cut->Stats().gathers, 0);
    std::atomic<bool> done{false};
    std::thread toggle([&] {
        while (!done) {
            flag = !flag;
            std::this_thread::sleep_for(std::chrono::microseconds(300));
        }
    });
    int calls = 0;
    while (cut->Stats().iterations < 6) {
        cut->Iterate(1);
        ++calls;
    }
    done = true;
    toggle.join();
    std::printf("6 iterations in %d calls, %d passes\n", calls, cut->Stats().gathers);
    EXPECT_EQ(cut->Stats().gathers, uncut->Stats().gathers);
    EXPECT_EQ(cut->SurfelIrradiance(), uncut->SurfelIrradiance());
}

// A material edit between iterations (the service's SetLight/SetMaterial) continues from the
// current radiance and converges to what a fresh solver on the edited scene gives. Checked
// on the CPU back end and on lavapipe (where the leaves are uploaded again).
TEST(Antiradiance, MaterialEditsConvergeToAFreshSolve) {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
    uint32_t light = b.AddMaterial("light", glm::vec3(0.5f), glm::vec3(4.0f));
    AddUnitRoom(b, grey, light);
    Scene scene = b.Build();
    for (DeviceChoice device : {DeviceChoice::kCpu, DeviceChoice::kLavapipe}) {
        SolverSettings settings = CpuSettings(64, 0.2f);
        settings.device = device;
        settings.validation = device == DeviceChoice::kLavapipe;
        auto edited = CreateSolver(scene, settings);
        edited->Iterate(4);
        Scene dimmed = scene;
        dimmed.materials[light].emission = glm::vec3(1.0f, 2.0f, 0.5f);
        dimmed.materials[grey].albedo = glm::vec3(0.3f, 0.6f, 0.4f);
        edited->UpdateMaterials(dimmed);
        edited->Iterate(40);
        auto fresh = CreateSolver(dimmed, settings);
        fresh->Iterate(40);
        auto a = edited->SurfelIrradiance(), c = fresh->SurfelIrradiance();
        double worst = 0.0, peak = 0.0;
        for (size_t i = 0; i < a.size(); ++i) {
            worst = std::max(worst, double(glm::length(a[i] - c[i])));
            peak = std::max(peak, double(glm::length(c[i])));
        }
        // ρ ≤ 0.6: 36 more steps than needed leave < 0.6^36 ≈ 1e-8 of the old solution.
        EXPECT_LT(worst, 1e-4 * peak) << (device == DeviceChoice::kCpu ? "cpu" : "lavapipe")
                                      << ": max |edited − fresh| " << worst << " of " << peak;
    }
}

// The area oracle (links/oracle.h) refines wherever the paper's does, and also every
// receiver cluster whose area subtends more than oracle × receiverOracle × ω_bin: more
// links than the paper's, and no static link into a cluster past that bound.
TEST(LinkOracles, AreaOracleBoundsTheReceiversToo) {
    Scene scene = scenes::CornellBox().Build();
    SolverSettings s = CpuSettings(64, 0.1f);
    SetOption(s.options, "oracle", 2.0f);
    SetOption(s.options, "link-oracle", "paper");
    const AntiradianceModel paper = BuildAntiradianceModel(scene, s, {});
    SetOption(s.options, "link-oracle", "area");
    const AntiradianceModel area = BuildAntiradianceModel(scene, s, {});
    EXPECT_GT(area.links.links.size(), paper.links.links.size());
    const AntiradianceSettings own = ReadAntiradianceSettings(s);
    const float bound = own.oracle * own.receiverOracle * area.dirs.BinSolidAngle() * 1.0001f;
    size_t clusterLinks = 0, paperOver = 0;
    const auto over = [&](const AntiradianceModel& m, uint32_t r, const Link& l) {
        const HierarchyNode& R = m.hierarchy.nodes[r];
        const HierarchyNode& S = m.hierarchy.nodes[l.sender];
        const glm::vec3 d = R.center - S.center;
        return std::numbers::pi_v<float> * R.discRadius * R.discRadius / glm::dot(d, d) > bound;
    };
    for (uint32_t r = 0; r + 1 < area.links.offsets.size(); ++r) {
        if (area.hierarchy.nodes[r].IsLeaf()) continue;
        for (uint32_t i = area.links.offsets[r]; i < area.links.offsets[r + 1]; ++i) {
            ++clusterLinks;
            EXPECT_FALSE(over(area, r, area.links.links[i])) << "receiver " << r;
        }
    }
    for (uint32_t r = 0; r + 1 < paper.links.offsets.size(); ++r)
        if (!paper.hierarchy.nodes[r].IsLeaf())
            for (uint32_t i = paper.links.offsets[r]; i < paper.links.offsets[r + 1]; ++i)
                paperOver += over(paper, r, paper.links.links[i]);
    std::printf(
        "links: paper %zu, area %zu (%zu into clusters); paper links past the receiver "
        "bound: %zu\n",
        paper.links.links.size(), area.links.links.size(), clusterLinks, paperOver);
    EXPECT_GT(clusterLinks, 0u);
    EXPECT_GT(paperOver, 0u);  // else the test would not tell the two apart
    EXPECT_STREQ(LinkOracleName(LinkOracle::kArea), "area");
    try {
        ParseLinkOracle("sphere");
        ADD_FAILURE() << "an unknown oracle was accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("conservative, paper or area"), std::string::npos);
    }
}

// fp16 tables (cpu_half.cpp) hold I_ex over each node's area, scaled each iteration to the
// light's peak: the answer is fp32's to about 10⁻³ whatever the scene's units of light or
// length. A 5 mm box's 0.25 mm elements carry I_ex ≈ 10⁻⁷ (fp16's subnormals, were the rows
// not over the area); 10⁸ nits overflow fp16 unscaled.
std::vector<glm::vec3> SolveWithTables(const Scene& scene, SolverSettings s, TablePrecision t,
                                       int iterations, Channel channel) {
    SetOption(s.options, "tables", t == TablePrecision::kFp16 ? "fp16" : "fp32");
    auto solver = CreateSolver(scene, s);
    solver->Iterate(iterations);
    EXPECT_EQ(solver->Stats().Text("tables"), t == TablePrecision::kFp16 ? "fp16" : "fp32");
    return solver->SurfelIrradiance(channel);
}

TEST(HalfTables, MatchFp32WhateverTheUnits) {
    if (!cpu::CpuBackend::HalfSupported()) GTEST_SKIP() << "this CPU has no F16C";
    struct Case {
        const char* name;
        float emission, length;
    };
    for (const Case& c : {Case{"as built", 1.0f, 1.0f}, Case{"1e8 x emission", 1e8f, 1.0f},
                          Case{"1e-8 x emission", 1e-8f, 1.0f}, Case{"5 mm box", 1.0f, 0.01f}}) {
        SCOPED_TRACE(c.name);
        Scene scene = scenes::CornellBox().Build();
        for (Material& m : scene.materials) m.emission *= c.emission;
        for (size_t n = 0; n < scene.nodes.size(); ++n)
            if (scene.nodes[n].parent < 0)
                SetNodeTransform(
                    scene, static_cast<int>(n),
                    glm::scale(glm::mat4(1.0f), glm::vec3(c.length)) * scene.nodes[n].local);
        const SolverSettings s = CpuSettings(64, 0.05f * c.length);
        auto f32 = SolveWithTables(scene, s, TablePrecision::kFp32, 6, Channel::kIndirect);
        auto f16 = SolveWithTables(scene, s, TablePrecision::kFp16, 6, Channel::kIndirect);
        for (const glm::vec3& e : f16) ASSERT_TRUE(std::isfinite(e.x + e.y + e.z));
        EXPECT_LT(testing::RelativeRms(f16, f32), 2e-3);
    }
}

// The same with everything the local pass adds: a spot light (direct light reflected),
// glossy lobes, a sky, a light turned 10⁶ times brighter between iterations (the scale of
// the next table follows what the iteration adds, not only the last peak).
TEST(HalfTables, MatchFp32WithLightsGlossAndSky) {
    if (!cpu::CpuBackend::HalfSupported()) GTEST_SKIP() << "this CPU has no F16C";
    Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/glossy-box.gltf");
    ASSERT_FALSE(scene.lights.empty());
    scene.environment.constant = glm::vec3(0.2f);
    scene.environment.source = "constant";
    SolverSettings s = CpuSettings(64, 0.3f);
    std::vector<glm::vec3> result[2];
    for (int k = 0; k < 2; ++k) {
        SetOption(s.options, "tables", k ? "fp16" : "fp32");
        auto solver = CreateSolver(scene, s);
        solver->Iterate(3);
        Scene bright = scene;
        for (PunctualLight& l : bright.lights) l.intensity *= 1e6f;
        solver->UpdateLights(bright);
        solver->Iterate(3);
        result[k] = solver->SurfelIrradiance(Channel::kTotal);
    }
    for (const glm::vec3& e : result[1]) ASSERT_TRUE(std::isfinite(e.x + e.y + e.z));
    EXPECT_LT(testing::RelativeRms(result[1], result[0]), 2e-3);
}

TEST(HalfTables, AreACpuBackEndOption) {
    EXPECT_EQ(ParseTablePrecision("fp16"), TablePrecision::kFp16);
    EXPECT_THROW(ParseTablePrecision("fp8"), Error);
    Scene scene = scenes::CornellBox().Build();
    SolverSettings s = CpuSettings(32, 0.2f);
    s.device = DeviceChoice::kLavapipe;
    SetOption(s.options, "tables", "fp16");
    try {
        CreateSolver(scene, s);
        ADD_FAILURE() << "fp16 tables on a Vulkan device were accepted";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("fp16 tables are a CPU back end option"),
                  std::string::npos)
            << e.what();
    }
}

}  // namespace
}  // namespace penumbra
