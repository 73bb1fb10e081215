// The gather stage's emitter direct light (gather/emitter_direct.h) against closed forms:
// a small patch (the point-to-point formula), a square emitter over its centre (the
// differential-area-to-parallel-rectangle form factor), the half of it an opaque edge leaves,
// an umbra; and the sampling's determinism.
#include "gather/emitter_direct.h"

#include <gtest/gtest.h>

#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <memory>
#include <numbers>

#include "base/check.h"
#include "scene/scene_builder.h"
#include "scene/surfels.h"

namespace penumbra {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

// A square emitter of side `side`, radiance `le`, centred at height `h` above the origin,
// facing down; `blocker` adds an opaque quad at height h/2 over x < 0.
Scene Emitter(float side, float h, float le, bool blocker = false) {
    SceneBuilder b;
    const uint32_t light = b.AddMaterial("light", glm::vec3(0.0f), glm::vec3(le));
    const float s = side / 2;
    b.AddQuad("emitter", light, {-s, h, -s}, {s, h, -s}, {s, h, s}, {-s, h, s}, {0, 0, 0});
    if (blocker) {
        const uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
        b.AddQuad("edge", grey, {-5, h / 2, -5}, {0, h / 2, -5}, {0, h / 2, 5}, {-5, h / 2, 5},
                  {0, 0, 0});
    }
    return b.Build();
}

// Irradiance π L F at a point under the corner of a parallel a × b rectangle at height c:
// F = (1/2π)[X/√(1+X²) atan(Y/√(1+X²)) + Y/√(1+Y²) atan(X/√(1+Y²))], X = a/c, Y = b/c.
float CornerIrradiance(float le, float a, float b, float c) {
    const float x = a / c, y = b / c;
    const float sx = std::sqrt(1 + x * x), sy = std::sqrt(1 + y * y);
    const float f = (x / sx * std::atan(y / sx) + y / sy * std::atan(x / sy)) / (2 * kPi);
    return kPi * le * f;
}

float At(const Scene& scene, glm::vec3 point, glm::vec3 normal, int rays = 256) {
    RayScene rs(scene);
    EmitterDirectSettings s;
    s.rays = rays;
    return EmitterIrradiance(rs, {point}, {normal}, s)[0].x;
}

TEST(EmitterDirect, SmallPatchMatchesThePointToPointFormula) {
    const Scene scene = Emitter(0.02f, 1.0f, 10.0f);
    const float area = 0.02f * 0.02f;
    // Straight below: L A / h². One metre aside: cosθ_x = cosθ_y = 1/√2, d² = 2.
    EXPECT_NEAR(At(scene, {0, 0, 0}, {0, 1, 0}), 10.0f * area, 0.005f * 10.0f * area);
    EXPECT_NEAR(At(scene, {1, 0, 0}, {0, 1, 0}), 10.0f * area / 4, 0.005f * 10.0f * area / 4);
    // Facing away, or behind the emitter: nothing.
    EXPECT_EQ(At(scene, {0, 0, 0}, {0, -1, 0}), 0.0f);
    EXPECT_EQ(At(scene, {0, 2, 0}, {0, -1, 0}), 0.0f);
}

TEST(EmitterDirect, SquareEmitterMatchesTheFormFactor) {
    // A 1 m square 0.5 m above the point: four corners of 0.5 × 0.5 m.
    const float exact = 4 * CornerIrradiance(3.0f, 0.5f, 0.5f, 0.5f);
    const float e = At(Emitter(1.0f, 0.5f, 3.0f), {0, 0, 0}, {0, 1, 0});
    std::printf("square emitter: E %.5f, closed form %.5f (%.3f%%)\n", e, exact,
                100 * (e / exact - 1));
    EXPECT_NEAR(e, exact, 0.01f * exact);
}

TEST(EmitterDirect, AnOpaqueEdgeLeavesHalfAndAnUmbraNothing) {
    const Scene scene = Emitter(1.0f, 0.5f, 3.0f, true);
    const float full = 4 * CornerIrradiance(3.0f, 0.5f, 0.5f, 0.5f);
    // Under the edge, the point sees exactly the x > 0 half of the emitter. The edge makes
    // the integrand discontinuous: 256 rays land within 2.3% here, 4,096 within 0.2%.
    for (int rays : {256, 4096}) {
        const float half = At(scene, {0, 0, 0}, {0, 1, 0}, rays);
        std::printf("under the edge, %d rays: E %.5f, half the unblocked %.5f\n", rays, half,
                    full / 2);
        EXPECT_NEAR(half, full / 2, (rays == 256 ? 0.04f : 0.01f) * full / 2);
    }
    // Far under the blocker no ray gets through.
    EXPECT_EQ(At(scene, {-3, 0, 0}, {0, 1, 0}), 0.0f);
}

TEST(EmitterDirect, SameSeedSameAnswerAndNoEmitterNoLight) {
    const Scene scene = Emitter(1.0f, 0.5f, 3.0f, true);
    RayScene rs(scene);
    std::vector<glm::vec3> points, normals;
    for (int i = 0; i < 200; ++i) {
        points.emplace_back(-1.0f + 0.01f * i, 0.0f, 0.1f);
        normals.emplace_back(0, 1, 0);
    }
    const auto a = EmitterIrradiance(rs, points, normals);
    const auto b = EmitterIrradiance(rs, points, normals);
    for (size_t i = 0; i < a.size(); ++i) ASSERT_EQ(a[i], b[i]) << i;

    SceneBuilder dark;
    dark.AddQuad("floor", dark.AddMaterial("grey", glm::vec3(0.5f)), {-1, 0, -1}, {1, 0, -1},
                 {1, 0, 1}, {-1, 0, 1}, {0, 1, 0});
    const Scene unlit = dark.Build();
    RayScene none(unlit);
    EXPECT_EQ(EmitterIrradiance(none, {{0, 1, 0}}, {{0, -1, 0}})[0], glm::vec3(0.0f));
}

// The split between the two kinds of rays follows where the emitters are: inside a closed
// room whose every wall emits, cosine rays alone would be exact and light rays only add
// noise, so most rays are cosine rays; under a small far emitter most are light rays. The
// estimate is unbiased whatever the split: the room's points get π L either way, with less
// spread than half each gave (the white furnace's worst vertex was 1.15% at half each).
TEST(EmitterDirect, TheSplitFollowsWhereTheEmittersAre) {
    EmitterDirectSettings settings;  // 256 rays
    const Scene patch = Emitter(0.02f, 1.0f, 10.0f);
    RayScene small(patch);
    const auto under = EmitterCosineRays(small, {{0, 0, 0}}, {{0, 1, 0}}, settings);
    ASSERT_EQ(under.size(), 1u);
    EXPECT_EQ(under[0], 32);  // the least: an eighth

    SceneBuilder b;
    const uint32_t m = b.AddMaterial("wall", glm::vec3(0.0f), glm::vec3(1.0f));
    const glm::vec3 inside(0.5f);
    b.AddQuad("floor", m, {0, 0, 0}, {1, 0, 0}, {1, 0, 1}, {0, 0, 1}, inside);
    b.AddQuad("ceiling", m, {0, 1, 0}, {1, 1, 0}, {1, 1, 1}, {0, 1, 1}, inside);
    b.AddQuad("w0", m, {0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, inside);
    b.AddQuad("w1", m, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}, inside);
    b.AddQuad("w2", m, {0, 0, 0}, {0, 0, 1}, {0, 1, 1}, {0, 1, 0}, inside);
    b.AddQuad("w3", m, {1, 0, 0}, {1, 0, 1}, {1, 1, 1}, {1, 1, 0}, inside);
    const Scene room = b.Build();
    RayScene rs(room);
    // Points on the floor, from its middle into a corner.
    std::vector<glm::vec3> points, normals;
    for (int i = 0; i < 40; ++i) {
        const float f = 0.5f - 0.012f * i;
        points.emplace_back(f, 0.0f, f * 0.9f + 0.02f);
        normals.emplace_back(0, 1, 0);
    }
    const auto split = EmitterCosineRays(rs, points, normals, settings);
    for (size_t i = 0; i < split.size(); ++i) EXPECT_EQ(split[i], 224) << i;
    auto spread = [&](const std::vector<uint16_t>& s) {
        const auto e = EmitterDirect(settings).Trace(rs, points, normals, {}, s);
        double sum2 = 0, sum = 0;
        for (const glm::vec3& v : e) {
            const double rel = v.x / kPi - 1.0;
            sum += rel, sum2 += rel * rel;
        }
        std::printf("  mean %+.4f%%, relative RMS %.4f%%\n", 100 * sum / e.size(),
                    100 * std::sqrt(sum2 / e.size()));
        return std::sqrt(sum2 / e.size());
    };
    std::printf("closed emitting room, the split:\n");
    const double adaptive = spread(split);
    std::printf("half each:\n");
    const double half = spread(std::vector<uint16_t>(points.size(), 128));
    EXPECT_LT(adaptive, 0.005);
    EXPECT_LT(adaptive, 0.6 * half);
}

// After each of a run of moves (a box into the emitter's light, under it, away, back) the
// kept outcomes, traced again only near what moved, give what a fresh trace gives: the
// shadow rays the box cuts or frees, the cosine rays that met it or meet it now.
TEST(EmitterDirect, RetraceAfterMovesMatchesAFreshTrace) {
    SceneBuilder b;
    const uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
    const uint32_t light = b.AddMaterial("light", glm::vec3(0.0f), glm::vec3(4.0f));
    b.AddQuad("floor", grey, {-1, 0, -1}, {1, 0, -1}, {1, 0, 1}, {-1, 0, 1}, {0, 1, 0});
    b.AddQuad("wall", grey, {-1, 0, -1}, {-1, 1, -1}, {-1, 1, 1}, {-1, 0, 1}, {1, 0, 0});
    b.AddQuad("emitter", light, {-0.3f, 1, -0.3f}, {0.3f, 1, -0.3f}, {0.3f, 1, 0.3f},
              {-0.3f, 1, 0.3f}, {0, 0, 0});
    b.AddBox("box", grey, {0.7f, 0.15f, 0.0f}, {0.2f, 0.3f, 0.2f});
    b.SetDynamic("box", {0.7f, 0.15f, 0.0f});
    Scene scene = b.Build();
    const int box = FindNode(scene, "box");
    const glm::mat4 home = scene.nodes[box].local;
    EmitterDirectSettings settings;
    settings.rays = 64;
    Surfels surfels = RefineScene(scene, 0.1f);
    auto rays = std::make_unique<RayScene>(scene, surfels);
    EmitterDirect kept(settings);
    // The split between light and cosine rays stays as it was at the start (the gather stage
    // keeps it through moves): the fresh traces take it too.
    const std::vector<uint16_t> split =
        EmitterCosineRays(*rays, surfels.positions, surfels.normals, settings);
    ASSERT_EQ(split.size(), surfels.size());
    kept.Trace(*rays, surfels.positions, surfels.normals, {}, split);
    size_t tracedInAll = 0;
    for (const glm::vec3 to : {glm::vec3(-0.7f, 0.3f, 0.0f), glm::vec3(-0.7f, 0.6f, 0.1f),
                               glm::vec3(0.2f, 0.0f, 0.9f), glm::vec3(0.0f)}) {
        SetNodeTransform(scene, box, glm::translate(glm::mat4(1.0f), to) * home);
        Surfels now = RefineScene(scene, 0.1f);
        ASSERT_EQ(now.size(), surfels.size());
        std::vector<uint8_t> moved(now.size(), 0);
        Bounds was, is;
        for (size_t i = 0; i < now.size(); ++i)
            if (now.positions[i] != surfels.positions[i]) {
                moved[i] = 1;
                was.Add(surfels.positions[i]);
                is.Add(now.positions[i]);
            }
        surfels = std::move(now);
        rays->Update(surfels);
        size_t traced = 0;
        const auto again =
            kept.Retrace(*rays, surfels.positions, surfels.normals, moved, {was, is}, &traced);
        const RayScene freshRays(scene, surfels);
        const auto fresh =
            EmitterDirect(settings).Trace(freshRays, surfels.positions, surfels.normals, {}, split);
        float top = 0.0f, apart = 0.0f;
        for (size_t i = 0; i < fresh.size(); ++i) {
            top = std::max(top, fresh[i].x);
            apart = std::max(apart, glm::length(again[i] - fresh[i]));
        }
        EXPECT_GT(top, 1.0f);
        EXPECT_LT(apart, 1e-5f * top) << "box at " << to.x << ", " << to.y << ", " << to.z;
        EXPECT_GT(traced, 0u);
        tracedInAll += traced;
    }
    // Far fewer rays than four fresh traces.
    EXPECT_LT(tracedInAll, surfels.size() * settings.rays);
}

TEST(EmitterDirect, RefusesBadArguments) {
    const Scene scene = Emitter(1.0f, 0.5f, 3.0f);
    RayScene rs(scene);
    EmitterDirectSettings s;
    s.rays = 0;
    EXPECT_THROW(EmitterIrradiance(rs, {{0, 0, 0}}, {{0, 1, 0}}, s), Error);
    EXPECT_THROW(EmitterIrradiance(rs, {{0, 0, 0}}, {}), Error);
}

}  // namespace
}  // namespace penumbra
