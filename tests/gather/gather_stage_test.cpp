// The emitters' direct light as a solver's first shot (gather/gather_stage.h): the answer gets
// closer to the reference where the bins blurred the direct light, edits of an emitter give
// what a fresh solve gives, and the Vulkan back end agrees with the CPU one.
#include "gather/gather_stage.h"

#include <gtest/gtest.h>

#include <glm/gtc/matrix_transform.hpp>
#include <numbers>

#include "clutter_scenes.h"
#include "output/compare.h"
#include "output/irradiance_writer.h"
#include "reference/path_tracer.h"
#include "scene/gltf_loader.h"
#include "scene/scene_builder.h"
#include "solvers/antiradiance/settings.h"
#include "test_util.h"

namespace penumbra {
namespace {

double Rmse(const Scene& scene, Solver& solver, const IrradianceFile& truth) {
    return Compare(ToIrradianceFile(scene, CollectIrradiance(scene, solver, Channel::kIndirect)),
                   truth)
        .overall.relRmse;
}

IrradianceFile Truth(const Scene& scene, int samples) {
    ReferenceSettings rs;
    rs.samples = samples;
    return ReferenceFile(scene, rs);
}

// The first shot alone (no final gather).
GatherSettings ShotOnly() {
    GatherSettings g;
    g.gatherRays = 0;
    return g;
}

SolverSettings Cpu() {
    SolverSettings s;
    s.solver = "antiradiance";
    s.device = DeviceChoice::kCpu;
    s.elementSize = 0.1f;
    return s;
}

// The blocker under its panel: the solver alone blurs the area light's shadow over the bins;
// with the first shot the shadow is traced.
TEST(FirstShot, BlockerShadowGetsCloserToTheReference) {
    const Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/blocker.gltf");
    const IrradianceFile truth = Truth(scene, 1024);
    auto alone = CreateSolver(scene, Cpu());
    IterateUntilConverged(*alone, 1e-3, 200);
    GatherStage shot(CreateSolver(scene, Cpu()), scene, ShotOnly());
    IterateUntilConverged(shot, 1e-3, 200);
    const double a = Rmse(scene, *alone, truth), b = Rmse(scene, shot, truth);
    std::printf("blocker: solver alone %.2f%%, with the first shot %.2f%%\n", 100 * a, 100 * b);
    EXPECT_LT(b, 0.5 * a);
    EXPECT_GT(shot.Stats().gather.emitterRays, 0);
}

// A yard under a sky map with a small sun: a floor, a box and a wall. The sun (2° across,
// 84% of the light on open ground) casts hard shadows.
Scene SunnyYard(float rotation = 0.0f) {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", glm::vec3(0.6f));
    uint32_t red = b.AddMaterial("red", glm::vec3(0.7f, 0.2f, 0.2f));
    b.AddTiledQuad("floor", grey, {-2, 0, -2}, {4, 0, 0}, {0, 0, 4}, 8, 8, {0, 1, 0});
    b.AddBox("box", red, {0.3f, 0.4f, 0.2f}, {0.8f, 0.8f, 0.8f}, 0.0f, false);
    b.SetDynamic("box", {0.3f, 0.4f, 0.2f}, {-0.3f, 0.0f, -0.5f}, {1.0f, 0.8f, 0.8f});
    b.AddQuad("wall", grey, {-1.5f, 0, -1.2f}, {1.5f, 0, -1.2f}, {1.5f, 1.5f, -1.2f},
              {-1.5f, 1.5f, -1.2f}, {0, 0.75f, -1.2f}, 4);
    Scene scene = b.Build();
    scene.environment.source = "sunny";
    scene.environment.image = std::make_shared<Image>(
        testing::SunnyMap(256, glm::normalize(glm::vec3(0.3f, 0.8f, 0.5f)), 0.035f, 2000.0f, 0.5f));
    scene.environment.rotation = rotation;
    return scene;
}

// The sun as a light: traced from every surfel in the first shot (its hard shadows), the rest
// of the sky through the solver and the gather's cosine rays. Without the first shot the
// gather's cosine rays meet the sun in one of ~1,000 and the solver's bins blur its shadows.
TEST(FirstShot, TheSkyMapsSunIsTracedAsALight) {
    const Scene scene = SunnyYard();
    const IrradianceFile truth = Truth(scene, 1024);
    GatherSettings without;
    without.emitterRays = 0;
    auto old = CreateGatheredSolver(scene, Cpu(), without);
    IterateUntilConverged(*old, 1e-3, 200);
    auto now = CreateGatheredSolver(scene, Cpu(), GatherSettings{});
    IterateUntilConverged(*now, 1e-3, 200);
    EXPECT_EQ(old->Stats().gather.sunRays, 0);
    EXPECT_EQ(now->Stats().gather.sunRays, 128);
    const double a = Rmse(scene, *old, truth), b = Rmse(scene, *now, truth);
    std::printf("sunny yard: gathered without the sun's shot %.2f%%, with it %.2f%%\n", 100 * a,
                100 * b);
    EXPECT_LT(b, 0.05);
    EXPECT_LT(b, 0.5 * a);
}

// Dimming the emitter (a material edit) reshoots: the answer equals a fresh solve's.
TEST(FirstShot, EmitterEditMatchesAFreshSolve) {
    Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf");
    GatherStage shot(CreateSolver(scene, Cpu()), scene, ShotOnly());
    shot.Iterate(5);
    for (Material& m : scene.materials) m.emission *= 0.5f;
    shot.UpdateMaterials(scene);
    IterateUntilConverged(shot, 1e-4, 300);
    GatherStage fresh(CreateSolver(scene, Cpu()), scene, ShotOnly());
    IterateUntilConverged(fresh, 1e-4, 300);
    EXPECT_LT(testing::RelativeRms(shot.SurfelIrradiance(Channel::kIndirect),
                                   fresh.SurfelIrradiance(Channel::kIndirect)),
              2e-3);
}

// Lavapipe (validation on) and the CPU back end take the same first shot to the same answer.
TEST(FirstShot, LavapipeMatchesTheCpu) {
    const Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/blocker.gltf");
    SolverSettings s = Cpu();
    SetOption(s.options, "bins", 64);
    s.elementSize = 0.2f;
    SetOption(s.options, "tables", "fp32");
    GatherStage cpu(CreateSolver(scene, s), scene, ShotOnly());
    s.device = DeviceChoice::kLavapipe;
    SetOption(s.options, "tables", "auto");
    s.validation = true;
    GatherStage gpu(CreateSolver(scene, s), scene, ShotOnly());
    cpu.Iterate(6);
    gpu.Iterate(6);
    EXPECT_LT(testing::RelativeRms(gpu.SurfelIrradiance(Channel::kTotal),
                                   cpu.SurfelIrradiance(Channel::kTotal)),
              1e-3);
}

// The white furnace with blockers (tests/solver/antiradiance_test.cpp): every surface emits
// Le and reflects ρ, so E = π Le/(1 − ρ) at every vertex. At coarse settings the solver
// alone is a few per cent off near junctions; the gather reads its answer only through the
// reflected part (ρ of it) averaged over the hemisphere, and takes the emission exactly.
TEST(FinalGather, WhiteFurnaceWithinOnePercentAtEveryVertex) {
    const float Le = 1.0f, rho = 0.5f;
    SceneBuilder b;
    uint32_t m = b.AddMaterial("furnace", glm::vec3(rho), glm::vec3(Le));
    testing::AddUnitRoom(b, m, m, 3);
    b.AddBox("blocker_a", m, {0.3f, 0.4f, 0.35f}, {0.2f, 0.3f, 0.25f});
    b.AddBox("blocker_b", m, {0.7f, 0.6f, 0.6f}, {0.25f, 0.1f, 0.3f}, 30.0f);
    const Scene scene = b.Build();
    const float expected = std::numbers::pi_v<float> * Le / (1.0f - rho);
    auto worst = [&](const std::vector<glm::vec3>& e) {
        double w = 0.0, sum = 0.0, bias = 0.0;
        size_t at = 0;
        for (size_t i = 0; i < e.size(); ++i) {
            double d = std::abs(testing::Mean(e[i]) - expected);
            sum += d;
            bias += testing::Mean(e[i]) - expected;
            if (d > w) w = d, at = i;
        }
        std::printf("  bias %.3f%%, mean %.3f%%, worst %.3f%% at vertex %zu (%.3f)\n",
                    100 * bias / e.size() / expected, 100 * sum / e.size() / expected,
                    100 * w / expected, at, testing::Mean(e[at]));
        return w / expected;
    };
    auto alone = CreateSolver(scene, testing::CpuSettings(128, 0.1f));
    IterateUntilConverged(*alone, 1e-4, 300);
    const double a = worst(testing::AllVertices(*alone, scene, Channel::kTotal));
    // The emission at the hits (no first shot), and with the first shot.
    GatherSettings g;
    g.emitterRays = 0;
    GatherStage hits(CreateSolver(scene, testing::CpuSettings(128, 0.1f)), scene, g);
    IterateUntilConverged(hits, 1e-4, 300);
    const double h = worst(testing::AllVertices(hits, scene, Channel::kTotal));
    GatherStage shot(CreateSolver(scene, testing::CpuSettings(128, 0.1f)), scene, {});
    IterateUntilConverged(shot, 1e-4, 300);
    const double s = worst(testing::AllVertices(shot, scene, Channel::kTotal));
    std::printf(
        "furnace, worst vertex: solver alone %.2f%%, gathered %.2f%%, with the first "
        "shot %.2f%%\n",
        100 * a, 100 * h, 100 * s);
    EXPECT_LT(h, 0.01);
    EXPECT_LT(s, 0.01);
}

// Issue 61: a short hit's punctual light is its own. In the sunlit maze the sun lights the
// floor west of the first inner wall, which stands on floor triangles that run on under it
// to its east side, where no sun arrives (the reference: 0 lux). At the foot of the wall's
// east face the hemisphere sees mostly that floor; the solver's direct light interpolated
// over those triangles read 20–66 lux there, the west side's sun through the wall.
TEST(FinalGather, NoSunBehindAWallOnTheFloor) {
    const Scene scene = scenes::SunlitMaze().Build();
    SolverSettings settings;
    settings.solver = "lightfield";
    settings.device = DeviceChoice::kCpu;
    auto solver = CreateGatheredSolver(scene, settings, GatherSettings{});
    IterateUntilConverged(*solver, 1e-3, 50);
    const std::vector<glm::vec3> e = testing::AllVertices(*solver, scene, Channel::kTotal);
    const float sun = 1000.0f;
    size_t at = 0, checked = 0;
    for (const Primitive& prim : scene.primitives) {
        for (size_t v = 0; v < prim.positions.size(); ++v, ++at) {
            const glm::vec3& x = prim.positions[v];
            // inner_0's east face (x = 1.53, facing +x) by the sunlit floor (z 1–1.5 west of
            // the wall), its lowest two rows of vertices.
            if (prim.node != "inner_0" || prim.normals[v].x < 0.9f || x.y > 0.35f || x.z < 0.9f ||
                x.z > 1.6f)
                continue;
            ++checked;
            EXPECT_LT(e[at].x, 0.01f * sun) << "at " << x.x << "," << x.y << "," << x.z;
        }
    }
    EXPECT_EQ(checked, 6u);
}

// A room for edits: a ceiling half emitting panel, half open to a constant sky, a point
// light, a movable box on the floor.
Scene EditRoom() {
    SceneBuilder b;
    uint32_t white = b.AddMaterial("white", glm::vec3(0.7f));
    uint32_t red = b.AddMaterial("red", glm::vec3(0.6f, 0.1f, 0.1f));
    uint32_t panel = b.AddMaterial("panel", glm::vec3(0.5f), glm::vec3(3.0f));
    testing::AddRoomSides(b, white, "", 3);
    b.AddQuad("panel", panel, {0, 1, 0}, {0.5f, 1, 0}, {0.5f, 1, 1}, {0, 1, 1}, {0.5f, 0.5f, 0.5f},
              2);
    b.SetDynamic("panel", {0.25f, 1.0f, 0.5f}, {0.0f, 0.9f, 0.0f}, {1.0f, 1.0f, 1.0f});
    b.AddBox("box", red, {0.5f, 0.15f, 0.5f}, {0.3f, 0.3f, 0.3f}, 20.0f, false);
    b.SetDynamic("box", {0.5f, 0.15f, 0.5f}, {0.1f, 0.0f, 0.1f}, {0.9f, 0.4f, 0.9f});
    b.AddLight(
        testing::MakeLight("lamp", LightType::kPoint, {0.25f, 0.8f, 0.75f}, {0, -1, 0}, 0.5f));
    Scene scene = b.Build();
    scene.environment = ConstantEnvironment(glm::vec3(0.5f));
    return scene;
}

using Edit = std::function<void(Scene&)>;

// Each edit in turn applied to a gather stage on `scene` (edits named "light…" and "sky…" as
// light edits, "move" as a move, the others as material edits) re-evaluates the cached hits
// (or re-traces them, for a move, an emitter edit or a turned sky map, whose sun moves): the
// answer is what a gather stage built fresh on the edited scene gives.
void EditsMatchAFreshGather(Scene scene, const std::vector<std::pair<std::string, Edit>>& edits) {
    SolverSettings settings = Cpu();
    settings.prepareMoves = true;
    GatherStage stage(CreateSolver(scene, settings), scene, {});
    ASSERT_GT(stage.Stats().gather.rays, 0);
    ASSERT_GT(stage.Stats().gather.emitterRays, 0);
    IterateUntilConverged(stage, 1e-4, 300);
    for (const auto& [name, edit] : edits) {
        const std::vector<glm::vec3> before = testing::AllVertices(stage, scene, Channel::kTotal);
        const size_t traces = stage.Stats().gather.traces;
        edit(scene);
        if (name.rfind("light", 0) == 0 || name.rfind("sky", 0) == 0) {
            stage.UpdateLights(scene);
        } else if (name.rfind("move", 0) == 0) {
            ASSERT_EQ(stage.GeometryMismatch(scene), "");
            stage.UpdateGeometry(scene);
        } else {
            stage.UpdateMaterials(scene);
        }
        IterateUntilConverged(stage, 1e-4, 300);
        GatherStage fresh(CreateSolver(scene, settings), scene, {});
        IterateUntilConverged(fresh, 1e-4, 300);
        const std::vector<glm::vec3> now = testing::AllVertices(stage, scene, Channel::kTotal);
        const double moved = testing::RelativeRms(now, before);
        const double apart =
            testing::RelativeRms(now, testing::AllVertices(fresh, scene, Channel::kTotal));
        std::printf("%-10s changed the answer by %.2f%%; edited vs fresh %.4f%%\n", name.c_str(),
                    100 * moved, 100 * apart);
        EXPECT_GT(moved, 0.005) << name;
        EXPECT_LT(apart, 2e-3) << name;
        // Only a move traces the gather's or the shot's rays (part of them); the other edits
        // re-read the cached ones (an emissive edit re-weights them, emission being linear).
        if (name.rfind("move", 0) != 0 && name != "sky turn") {
            EXPECT_EQ(stage.Stats().gather.traces, traces) << name;
        }
        if (name == "move") {
            // Only the rays near the box were traced again: fewer than a third of them.
            const SolverStats st = stage.Stats();
            // The glints: a view from the vertex and one of each light each; the short hits:
            // one of each light each.
            const size_t all = st.gather.targets * st.gather.rays +
                               stage.GetSurfels().size() * st.gather.emitterRays +
                               size_t(st.Number("gather_glints")) * (1 + scene.lights.size()) +
                               size_t(st.Number("gather_short_hits")) * scene.lights.size();
            std::printf("the move traced %zu of at least %zu rays again\n", st.gather.raysRetraced,
                        all);
            EXPECT_GT(st.gather.raysRetraced, 0u);
            EXPECT_LT(st.gather.raysRetraced, all / 3);
        }
        if (name == "move emitter") {
            // The first shot is traced again whole (its rays aim at the emitter; a full trace
            // is not counted as retraced), the gather's rays only where they pass near the
            // emitter's old or new place (here most of the ceiling: 71% of them), with the
            // short hits' shadow rays at the targets whose rays were traced again.
            const SolverStats st = stage.Stats();
            const size_t gather = st.gather.targets * st.gather.rays +
                                  size_t(st.Number("gather_short_hits")) * scene.lights.size();
            std::printf("the emitter's move traced %zu of %zu gather rays again\n",
                        st.gather.raysRetraced, gather);
            EXPECT_GT(st.gather.traces, traces);
            EXPECT_GT(st.gather.raysRetraced, 0u);
            EXPECT_LT(st.gather.raysRetraced, gather * 3 / 4);
        }
    }
}

Edit MoveTheBox() {
    return [](Scene& s) {
        const int box = FindNode(s, "box");
        SetNodeTransform(
            s, box,
            glm::translate(glm::mat4(1.0f), glm::vec3(0.15f, 0.0f, -0.1f)) * s.nodes[box].local);
    };
}

// The sun's rays are kept: the sky's intensity re-reads them, a turned map (its sun elsewhere)
// traces them again, a move traces those that pass near the box.
TEST(FirstShot, SunEditsMatchAFreshGather) {
    EditsMatchAFreshGather(SunnyYard(),
                           {
                               {"sky", [](Scene& s) { s.environment.intensity = 0.5f; }},
                               {"sky turn", [](Scene& s) { s.environment.rotation = 1.3f; }},
                               {"move", MoveTheBox()},
                               {"albedo", [](Scene& s) { s.materials[1].albedo *= 0.5f; }},
                           });
}

TEST(FinalGather, EditsMatchAFreshGather) {
    EditsMatchAFreshGather(
        EditRoom(),
        {
            {"albedo", [](Scene& s) { s.materials[0].albedo = glm::vec3(0.4f, 0.5f, 0.6f); }},
            {"emission", [](Scene& s) { s.materials[2].emission = glm::vec3(1.0f, 2.0f, 4.0f); }},
            {"light", [](Scene& s) { s.lights[0].intensity *= 4.0f; }},
            {"sky", [](Scene& s) { s.environment.intensity = 3.0f; }},
            {"move", MoveTheBox()},
            {"move emitter",
             [](Scene& s) {
                 const int panel = FindNode(s, "panel");
                 SetNodeTransform(s, panel,
                                  glm::translate(glm::mat4(1.0f), glm::vec3(0.4f, -0.05f, 0.0f)) *
                                      s.nodes[panel].local);
             }},
        });
}

// A moved emitter's first shot in parts (GatherSettings::shotPartMs, as the service's
// frames take it): while parts are left the stats say how far it is and the iteration does
// not count as settled; a move of something else while it is under way starts it again; once
// done, the answer is the whole shot's.
TEST(FinalGather, AMovedEmittersShotInPartsMatchesTheWholeShot) {
    Scene scene = EditRoom();
    SolverSettings settings = Cpu();
    settings.prepareMoves = true;
    GatherSettings parts;
    parts.shotPartMs = 1e-3;  // one block of surfels a part
    GatherStage whole(CreateSolver(scene, settings), scene, {});
    GatherStage inParts(CreateSolver(scene, settings), scene, parts);
    IterateUntilConverged(whole, 1e-4, 300);
    IterateUntilConverged(inParts, 1e-4, 300);
    EXPECT_EQ(inParts.Stats().catchingUp, "");
    const int panel = FindNode(scene, "panel");
    SetNodeTransform(
        scene, panel,
        glm::translate(glm::mat4(1.0f), glm::vec3(0.4f, -0.05f, 0.0f)) * scene.nodes[panel].local);
    whole.UpdateGeometry(scene);
    inParts.UpdateGeometry(scene);
    EXPECT_EQ(whole.Stats().catchingUp, "");
    const std::string first = inParts.Stats().catchingUp;
    std::printf("after the move: %s\n", first.c_str());
    ASSERT_NE(first.find("the first shot traced again"), std::string::npos) << first;
    // A move of the box while parts are left: the shot starts again (the part traced so far
    // saw the box where it was).
    inParts.Iterate(1);
    MoveTheBox()(scene);
    whole.UpdateGeometry(scene);
    inParts.UpdateGeometry(scene);
    int left = 0;
    for (; !inParts.Stats().catchingUp.empty() && left < 1000; ++left) inParts.Iterate(1);
    std::printf("parts after the second move: %d\n", left + 1);
    EXPECT_GT(left, 2);
    const Convergence c = IterateUntilConverged(inParts, 1e-4, 300);
    EXPECT_TRUE(c.converged);
    IterateUntilConverged(whole, 1e-4, 300);
    const double apart = testing::RelativeRms(testing::AllVertices(inParts, scene, Channel::kTotal),
                                              testing::AllVertices(whole, scene, Channel::kTotal));
    std::printf("in parts vs whole: %.5f%%\n", 100 * apart);
    EXPECT_LT(apart, 2e-4);
}

// The same with glossy materials (a metal box, glossy walls): the lobe rays of glossy
// hits and the punctual lights they see are cached too; a lobe's shape (roughness) or a
// light's place traces them again, its colour or intensity re-reads them.
TEST(FinalGather, GlossyEditsMatchAFreshGather) {
    Scene scene = EditRoom();
    scene.materials[1] = PbrMaterial("red", glm::vec3(0.8f, 0.3f, 0.2f), 1.0f, 0.3f);
    scene.materials[0] = PbrMaterial("white", glm::vec3(0.7f), 0.0f, 0.5f);
    ASSERT_TRUE(scene.materials[0].Glossy() && scene.materials[1].Glossy());
    auto metal = [](float roughness) {
        return [roughness](Scene& s) {
            s.materials[1] = PbrMaterial("red", glm::vec3(0.3f, 0.8f, 0.2f), 1.0f, roughness);
        };
    };
    EditsMatchAFreshGather(
        scene,
        {
            {"colour", metal(0.3f)},
            {"roughness",
             [](Scene& s) { s.materials[0] = PbrMaterial("white", glm::vec3(0.7f), 0.0f, 0.15f); }},
            {"emission", [](Scene& s) { s.materials[2].emission = glm::vec3(1, 2, 4); }},
            {"light", [](Scene& s) { s.lights[0].intensity *= 4.0f; }},
            {"light-move", [](Scene& s) { s.lights[0].position.x += 0.4f; }},
            {"sky", [](Scene& s) { s.environment.intensity = 3.0f; }},
            {"move", MoveTheBox()},
        });
}

// Behind a final gather the antiradiance solver's bins default to kBinsBehindGather; a glossy scene
// keeps kDefaultBins (its solver reflects the emitters' light through its lobes itself: the first
// shot is not handed to it, a note says so); bins given are kept.
TEST(FinalGather, SolverBehindTheGatherDefaultsToFewerBins) {
    SolverSettings s = Cpu();
    s.elementSize = 0.25f;
    const Scene cornell = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf");
    EXPECT_EQ(CreateGatheredSolver(cornell, s, {})->Stats().bins, kBinsBehindGather);
    EXPECT_EQ(CreateSolver(cornell, s)->Stats().bins, kDefaultBins);
    GatherSettings off;
    off.gatherRays = 0;
    EXPECT_EQ(CreateGatheredSolver(cornell, s, off)->Stats().bins, kDefaultBins);
    std::vector<std::string> notes;
    const Scene glossy = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/glossy-box.gltf");
    const SolverStats g = CreateGatheredSolver(glossy, s, {})->Stats();
    EXPECT_EQ(g.bins, kDefaultBins);
    EXPECT_GT(g.gather.rays, 0);
    Scene metal = cornell;  // emitters and a glossy material
    metal.materials[0] = PbrMaterial(metal.materials[0].name, glm::vec3(0.8f), 1.0f, 0.3f);
    const SolverStats m = CreateGatheredSolver(metal, s, {}, {}, &notes)->Stats();
    EXPECT_EQ(m.bins, kDefaultBins);
    EXPECT_GT(m.gather.emitterRays, 0);
    ASSERT_EQ(notes.size(), 1u);
    EXPECT_NE(notes[0].find("not the solver"), std::string::npos) << notes[0];
    SetOption(s.options, "bins", 96);
    EXPECT_EQ(CreateGatheredSolver(cornell, s, {})->Stats().bins, 96);
}

// A point light's highlight in a glossy metal floor lights a white wall beside it: the wall's
// indirect light is almost all that path (light → glossy floor → wall), which the gather
// follows through the floor's lobe from each wall vertex's rays and from its glints (MIS).
TEST(FinalGather, PunctualLightThroughAGlossyFloorMatchesTheReference) {
    SceneBuilder b;
    const uint32_t metal = b.AddMaterial("metal", glm::vec3(0.9f));
    const uint32_t white = b.AddMaterial("white", glm::vec3(0.8f));
    b.AddTiledQuad("floor", metal, {-1, 0, -1}, {2, 0, 0}, {0, 0, 2}, 8, 8, {0, 1, 0});
    b.AddQuad("wall", white, {1, 0, -1}, {1, 0, 1}, {1, 1, 1}, {1, 1, -1}, {0, 0.5f, 0}, 6);
    b.AddLight(
        testing::MakeLight("lamp", LightType::kPoint, {-0.2f, 0.5f, 0.1f}, {0, -1, 0}, 2.0f));
    Scene scene = b.Build();
    scene.materials[metal] = PbrMaterial("metal", glm::vec3(0.9f), 1.0f, 0.5f);
    ASSERT_TRUE(scene.materials[metal].Glossy());
    // The path tracer follows this path no better than the gather: at 16,384 paths a vertex
    // it is itself about 3% from a 65,536-path truth here.
    const IrradianceFile truth = Truth(scene, 65536);
    SolverSettings s = testing::CpuSettings(128, 0.1f);
    auto alone = CreateSolver(scene, s);
    IterateUntilConverged(*alone, 1e-4, 300);
    GatherStage gathered(CreateSolver(scene, s), scene, {});
    IterateUntilConverged(gathered, 1e-4, 300);
    const int wall = FindNode(scene, "wall");
    auto wallError = [&](Solver& solver) {
        const IrradianceFile f =
            ToIrradianceFile(scene, CollectIrradiance(scene, solver, Channel::kIndirect));
        return Compare(f, truth).nodes.at(scene.nodes[wall].name).relRmse;
    };
    const double a = wallError(*alone), g = wallError(gathered);
    std::printf("wall through the glossy floor: solver alone %.2f%%, gathered %.2f%%\n", 100 * a,
                100 * g);
    EXPECT_LT(g, 0.05);
    EXPECT_LT(g, 0.5 * a);
}

}  // namespace
}  // namespace penumbra
