// Glossy surfaces (issue 5): the glTF roughness/metallic mapping, the discretised Phong
// lobes, directional reflection in the local pass (Eq. 18 with the lobe) for light from
// emitters and from punctual lights, energy conservation, the reference's lobe, and the
// solver on lavapipe against the CPU solver.
#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "base/check.h"
#include "reference/path_tracer.h"
#include "scene/gltf_loader.h"
#include "solver/solver.h"
#include "solvers/antiradiance/antiradiance_solver.h"
#include "solvers/antiradiance/model.h"
#include "test_util.h"

namespace penumbra {
namespace {

using testing::Mean;
constexpr float kPi = std::numbers::pi_v<float>;

using testing::CpuSettings;

TEST(GlossyMaterial, MetallicRoughnessMapsToDiffuseAndLobe) {
    // Rough dielectric: the diffuse path, albedo = base colour (docs/MATERIALS.md).
    Material rough = PbrMaterial("rough", glm::vec3(0.5f, 0.4f, 0.3f), 0.0f, 1.0f);
    EXPECT_FALSE(rough.Glossy());
    EXPECT_EQ(rough.albedo, glm::vec3(0.5f, 0.4f, 0.3f));
    // Rough metal: its nearly uniform lobe reflects as diffuse light of the base colour.
    Material roughMetal = PbrMaterial("m", glm::vec3(0.9f, 0.6f, 0.2f), 1.0f, 0.9f);
    EXPECT_FALSE(roughMetal.Glossy());
    EXPECT_EQ(roughMetal.albedo, glm::vec3(0.9f, 0.6f, 0.2f));
    // Smooth metal: no diffuse, F0 = base colour, n = 1/(2α²) − ½ with α = roughness².
    Material metal = PbrMaterial("gold", glm::vec3(1.0f, 0.8f, 0.3f), 1.0f, 0.5f);
    ASSERT_TRUE(metal.Glossy());
    EXPECT_EQ(metal.albedo, glm::vec3(0.0f));
    EXPECT_EQ(metal.specular, glm::vec3(1.0f, 0.8f, 0.3f));
    EXPECT_NEAR(metal.phongExponent, 0.5f / 0.0625f - 0.5f, 1e-4f);
    // Smooth dielectric: F0 = 0.04 and the diffuse layer keeps 1 − 0.04.
    Material plastic = PbrMaterial("p", glm::vec3(1.0f), 0.0f, 0.3f);
    ASSERT_TRUE(plastic.Glossy());
    EXPECT_NEAR(plastic.specular.x, 0.04f, 1e-6f);
    EXPECT_NEAR(plastic.albedo.x + plastic.specular.x, 1.0f, 1e-6f);
    // The cut between the two: n = 1 at roughness (1/3)^¼.
    EXPECT_TRUE(PbrMaterial("a", glm::vec3(1.0f), 1.0f, kGlossyRoughness - 1e-3f).Glossy());
    EXPECT_FALSE(PbrMaterial("b", glm::vec3(1.0f), 1.0f, kGlossyRoughness + 1e-3f).Glossy());
    // A mirror's exponent is capped.
    EXPECT_EQ(PbrMaterial("c", glm::vec3(1.0f), 1.0f, 0.0f).phongExponent, kMaxPhongExponent);
}

TEST(GlossyMaterial, GltfRoundTripAndBadFactors) {
    auto dir = testing::TempDir("glossy-gltf");
    SceneBuilder b;
    uint32_t gold = b.AddPbrMaterial("gold", glm::vec3(1.0f, 0.8f, 0.3f), 1.0f, 0.4f);
    b.AddQuad("floor", gold, {0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}, {0, 1, 0});
    b.WriteGltf((dir / "gold.gltf").string());
    Scene scene = LoadGltf((dir / "gold.gltf").string());
    const Material& m = scene.materials[scene.primitives[0].material];
    EXPECT_NEAR(m.roughness, 0.4f, 1e-6f);
    EXPECT_NEAR(m.metallic, 1.0f, 1e-6f);
    EXPECT_TRUE(m.Glossy());
    EXPECT_NEAR(m.specular.y, 0.8f, 1e-6f);

    // A roughness outside [0, 1] names the material and the reason.
    std::string text = testing::ReadFile(dir / "gold.gltf");
    auto at = text.find("\"roughnessFactor\"");
    ASSERT_NE(at, std::string::npos);
    auto end = text.find_first_of(",}", at);
    text.replace(at, end - at, "\"roughnessFactor\": 1.5");
    testing::WriteFile(dir / "bad.gltf", text);
    try {
        LoadGltf((dir / "bad.gltf").string());
        FAIL() << "expected an error";
    } catch (const Error& e) {
        EXPECT_NE(std::string(e.what()).find("'gold'"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("roughnessFactor"), std::string::npos) << e.what();
    }
}

// A floor with one glossy material, for the model's lobes.
Scene GlossyFloor(float roughness) {
    SceneBuilder b;
    uint32_t m = b.AddPbrMaterial("metal", glm::vec3(0.8f), 1.0f, roughness);
    b.AddQuad("floor", m, {0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}, {0, 1, 0});
    return b.Build();
}

// Every lobe row reflects at most F0 about its own centre (normal incidence), the best row
// exactly F0, none much less; the kernel is symmetric, so rows serve either side.
TEST(GlossyLobe, RowsAreNormalisedAndSymmetric) {
    for (int bins : {64, 128, 512}) {
        for (float roughness : {0.7f, 0.5f, 0.2f}) {
            Scene scene = GlossyFloor(roughness);
            AntiradianceModel m = BuildAntiradianceModel(scene, CpuSettings(bins, 0.5f), {});
            ASSERT_EQ(m.lobes.size(), 1u);
            ASSERT_EQ(m.glossy.size(), m.leaves.size());
            const GlossyLobe& lobe = m.lobes[0];
            EXPECT_LE(lobe.exponent, MaxLobeExponent(bins) + 1e-4f);
            std::vector<float> dense(size_t(bins) * bins, 0.0f);
            double best = 0.0, worst = 1e9;
            for (int b = 0; b < bins; ++b) {
                double sum = 0.0;
                for (uint32_t k = 0; k < lobe.width; ++k) {
                    const BinWeight& w = m.lobeWeights[lobe.start + size_t(b) * lobe.width + k];
                    dense[size_t(b) * bins + w.bin] += w.weight;
                    sum += w.weight *
                           std::max(0.0f, glm::dot(m.dirs.Direction(b), m.dirs.Direction(w.bin)));
                }
                sum *= m.dirs.BinSolidAngle();
                best = std::max(best, sum);
                worst = std::min(worst, sum);
            }
            EXPECT_NEAR(best, 1.0, 1e-5) << bins << " bins, roughness " << roughness;
            EXPECT_GT(worst, 0.85) << bins << " bins, roughness " << roughness;
            for (int b = 0; b < bins; ++b)
                for (int j = 0; j < bins; ++j)
                    ASSERT_NEAR(dense[size_t(b) * bins + j], dense[size_t(j) * bins + b], 1e-6f);
        }
    }
}

// A small floor (0.6 m square) lit from the −x side at 45°, and two panels (0.6 m square)
// 1.4 m away that look at the floor's centre: one at the mirror position on the +x side, one
// off to the +z side at the same height. `emitter`: the light is an emitting patch (0.2 m
// square, facing the floor); otherwise a point light.
struct MirrorProbe {
    float mirror = 0.0f, side = 0.0f;  // mean indirect irradiance at each panel's vertices
};
Scene MirrorScene(const Material& fm, bool emitter) {
    SceneBuilder b;
    uint32_t floor = b.AddPbrMaterial("floor", fm.baseColor, fm.metallic, fm.roughness);
    uint32_t black = b.AddMaterial("black", glm::vec3(0.0f));
    b.AddTiledQuad("floor", floor, {-0.3f, 0, -0.3f}, {0.6f, 0, 0}, {0, 0, 0.6f}, 2, 2, {0, 1, 0});
    const float h = 0.3f;  // panel half size
    auto panel = [&](const std::string& name, glm::vec3 c, glm::vec3 u, glm::vec3 v) {
        b.AddQuad(name, black, c - h * u - h * v, c + h * u - h * v, c + h * u + h * v,
                  c - h * u + h * v, glm::vec3(0.0f), 2);
    };
    const float s = 0.70710678f;
    panel("mirror", {1, 1, 0}, {0, 0, 1}, {s, -s, 0});
    panel("side", {0, 1, 1}, {1, 0, 0}, {0, -s, s});
    const glm::vec3 lamp(-1.0f, 1.0f, 0.0f);
    if (emitter) {
        uint32_t light = b.AddMaterial("light", glm::vec3(0.0f), glm::vec3(50.0f));
        const glm::vec3 u(0, 0, 0.1f), v(0.0707f, 0.0707f, 0);
        b.AddQuad("lamp", light, lamp - u - v, lamp + u - v, lamp + u + v, lamp - u + v,
                  glm::vec3(0.0f));
    } else {
        b.AddLight(testing::MakeLight("lamp", LightType::kPoint, lamp, {1, -1, 0}, 20.0f));
    }
    return b.Build();
}
// Means over the vertices of the primitives of nodes "mirror" and "side".
MirrorProbe Panels(const Scene& scene, const std::vector<std::vector<glm::vec3>>& perVertex) {
    MirrorProbe p;
    for (size_t k = 0; k < scene.primitives.size(); ++k) {
        const std::string& node = scene.primitives[k].node;
        if (node != "mirror" && node != "side") continue;
        float sum = 0.0f;
        for (const glm::vec3& e : perVertex[k]) sum += Mean(e);
        (node == "mirror" ? p.mirror : p.side) = sum / perVertex[k].size();
    }
    return p;
}
MirrorProbe ProbeFloor(const Material& floorMaterial, bool emitter, DeviceChoice device,
                       int bins = 256) {
    Scene scene = MirrorScene(floorMaterial, emitter);
    SolverSettings settings = CpuSettings(bins, 0.1f);
    settings.device = device;
    SetOption(settings.options, "tables", "fp32");  // Glossy.LavapipeMatchesTheCpuSolver: 1e-4
    SetOption(settings.options, "oracle", 0.5f);
    settings.validation = true;
    auto solver = CreateSolver(scene, settings);
    solver->Iterate(4);
    auto e = solver->SurfelIrradiance(Channel::kIndirect);
    std::vector<std::vector<glm::vec3>> perVertex;
    for (size_t k = 0; k < scene.primitives.size(); ++k)
        perVertex.push_back(PrimitiveIrradiance(solver->GetSurfels(), e, scene, k));
    if (auto* a = dynamic_cast<AntiradianceSolver*>(solver.get()))
        for (const auto& m : a->ValidationMessages()) ADD_FAILURE() << "validation: " << m;
    return Panels(scene, perVertex);
}
MirrorProbe ReferenceProbe(const Material& floorMaterial, bool emitter) {
    Scene scene = MirrorScene(floorMaterial, emitter);
    ReferenceSettings rs;
    rs.samples = 2048;
    return Panels(scene, RenderReference(scene, rs).irradiance);
}

// A glossy floor sends more light into the mirror direction than a diffuse floor of equal
// albedo, and less to the side; for light from an emitting patch (through L_in and the
// lobe rows) and from a point light (its exact mirror direction, glossyDirect).
TEST(Glossy, FloorReflectsMoreIntoTheMirrorDirection) {
    const Material diffuse = DiffuseMaterial("d", glm::vec3(0.5f));
    const Material glossy = PbrMaterial("g", glm::vec3(0.5f), 1.0f, 0.3f);  // F0 = 0.5
    const Material black = DiffuseMaterial("b", glm::vec3(0.0f));
    for (bool emitter : {true, false}) {
        // What the floor reflects: the panels' light less what they get with a black floor
        // (the emitting patch lights them directly too).
        MirrorProbe none = ProbeFloor(black, emitter, DeviceChoice::kCpu);
        MirrorProbe d = ProbeFloor(diffuse, emitter, DeviceChoice::kCpu);
        MirrorProbe g = ProbeFloor(glossy, emitter, DeviceChoice::kCpu);
        for (MirrorProbe* p : {&d, &g}) p->mirror -= none.mirror, p->side -= none.side;
        std::printf(
            "%s: mirror panel diffuse %.4f glossy %.4f; side panel diffuse %.4f glossy "
            "%.4f\n",
            emitter ? "emitter" : "point light", d.mirror, g.mirror, d.side, g.side);
        EXPECT_GT(g.mirror, 2.0f * d.mirror) << (emitter ? "emitter" : "point light");
        EXPECT_LT(g.side, 0.5f * d.side) << (emitter ? "emitter" : "point light");
        // The path-traced lobe (the material's own exponent, not widened to the bins) puts
        // about as much light on the mirror panel. Measured (mirror panel, solver against
        // reference): emitter −15% / −26% / −7% / −8% at 128 / 256 / 512 / 1024 bins (the
        // emitter's light reaches the floor through binned L_in, and where its mirror bins
        // fall against the panel varies with the bin set), point light +15 / +5 / +7 / +5%
        // (exact mirror directions). Compared at 512 bins, within 15%.
        MirrorProbe r = ReferenceProbe(glossy, emitter);
        MirrorProbe rNone = ReferenceProbe(black, emitter);
        r.mirror -= rNone.mirror, r.side -= rNone.side;
        MirrorProbe fine = ProbeFloor(glossy, emitter, DeviceChoice::kCpu, 512);
        MirrorProbe fineNone = ProbeFloor(black, emitter, DeviceChoice::kCpu, 512);
        fine.mirror -= fineNone.mirror;
        std::printf("  reference: mirror panel glossy %.4f, side %.4f; solver at 512 bins %.4f\n",
                    r.mirror, r.side, fine.mirror);
        EXPECT_NEAR(fine.mirror, r.mirror, 0.15f * r.mirror);
    }
}

// Energy: a room of glossy metal (F0 = 1, no diffuse) under a constant sky through half a
// ceiling. Nothing absorbs, so radiance can nowhere exceed the sky's: E ≤ π·L on every
// wall. (The normalised Phong lobe loses what it sends below the horizon, so E may fall
// short of π·L, and in a metal room that loss compounds over many bounces: E ≈ 0.24 π·L,
// which the path-traced reference confirms in the next test.) The same for a white glossy
// dielectric, whose diffuse layer and 4% lobe add up to 1 and which loses little.
TEST(Glossy, SkyFurnaceNeverCreatesLight) {
    for (float metallic : {1.0f, 0.0f}) {
        SceneBuilder b;
        Scene scene =
            testing::SkyFurnaceRoom(b, b.AddPbrMaterial("white", glm::vec3(1.0f), metallic, 0.5f));
        SolverSettings settings = CpuSettings(128, 0.1f);
        SetOption(settings.options, "oracle", 0.25f);
        auto solver = CreateSolver(scene, settings);
        solver->Iterate(60);
        auto e = solver->SurfelIrradiance();
        const auto& s = solver->GetSurfels();
        double sum = 0, most = 0;
        size_t n = 0;
        for (size_t i = 0; i < s.size(); ++i) {
            if (s.areas[i] <= 0.0f) continue;
            sum += Mean(e[i]) / kPi;
            most = std::max(most, double(Mean(e[i])) / kPi);
            ++n;
        }
        std::printf("glossy sky furnace (metallic %.0f): E/πL mean %.4f, max %.4f\n", metallic,
                    sum / n, most);
        // Single surfels carry the furnace test's discretisation error (≤ 5%, as there).
        EXPECT_LT(most, 1.05) << "metallic " << metallic;
        EXPECT_LT(sum / n, 1.01) << "metallic " << metallic;
        if (metallic == 0.0f) {
            EXPECT_GT(sum / n, 0.8);
        }
    }
}

// The reference's lobe: the same room, path traced: E ≤ π·L within its noise, and the
// solver agrees with it.
TEST(Glossy, ReferenceKeepsTheFurnaceBoundAndAgreesWithTheSolver) {
    SceneBuilder b;
    Scene scene =
        testing::SkyFurnaceRoom(b, b.AddPbrMaterial("white", glm::vec3(1.0f), 1.0f, 0.5f), 4);
    ReferenceSettings rs;
    rs.samples = 4096;
    ReferenceResult ref = RenderReference(scene, rs);
    double over = 0;
    for (size_t p = 0; p < 2; ++p)
        for (size_t i = 0; i < ref.irradiance[p].size(); ++i)
            over = std::max(
                over,
                double(Mean(ref.irradiance[p][i]) - 5.0f * Mean(ref.standardError[p][i])) / kPi);
    EXPECT_LT(over, 1.0) << "a path-traced E exceeds π·L by more than 5σ";

    SolverSettings settings = CpuSettings(128, 0.1f);
    SetOption(settings.options, "oracle", 0.25f);
    auto solver = CreateSolver(scene, settings);
    solver->Iterate(60);
    auto e = solver->SurfelIrradiance();
    std::vector<glm::vec3> a, r;
    for (size_t p = 0; p < 2; ++p) {
        auto mine = PrimitiveIrradiance(solver->GetSurfels(), e, scene, p);
        a.insert(a.end(), mine.begin(), mine.end());
        r.insert(r.end(), ref.irradiance[p].begin(), ref.irradiance[p].end());
    }
    double rel = testing::RelativeRms(a, r);
    float meanA = 0, meanR = 0;
    for (size_t i = 0; i < a.size(); ++i) meanA += Mean(a[i]) / kPi, meanR += Mean(r[i]) / kPi;
    std::printf("glossy room: E/πL solver %.4f reference %.4f, relative RMS %.4f\n",
                meanA / a.size(), meanR / r.size(), rel);
    // Measured 6.4% (means 0.246 and 0.240; 8.6% before issue 18): the lobe on 128 bins and
    // the corners' usual discretisation error (the diffuse furnace's worst surfels are 4% off).
    EXPECT_LT(rel, 0.12);
    EXPECT_NEAR(meanA / a.size(), meanR / r.size(), 0.08 * meanR / r.size());
}

// The glossy local pass and the reflected direct light on lavapipe, validation on, equal the
// CPU back end's.
TEST(Glossy, LavapipeMatchesTheCpuSolver) {
    const Material glossy = PbrMaterial("g", glm::vec3(0.5f), 1.0f, 0.4f);
    for (bool emitter : {true, false}) {
        MirrorProbe c = ProbeFloor(glossy, emitter, DeviceChoice::kCpu);
        MirrorProbe v = ProbeFloor(glossy, emitter, DeviceChoice::kLavapipe);
        EXPECT_NEAR(v.mirror, c.mirror, 1e-4f * c.mirror);
        EXPECT_NEAR(v.side, c.side, 1e-4f * c.side + 1e-6f);
    }
}

}  // namespace
}  // namespace penumbra
