// The Embree reference against closed forms (a small patch's form factor, the white
// furnace), its standard error against 1/√N, and its determinism.
#include "reference/path_tracer.h"

#include <gtest/gtest.h>

#include <cmath>
#include <numbers>

#include "base/check.h"
#include "scene/scene_builder.h"
#include "test_util.h"

namespace penumbra {
namespace {

using testing::AddUnitRoom;
using testing::Mean;

ReferenceSettings Settings(int samples, uint64_t seed = 1) {
    ReferenceSettings s;
    s.samples = samples;
    s.seed = seed;
    return s;
}

// Index of the vertex of primitive `prim` nearest to `p`.
size_t NearestVertex(const Primitive& prim, glm::vec3 p) {
    size_t best = 0;
    for (size_t i = 1; i < prim.positions.size(); ++i)
        if (glm::length(prim.positions[i] - p) < glm::length(prim.positions[best] - p)) best = i;
    return best;
}

// The unit room with white (ρ 0.7) walls under an emitting ceiling, tiles × tiles a face.
Scene LitRoom(int tiles) {
    SceneBuilder b;
    uint32_t white = b.AddMaterial("white", glm::vec3(0.7f));
    uint32_t light = b.AddMaterial("light", glm::vec3(0.0f), glm::vec3(5.0f));
    AddUnitRoom(b, white, light, tiles);
    return b.Build();
}

// E = L · A · cosθr · cosθe / d² for a 0.06 m emitting square 1 m over a black floor (the
// point formula is within 0.3% of the exact integral here). The 2%, and within
// four standard errors of the estimate.
TEST(Reference, SmallPatchMatchesPointToPointFormula) {
    for (float tilt : {0.0f, 30.0f})
        for (float x : {0.0f, 0.5f}) {
            const float L = 3.0f, side = 0.06f, height = 1.0f;
            SceneBuilder b;
            uint32_t black = b.AddMaterial("black", glm::vec3(0.0f));
            uint32_t emit = b.AddMaterial("emit", glm::vec3(0.0f), glm::vec3(L));
            b.AddQuad("floor", black, {-2, 0, -2}, {2, 0, -2}, {2, 0, 2}, {-2, 0, 2}, {0, 1, 0}, 8);
            const glm::vec3 n = testing::AddTiltedEmitter(b, emit, tilt, side, height);
            const glm::vec3 o(0, height, 0);
            Scene scene = b.Build();
            ReferenceResult r = RenderReference(scene, Settings(4000));
            const Primitive& floor = scene.primitives[0];
            size_t i = NearestVertex(floor, {x, 0, 0});
            ASSERT_NEAR(floor.positions[i].x, x, 1e-6f);
            glm::vec3 d = o - floor.positions[i];
            float dist = glm::length(d);
            float expected =
                L * side * side * (d.y / dist) * glm::dot(n, -d / dist) / (dist * dist);
            float actual = Mean(r.irradiance[0][i]), se = Mean(r.standardError[0][i]);
            EXPECT_NEAR(actual, expected, 0.02f * expected) << "tilt " << tilt << " x " << x;
            EXPECT_NEAR(actual, expected, 4.0f * se + 3e-3f * expected)
                << "tilt " << tilt << " x " << x << " stderr " << se;
        }
}

// Punctual lights: the `direct` channel is the closed form I·att·cosθ/d² (E⊥·cosθ for a
// directional light) at every vertex, exactly (no sampling), away from the shadow of a slab;
// in the slab's umbra it is zero.
TEST(Reference, PunctualLightsMatchClosedForms) {
    PunctualLight point;
    point.name = "lamp";
    point.position = glm::vec3(0.3f, 1.2f, -0.2f);
    point.intensity = 25.0f;
    PunctualLight spot = point;
    spot.name = "spot";
    spot.type = LightType::kSpot;
    spot.direction = glm::normalize(glm::vec3(0.2f, -1.0f, 0.0f));
    spot.innerCone = 0.3f;
    spot.outerCone = 0.5f;
    spot.range = 3.0f;
    PunctualLight sun;
    sun.name = "sun";
    sun.type = LightType::kDirectional;
    sun.position = glm::vec3(0, 3, 0);
    sun.direction = glm::normalize(glm::vec3(0.5f, -1.0f, 0.0f));
    sun.intensity = 800.0f;
    for (const PunctualLight& light : {point, spot, sun}) {
        SceneBuilder b;
        uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
        b.AddQuad("floor", grey, {-2, 0, -2}, {2, 0, -2}, {2, 0, 2}, {-2, 0, 2}, {0, 1, 0}, 16);
        b.AddBox("slab", grey, {-1.2f, 0.5f, 1.2f}, {0.6f, 0.05f, 0.6f});
        b.AddLight(light);
        Scene scene = b.Build();
        const PunctualLight& placed = scene.lights[0];
        ReferenceSettings s = Settings(2);
        s.channel = Channel::kDirect;
        ReferenceResult r = RenderReference(scene, s);
        const Primitive& floor = scene.primitives[0];
        int checked = 0, shadowed = 0;
        for (size_t i = 0; i < floor.positions.size(); ++i) {
            glm::vec3 p = floor.positions[i];
            glm::vec3 toLight = placed.type == LightType::kDirectional
                                    ? -placed.direction
                                    : glm::normalize(placed.position - p);
            // Where the ray to the light crosses the slab's height: inside its square?
            glm::vec3 at = p + toLight * ((0.5f - p.y) / toLight.y);
            bool umbra = std::abs(at.x + 1.2f) < 0.25f && std::abs(at.z - 1.2f) < 0.25f;
            bool edge = std::abs(at.x + 1.2f) < 0.35f && std::abs(at.z - 1.2f) < 0.35f;
            float e = Mean(r.irradiance[0][i]);
            EXPECT_EQ(Mean(r.standardError[0][i]), 0.0f);
            if (umbra) {
                EXPECT_EQ(e, 0.0f) << light.name << " at " << p.x << "," << p.z;
                ++shadowed;
            } else if (!edge && std::abs(p.x) < 1.99f && std::abs(p.z) < 1.99f) {
                // (Boundary vertices are estimated 10⁻³ × diameter inside the floor.)
                float want;
                if (placed.type == LightType::kDirectional) {
                    want = placed.intensity * toLight.y;
                } else {
                    float d = glm::length(placed.position - p);
                    want = placed.intensity * LightAttenuation(placed, -toLight, d) * toLight.y /
                           (d * d);
                }
                EXPECT_NEAR(e, want, 1e-4f * want + 1e-6f) << light.name << " at " << p.x;
                ++checked;
            }
        }
        EXPECT_GT(checked, 200) << light.name;
        EXPECT_GT(shadowed, 0) << light.name;
    }
}

// `total` is `direct` plus `indirect` with the same random streams; the bounce of a point
// light's light reaches a wall the light cannot see.
TEST(Reference, TotalIsDirectPlusIndirect) {
    SceneBuilder b;
    uint32_t white = b.AddMaterial("white", glm::vec3(0.8f));
    b.AddQuad("floor", white, {-1, 0, -1}, {1, 0, -1}, {1, 0, 1}, {-1, 0, 1}, {0, 1, 0}, 4);
    b.AddQuad("wall", white, {1, 0, -1}, {1, 0, 1}, {1, 1, 1}, {1, 1, -1}, {0, 0.5f, 0}, 4);
    PunctualLight spot;
    spot.name = "spot";
    spot.type = LightType::kSpot;
    spot.position = glm::vec3(0.8f, 0.9f, 0.0f);
    spot.direction = glm::normalize(glm::vec3(-0.3f, -1.0f, 0.0f));
    spot.innerCone = 0.5f;
    spot.outerCone = 0.6f;
    spot.intensity = 10.0f;
    b.AddLight(spot);
    Scene scene = b.Build();
    ReferenceResult r[3];
    for (Channel c : {Channel::kIndirect, Channel::kDirect, Channel::kTotal}) {
        ReferenceSettings s = Settings(64);
        s.channel = c;
        r[static_cast<int>(c)] = RenderReference(scene, s);
    }
    const auto &indirect = r[0].irradiance, &direct = r[1].irradiance, &total = r[2].irradiance;
    for (size_t p = 0; p < total.size(); ++p)
        for (size_t i = 0; i < total[p].size(); ++i)
            EXPECT_NEAR(Mean(total[p][i]), Mean(direct[p][i] + indirect[p][i]),
                        1e-5f * Mean(total[p][i]) + 1e-7f);
    size_t v = NearestVertex(scene.primitives[1], {1, 0.5f, 0});
    EXPECT_EQ(Mean(direct[1][v]), 0.0f);
    EXPECT_GT(Mean(indirect[1][v]), 0.05f);
}

// A closed room with blockers, every surface emitting Le with albedo ρ: E = π Le / (1 − ρ)
// at every vertex. Each vertex within 2% and within five standard errors.
TEST(Reference, WhiteFurnace) {
    const float Le = 1.0f, rho = 0.5f;
    SceneBuilder b;
    uint32_t m = b.AddMaterial("furnace", glm::vec3(rho), glm::vec3(Le));
    AddUnitRoom(b, m, m, 4);
    b.AddBox("blocker_a", m, {0.3f, 0.4f, 0.35f}, {0.2f, 0.3f, 0.25f});
    b.AddBox("blocker_b", m, {0.7f, 0.6f, 0.6f}, {0.25f, 0.1f, 0.3f}, 30.0f);
    Scene scene = b.Build();
    ReferenceResult r = RenderReference(scene, Settings(16000));
    const float expected = std::numbers::pi_v<float> * Le / (1.0f - rho);
    size_t n = 0;
    for (size_t p = 0; p < r.irradiance.size(); ++p)
        for (size_t i = 0; i < r.irradiance[p].size(); ++i, ++n) {
            float e = Mean(r.irradiance[p][i]), se = Mean(r.standardError[p][i]);
            EXPECT_NEAR(e, expected, 0.02f * expected) << scene.primitives[p].node << " " << i;
            EXPECT_NEAR(e, expected, 5.0f * se + 1e-4f) << scene.primitives[p].node << " " << i;
        }
    EXPECT_GT(n, 100u);
}

// Sixteen times the samples → a quarter of the standard error (√16), within 10%; and the
// low-sample estimates scatter around the high-sample ones as their standard errors say.
TEST(Reference, StandardErrorShrinksAsInverseSqrtN) {
    Scene scene = LitRoom(4);
    ReferenceResult lo = RenderReference(scene, Settings(64, 7));
    ReferenceResult hi = RenderReference(scene, Settings(1024, 8));
    double seLo = 0, seHi = 0;
    size_t n = 0, within2 = 0;
    for (size_t p = 0; p < lo.irradiance.size(); ++p)
        for (size_t i = 0; i < lo.irradiance[p].size(); ++i, ++n) {
            seLo += Mean(lo.standardError[p][i]);
            seHi += Mean(hi.standardError[p][i]);
            float diff = std::abs(lo.irradiance[p][i].x - hi.irradiance[p][i].x);
            float se = std::hypot(lo.standardError[p][i].x, hi.standardError[p][i].x);
            within2 += diff <= 2.0f * se;
        }
    double ratio = seLo / seHi;
    EXPECT_NEAR(ratio, 4.0, 0.4) << "mean stderr 64 samples " << seLo / n << ", 1024 " << seHi / n;
    // A normal estimate falls within 2σ 95% of the time.
    EXPECT_GT(double(within2) / n, 0.88) << within2 << " of " << n;
}

TEST(Reference, DeterministicForASeedWhateverTheThreadCount) {
    Scene scene = LitRoom(2);
    ReferenceSettings one = Settings(32, 3), two = Settings(32, 3), other = Settings(32, 4);
    one.threads = 1;
    two.threads = 2;
    ReferenceResult a = RenderReference(scene, one), c = RenderReference(scene, two);
    ReferenceResult d = RenderReference(scene, other);
    EXPECT_EQ(a.irradiance, c.irradiance);
    EXPECT_EQ(a.standardError, c.standardError);
    EXPECT_NE(a.irradiance, d.irradiance);
    EXPECT_GT(a.stats.rays, 0u);
}

TEST(Reference, RejectsBadSettings) {
    SceneBuilder b;
    AddUnitRoom(b, b.AddMaterial("white", glm::vec3(0.7f)), 0);
    Scene scene = b.Build();
    EXPECT_THROW(RenderReference(scene, Settings(1)), Error);
    ReferenceSettings s = Settings(8);
    s.maxDepth = -1;
    EXPECT_THROW(RenderReference(scene, s), Error);
}

}  // namespace
}  // namespace penumbra
