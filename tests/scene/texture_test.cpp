// Colour maps (scene/texture.h): sampling and averaging, and that a base colour or emissive
// texture lights a scene as the geometry it draws would: the same scene with the texture's
// halves made separate surfaces is the check, for the reference and for a bake.
#include "scene/texture.h"

#include <gtest/gtest.h>

#include "gather/gather_stage.h"
#include "output/irradiance_writer.h"
#include "reference/path_tracer.h"
#include "scene/scene_builder.h"
#include "scene/surfels.h"
#include "test_util.h"

namespace penumbra {
namespace {

// A map `w` texels wide and one high: `left` on its left half, `right` on its right.
TintMap Halves(int w, glm::vec3 left, glm::vec3 right, Wrap wrap = Wrap::kClamp) {
    std::vector<glm::vec3> texels(w);
    for (int i = 0; i < w; ++i) texels[i] = i < w / 2 ? left : right;
    return TintMap(w, 1, std::move(texels), wrap, wrap);
}

TEST(Textures, TintsAreRelativeToTheMean) {
    const TintMap map = Halves(4, glm::vec3(0.8f, 0.4f, 0.0f), glm::vec3(0.2f, 0.4f, 0.0f));
    EXPECT_NEAR(map.Mean().x, 0.5f, 1e-6f);
    EXPECT_NEAR(map.Mean().y, 0.4f, 1e-6f);
    EXPECT_EQ(map.Mean().z, 0.0f);
    // At texel centres: the texel over the mean; a zero channel stays zero.
    const glm::vec3 a = map.At({0.125f, 0.5f}), d = map.At({0.875f, 0.5f});
    EXPECT_NEAR(a.x, 1.6f, 1e-5f);
    EXPECT_NEAR(a.y, 1.0f, 1e-5f);
    EXPECT_EQ(a.z, 0.0f);
    EXPECT_NEAR(d.x, 0.4f, 1e-5f);
    // Bilinear between the two middle texels.
    EXPECT_NEAR(map.At({0.5f, 0.5f}).x, 1.0f, 1e-5f);
    // Averaged over the whole square (two triangles) and over one half.
    const glm::vec2 c00(0, 0), c10(1, 0), c11(1, 1), c01(0, 1);
    const float whole = 0.5f * (map.Over(c00, c10, c11).x + map.Over(c00, c11, c01).x);
    EXPECT_NEAR(whole, 1.0f, 0.02f);
    EXPECT_NEAR(map.Over({0.05f, 0}, {0.25f, 1}, {0.45f, 0}).x, 1.6f, 0.05f);
}

TEST(Textures, WrapModes) {
    std::vector<glm::vec3> texels = {glm::vec3(1), glm::vec3(2), glm::vec3(3), glm::vec3(4)};
    const TintMap repeat(4, 1, texels, Wrap::kRepeat, Wrap::kRepeat);
    const TintMap clamp(4, 1, texels, Wrap::kClamp, Wrap::kClamp);
    const TintMap mirror(4, 1, texels, Wrap::kMirror, Wrap::kMirror);
    const float mean = 2.5f;
    EXPECT_NEAR(repeat.At({1.125f, 0.5f}).x, 1.0f / mean, 1e-5f);
    EXPECT_NEAR(repeat.At({-0.875f, 0.5f}).x, 1.0f / mean, 1e-5f);
    EXPECT_NEAR(clamp.At({1.125f, 0.5f}).x, 4.0f / mean, 1e-5f);
    EXPECT_NEAR(clamp.At({-3.0f, 0.5f}).x, 1.0f / mean, 1e-5f);
    EXPECT_NEAR(mirror.At({1.125f, 0.5f}).x, 4.0f / mean, 1e-5f);  // 1 + ⅛ mirrors to ⅞
    EXPECT_NEAR(mirror.At({1.375f, 0.5f}).x, 3.0f / mean, 1e-5f);
    // Far outside [0, 1]: no overflow, the same answers.
    EXPECT_NEAR(repeat.At({1e9f + 0.125f, 0.5f}).x, repeat.At({0.125f, 0.5f}).x, 0.6f);
    EXPECT_TRUE(std::isfinite(mirror.At({-3e9f, 1e9f}).x));
    EXPECT_THROW(TintMap(3, 2, texels, Wrap::kRepeat, Wrap::kRepeat), Error);
}

// Texture coordinates for a primitive from its positions: u along x from x0 over `width`, v
// along z from z0 over `depth`.
void PlanarUv(Primitive& p, float x0, float width, float z0, float depth) {
    std::vector<glm::vec2>& uv = p.texcoords.emplace_back();
    for (const glm::vec3& x : p.positions) uv.emplace_back((x.x - x0) / width, (x.z - z0) / depth);
}

const std::vector<glm::vec3>& Of(const IrradianceFile& f, const std::string& node) {
    for (const IrradianceRecord& r : f.primitives)
        if (r.node == node) return r.irradiance;
    throw Error("no node " + node);
}

IrradianceFile Truth(const Scene& scene) {
    ReferenceSettings rs;
    rs.samples = 1024;
    return ReferenceFile(scene, rs);
}

IrradianceFile Bake(const Scene& scene, const std::string& solverName = "antiradiance",
                    DeviceChoice device = DeviceChoice::kCpu, bool gather = true) {
    SolverSettings s;
    s.solver = solverName;
    s.device = device;
    s.validation = device != DeviceChoice::kCpu;
    s.elementSize = 0.1f;
    GatherSettings g;
    if (!gather) g.gatherRays = 0, g.emitterRays = 0;
    GatherStage solver(CreateSolver(scene, s), scene, g);
    IterateUntilConverged(solver, 1e-3, 200);
    return ToIrradianceFile(scene, CollectIrradiance(scene, solver, Channel::kIndirect));
}

// Node `node`'s irradiance against the reference of `split` (the texture's halves made
// separate surfaces): the mapped scene's reference and bake, the split scene's own bake,
// and a bake with the map's mean colour instead of the map.
struct Errors {
    double reference, baked, geometry, unmapped;
};
Errors AgainstTheSplitScene(const Scene& mapped, const Scene& split, const Scene& mean,
                            const std::string& node) {
    const std::vector<glm::vec3> truth = Of(Truth(split), node);
    Errors e{testing::RelativeRms(Of(Truth(mapped), node), truth),
             testing::RelativeRms(Of(Bake(mapped), node), truth),
             testing::RelativeRms(Of(Bake(split), node), truth),
             testing::RelativeRms(Of(Bake(mean), node), truth)};
    std::printf(
        "%s against the split scene's reference: mapped reference %.2f%%, mapped bake "
        "%.2f%%, the split scene's bake %.2f%%, the mean's bake %.2f%%\n",
        node.c_str(), 100 * e.reference, 100 * e.baked, 100 * e.geometry, 100 * e.unmapped);
    return e;
}

// A 2 m floor and a 1 m panel 1 m above it, facing it. `mapped`: the panel's emission map
// is lit on its left half (x < 0) and dark on its right; else (`split`) the same as two
// panels, the left emitting and the right black; else one panel at the map's mean.
enum class Panel { kMapped, kSplit, kMean };
Scene EmitterOverFloor(Panel panel) {
    SceneBuilder b;
    const uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
    b.AddTiledQuad("floor", grey, {-1, 0, -1}, {2, 0, 0}, {0, 0, 2}, 8, 8, {0, 1, 0});
    const glm::vec3 le(8.0f);
    if (panel == Panel::kSplit) {
        const uint32_t lit = b.AddMaterial("lit", glm::vec3(0.0f), le);
        const uint32_t dark = b.AddMaterial("dark", glm::vec3(0.0f));
        b.AddTiledQuad("panel", lit, {-0.5f, 1, -0.5f}, {0.5f, 0, 0}, {0, 0, 1}, 2, 4, {0, 0, 0});
        b.AddTiledQuad("panel_dark", dark, {0, 1, -0.5f}, {0.5f, 0, 0}, {0, 0, 1}, 2, 4, {0, 0, 0});
        return b.Build();
    }
    const uint32_t lamp = b.AddMaterial("lamp", glm::vec3(0.0f), 0.5f * le);
    b.AddTiledQuad("panel", lamp, {-0.5f, 1, -0.5f}, {1, 0, 0}, {0, 0, 1}, 4, 4, {0, 0, 0});
    Scene scene = b.Build();
    if (panel == Panel::kMapped) {
        scene.maps.push_back(Halves(64, glm::vec3(1.0f), glm::vec3(0.0f)));
        scene.materials[lamp].emissionMap = 0;
        scene.materials[lamp].emission = le * scene.maps[0].Mean();
        PlanarUv(scene.primitives[scene.nodes[FindNode(scene, "panel")].primitives[0]], -0.5f, 1.0f,
                 -0.5f, 1.0f);
    }
    return scene;
}

// The panel's emission map puts its light where the map is lit: the floor receives what
// it receives from the left half alone, in the reference and in a bake (first shot and
// final gather), and unlike a panel at the map's mean.
TEST(Textures, AnEmissionMapLightsLikeTheSurfaceItDraws) {
    const Errors e =
        AgainstTheSplitScene(EmitterOverFloor(Panel::kMapped), EmitterOverFloor(Panel::kSplit),
                             EmitterOverFloor(Panel::kMean), "floor");
    EXPECT_LT(e.reference, 0.03);
    EXPECT_LT(e.baked, std::max(0.05, e.geometry + 0.02));
    EXPECT_GT(e.unmapped, 0.2);
}

// A floor whose base colour map is white on its left half and black on its right, a panel
// above it shining down and a ceiling above that: the ceiling sees only the floor's bounce.
// `split`: the same floor as two surfaces, white and black; `mean`: one at the map's mean.
enum class Floor { kMapped, kSplit, kMean };
Scene BounceFromFloor(Floor floor) {
    SceneBuilder b;
    const uint32_t lamp = b.AddMaterial("lamp", glm::vec3(0.0f), glm::vec3(20.0f));
    b.AddTiledQuad("panel", lamp, {-0.25f, 1, -0.25f}, {0.5f, 0, 0}, {0, 0, 0.5f}, 2, 2, {0, 0, 0});
    const uint32_t grey = b.AddMaterial("grey", glm::vec3(0.0f));
    b.AddTiledQuad("ceiling", grey, {-1, 1.5f, -1}, {2, 0, 0}, {0, 0, 2}, 8, 8, {0, 0, 0});
    if (floor == Floor::kSplit) {
        const uint32_t white = b.AddMaterial("white", glm::vec3(0.9f));
        const uint32_t black = b.AddMaterial("black", glm::vec3(0.0f));
        b.AddTiledQuad("floor", white, {-1, 0, -1}, {1, 0, 0}, {0, 0, 2}, 4, 8, {0, 1, 0});
        b.AddTiledQuad("floor_black", black, {0, 0, -1}, {1, 0, 0}, {0, 0, 2}, 4, 8, {0, 1, 0});
        return b.Build();
    }
    const uint32_t tex = b.AddMaterial("textured", glm::vec3(0.45f));
    b.AddTiledQuad("floor", tex, {-1, 0, -1}, {2, 0, 0}, {0, 0, 2}, 8, 8, {0, 1, 0});
    Scene scene = b.Build();
    if (floor == Floor::kMapped) {
        scene.maps.push_back(Halves(64, glm::vec3(0.9f), glm::vec3(0.0f)));
        scene.materials[tex].baseColorMap = 0;
        PlanarUv(scene.primitives[scene.nodes[FindNode(scene, "floor")].primitives[0]], -1.0f, 2.0f,
                 -1.0f, 2.0f);
    }
    return scene;
}

TEST(Textures, ABaseColourMapReflectsLikeTheSurfaceItDraws) {
    const Errors e =
        AgainstTheSplitScene(BounceFromFloor(Floor::kMapped), BounceFromFloor(Floor::kSplit),
                             BounceFromFloor(Floor::kMean), "ceiling");
    EXPECT_LT(e.reference, 0.03);
    // As close as a bake of the drawn geometry itself.
    EXPECT_LT(e.baked, e.geometry + 0.02);
    EXPECT_GT(e.unmapped, 0.15);
}

// The maps reach every solver and back end through the surfels: the implicit solver's answer
// for the mapped floor is its answer for the split floor, and the solver alone (no gather)
// on lavapipe, validation on, is the CPU's.
TEST(Textures, EverySolverAndBackEndReadsTheMaps) {
    const Scene mapped = BounceFromFloor(Floor::kMapped), split = BounceFromFloor(Floor::kSplit);
    const double implicit = testing::RelativeRms(Of(Bake(mapped, "implicit"), "ceiling"),
                                                 Of(Bake(split, "implicit"), "ceiling"));
    const std::vector<glm::vec3> cpu =
        Of(Bake(mapped, "antiradiance", DeviceChoice::kCpu, false), "ceiling");
    const double lavapipe = testing::RelativeRms(
        Of(Bake(mapped, "antiradiance", DeviceChoice::kLavapipe, false), "ceiling"), cpu);
    const double unmapped = testing::RelativeRms(
        Of(Bake(BounceFromFloor(Floor::kMean), "antiradiance", DeviceChoice::kCpu, false),
           "ceiling"),
        cpu);
    std::printf(
        "ceiling: implicit mapped against split %.2f%%; antiradiance alone, lavapipe "
        "against the CPU %.3f%%, the mean's floor against the mapped %.2f%%\n",
        100 * implicit, 100 * lavapipe, 100 * unmapped);
    EXPECT_LT(implicit, 0.03);
    EXPECT_LT(lavapipe, 0.01);
    EXPECT_GT(unmapped, 0.15);  // the maps make a difference the comparison can see
}

// Surfels take the map averaged over their hat functions: on the mapped floor, those well
// inside the white half have the white albedo, those inside the black half none.
TEST(Textures, SurfelsAverageTheMapOverTheirArea) {
    const Scene scene = BounceFromFloor(Floor::kMapped);
    const Surfels s = RefineScene(scene, 0.1f);
    ASSERT_EQ(s.albedoTints.size(), s.size());
    const uint32_t floor = scene.nodes[FindNode(scene, "floor")].primitives[0];
    const Material& m = scene.materials[scene.primitives[floor].material];
    int white = 0, black = 0;
    for (size_t i = s.firstSurfel[floor]; i < s.End(floor); ++i) {
        const float x = s.positions[i].x;
        const float albedo = s.Albedo(m, i).x;
        if (x < -0.15f) {
            EXPECT_NEAR(albedo, 0.9f, 0.01f) << x;
            ++white;
        }
        if (x > 0.15f) {
            EXPECT_NEAR(albedo, 0.0f, 0.01f) << x;
            ++black;
        }
        EXPECT_GE(albedo, 0.0f);
        EXPECT_LE(albedo, 0.9f + 1e-5f);
    }
    EXPECT_GT(white, 50);
    EXPECT_GT(black, 50);
    // Every surfel's emission tint is 1 (no emission map here).
    for (const glm::vec3& t : s.emissionTints) EXPECT_EQ(t, glm::vec3(1.0f));
}

}  // namespace
}  // namespace penumbra
