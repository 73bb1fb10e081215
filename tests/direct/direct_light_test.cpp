// Direct light of punctual lights (issue 5): closed forms for point, spot and directional
// lights, shadows from each type, light edits, and direct light feeding the bounces.
#include "direct/direct_light.h"

#include <gtest/gtest.h>

#include <cmath>
#include <glm/gtc/matrix_transform.hpp>
#include <numbers>

#include "base/check.h"
#include "clutter_scenes.h"
#include "reference/path_tracer.h"
#include "scene/gltf_loader.h"
#include "solver/solver.h"
#include "test_util.h"

namespace penumbra {
namespace {

using testing::Mean;

SolverSettings Settings(float elementSize = 0.1f) {
    SolverSettings s;
    s.solver = "antiradiance";
    s.device = DeviceChoice::kCpu;
    SetOption(s.options, "bins", 64);
    s.elementSize = elementSize;
    return s;
}

// A grey 4 m floor at y = 0 facing up, optionally with a 0.4 m square slab at y = 0.5.
SceneBuilder Floor(bool blocker) {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
    b.AddTiledQuad("floor", grey, {-2, 0, -2}, {4, 0, 0}, {0, 0, 4}, 20, 20, {0, 1, 0});
    if (blocker) b.AddBox("blocker", grey, {0, 0.5f, 0}, {0.4f, 0.05f, 0.4f});
    return b;
}

// Direct irradiance on the floor's surfels next to the closed form `expected(p)`; returns
// the largest relative error over surfels where expected > 5% of its peak.
template <typename F>
float MaxRelativeError(Solver& solver, F expected) {
    const Surfels& s = solver.GetSurfels();
    std::vector<glm::vec3> e = solver.SurfelIrradiance(Channel::kDirect);
    float peak = 0.0f;
    for (size_t i = 0; i < s.size(); ++i) peak = std::max(peak, expected(s.positions[i]));
    float worst = 0.0f;
    int checked = 0;
    for (size_t i = 0; i < s.size(); ++i) {
        float want = expected(s.positions[i]);
        if (want < 0.05f * peak) {
            EXPECT_LT(Mean(e[i]), 0.05f * peak + 1e-6f) << "at surfel " << i;
            continue;
        }
        worst = std::max(worst, std::abs(Mean(e[i]) - want) / want);
        ++checked;
    }
    EXPECT_GT(checked, 100);
    return worst;
}

TEST(DirectLight, PointLightOverAPlaneIsICosOverDSquared) {
    SceneBuilder b = Floor(false);
    const glm::vec3 light(0.3f, 1.2f, -0.2f);
    b.AddLight(testing::MakeLight("lamp", LightType::kPoint, light, {0, -1, 0}, 25.0f));
    auto solver = CreateSolver(b.Build(), Settings());
    float worst = MaxRelativeError(*solver, [&](glm::vec3 p) {
        glm::vec3 v = light - p;
        float d2 = glm::dot(v, v);
        return 25.0f * (v.y / std::sqrt(d2)) / d2;
    });
    std::printf("point light: max relative error %.5f\n", worst);
    EXPECT_LT(worst, 0.02f);
    EXPECT_EQ(direct::PlanShadows(b.Build()).views.size(), 6u);
}

// The direct pass projects a cube light's taps into their face from the light's `cube`
// parameters instead of loading the face's view (direct.comp, CubeNdc): the same NDC as
// the matrices the shadow maps were rendered with, on every face, out to the guard band.
TEST(DirectLight, CubeFacesProjectAsTheirViews) {
    SceneBuilder b = Floor(true);
    b.AddLight(testing::MakeLight("lamp", LightType::kPoint, {0.3f, 1.2f, -0.2f}, {0, -1, 0}, 5));
    const direct::Plan plan = direct::PlanShadows(b.Build(), 256);
    ASSERT_EQ(plan.views.size(), 6u);
    const direct::GpuLight& light = plan.lights[0];
    const glm::vec3 eye(light.position);
    int checked = 0;
    for (int face = 0; face < 6; ++face) {
        glm::vec3 forward(0.0f);
        forward[face / 2] = face % 2 ? -1.0f : 1.0f;
        for (int i = 0; i < 50; ++i) {
            // Points across the face, to its edges, at depths from near to far.
            glm::vec3 q = eye + (0.05f + 0.2f * i) * forward;
            for (int axis = 0; axis < 3; ++axis)
                if (axis != face / 2)
                    q[axis] += (0.05f + 0.2f * i) * std::sin(1.7f * i + axis) * 0.999f;
            glm::vec3 ndc;
            ASSERT_TRUE(direct::CubeNdc(light, face, q, ndc));
            glm::vec4 clip = plan.views[face].viewProj * glm::vec4(q, 1.0f);
            glm::vec3 want = glm::vec3(clip) / clip.w;
            EXPECT_NEAR(ndc.x, want.x, 1e-5f) << "face " << face;
            EXPECT_NEAR(ndc.y, want.y, 1e-5f) << "face " << face;
            EXPECT_NEAR(ndc.z, want.z, 1e-5f) << "face " << face;
            ++checked;
        }
        glm::vec3 ndc;
        EXPECT_FALSE(direct::CubeNdc(light, face, eye - forward, ndc));  // behind the face
    }
    EXPECT_EQ(checked, 300);
}

// The shadow pass draws, per view, only the triangles that can reach its map: those wholly
// beyond one plane of the clip volume are left out, all others kept (one corner in view,
// or spanning the view with every corner outside).
TEST(DirectLight, ViewsDrawOnlyTheTrianglesThatCanReachTheirMaps) {
    // A 90° view from the origin down −z, depth 0.1…10.
    const glm::mat4 viewProj = glm::perspectiveRH_ZO(glm::radians(90.0f), 1.0f, 0.1f, 10.0f) *
                               glm::lookAtRH(glm::vec3(0), glm::vec3(0, 0, -1), glm::vec3(0, 1, 0));
    const std::vector<glm::vec3> tris = {
        {-0.5f, -0.5f, -2}, {0.5f, -0.5f, -2}, {0, 0.5f, -2},  // in view: kept
        {3, 0, -2},         {4, 0, -2},        {3, 1, -2},     // right of the view: dropped
        {-1, 0, 2},         {1, 0, 2},         {0, 1, 2},      // behind the eye: dropped
        {-1, 0, -20},       {1, 0, -20},       {0, 1, -20},    // beyond the far plane: dropped
        {-9, -1, -2},       {9, -1, -2},       {0, 9, -2},     // every corner out, spans it
        {1.5f, 0, -2},      {-1, 0, 1},        {0, 0, -5},     // one corner in view: kept
    };
    std::vector<uint32_t> indices;
    direct::ViewTriangles(viewProj, tris, indices);
    EXPECT_EQ(indices, (std::vector<uint32_t>{0, 1, 2, 12, 13, 14, 15, 16, 17}));
}

TEST(DirectLight, SpotLightFollowsItsConeFalloff) {
    SceneBuilder b = Floor(false);
    PunctualLight spot =
        testing::MakeLight("spot", LightType::kSpot, {0, 1.5f, 0}, {0.2f, -1, 0}, 40.0f);
    spot.innerCone = 0.3f;
    spot.outerCone = 0.5f;
    spot.color = glm::vec3(1.0f, 0.5f, 0.25f);
    b.AddLight(spot);
    Scene scene = b.Build();
    const PunctualLight& placed = scene.lights[0];
    auto solver = CreateSolver(scene, Settings());
    const glm::vec3 colourMean(Mean(spot.color));
    float worst = MaxRelativeError(*solver, [&](glm::vec3 p) {
        glm::vec3 v = p - placed.position;
        float d = glm::length(v);
        float cosine = -v.y / d;
        // KHR_lights_punctual's smooth cone, written out here on its own.
        float cd = glm::dot(placed.direction, v / d);
        float t = std::clamp((cd - std::cos(0.5f)) / (std::cos(0.3f) - std::cos(0.5f)), 0.f, 1.f);
        return 40.0f * colourMean.x * t * t * cosine / (d * d);
    });
    std::printf("spot light: max relative error %.5f\n", worst);
    EXPECT_LT(worst, 0.02f);
    EXPECT_EQ(direct::PlanShadows(scene).views.size(), 1u);
}

TEST(DirectLight, DirectionalLightGivesEPerpTimesCosine) {
    for (float degrees : {0.0f, 30.0f, 60.0f}) {
        SceneBuilder b = Floor(false);
        float t = glm::radians(degrees);
        b.AddLight(testing::MakeLight("sun", LightType::kDirectional, {0, 3, 0},
                                      {std::sin(t), -std::cos(t), 0.0f}, 1000.0f));
        auto solver = CreateSolver(b.Build(), Settings());
        float worst = MaxRelativeError(*solver, [&](glm::vec3) { return 1000.0f * std::cos(t); });
        std::printf("directional %.0f°: max relative error %.6f\n", degrees, worst);
        EXPECT_LT(worst, 0.001f);
    }
}

// The umbra of a slab under each light type is below 5% of the lit value, and away from the
// shadow the blocker changes nothing.
TEST(DirectLight, BlockerCastsAShadowFromEveryLightType) {
    struct Case {
        PunctualLight light;
        float umbra;  // half-width of the floor square that must be in full shadow
    };
    PunctualLight spot = testing::MakeLight("spot", LightType::kSpot, {0, 1, 0}, {0, -1, 0}, 20.0f);
    spot.outerCone = 0.9f;
    spot.innerCone = 0.8f;
    const Case cases[] = {
        {testing::MakeLight("lamp", LightType::kPoint, {0, 1, 0}, {0, -1, 0}, 20.0f), 0.3f},
        {spot, 0.3f},
        {testing::MakeLight("sun", LightType::kDirectional, {0, 3, 0}, {0, -1, 0}, 1000.0f), 0.12f},
    };
    for (const Case& c : cases) {
        SceneBuilder open = Floor(false), blocked = Floor(true);
        open.AddLight(c.light);
        blocked.AddLight(c.light);
        auto lit = CreateSolver(open.Build(), Settings(0.05f));
        auto shadowed = CreateSolver(blocked.Build(), Settings(0.05f));
        std::vector<glm::vec3> a = lit->SurfelIrradiance(Channel::kDirect);
        std::vector<glm::vec3> s = shadowed->SurfelIrradiance(Channel::kDirect);
        const Surfels& sa = lit->GetSurfels();
        const Surfels& ss = shadowed->GetSurfels();
        int umbra = 0, far = 0;
        for (size_t i = 0; i < ss.size(); ++i) {
            glm::vec3 p = ss.positions[i];
            if (p.y > 1e-4f || ss.normals[i].y < 0.99f) continue;  // floor only
            size_t j = testing::NearestSurfel(sa, p, {0, 1, 0});
            float open = Mean(a[j]);
            if (std::abs(p.x) < c.umbra && std::abs(p.z) < c.umbra) {
                EXPECT_LT(Mean(s[i]), 0.05f * open) << c.light.name << " at " << p.x << "," << p.z;
                ++umbra;
            } else if (std::abs(p.x) > 0.8f || std::abs(p.z) > 0.8f) {
                EXPECT_NEAR(Mean(s[i]), open, 1e-3f * open) << c.light.name;
                ++far;
            }
        }
        std::printf("%s: %d umbra surfels, %d far surfels checked\n", c.light.name.c_str(), umbra,
                    far);
        EXPECT_GT(umbra, 20);
        EXPECT_GT(far, 100);
    }
}

// A shadow edge at an angle to the element grid falls off smoothly across one element: the
// direct light of vertices near the edge rises with their distance into the lit side, with
// intermediate values at the edge, instead of a jagged 0/1 staircase along the grid.
TEST(DirectLight, ShadowEdgesDoNotAliasOnTheElementGrid) {
    SceneBuilder b = Floor(false);
    uint32_t grey = b.AddMaterial("slab", glm::vec3(0.5f));
    // A large slab turned 27° about y: its straight edge crosses the floor's grid diagonally.
    b.AddBox("slab", grey, {-1.0f, 0.5f, 0.0f}, {2.0f, 0.05f, 6.0f}, 27.0f);
    b.AddLight(testing::MakeLight("sun", LightType::kDirectional, {0, 3, 0}, {0, -1, 0}, 1000.0f));
    const float h = 0.05f;
    auto solver = CreateSolver(b.Build(), Settings(h));
    const Surfels& s = solver->GetSurfels();
    std::vector<glm::vec3> e = solver->SurfelIrradiance(Channel::kDirect);
    // The slab's +x edge: through (−1 + cos27°, ·, −sin27°)·1 from the centre, along its z axis.
    float t = glm::radians(27.0f);
    glm::vec3 normal(std::cos(t), 0.0f, -std::sin(t));  // the slab's local +x, outwards
    glm::vec3 edge = glm::vec3(-1.0f, 0.0f, 0.0f) + 1.0f * normal;
    std::vector<std::pair<float, float>> near;  // (signed distance into the light, E / E0)
    for (size_t i = 0; i < s.size(); ++i) {
        glm::vec3 p = s.positions[i];
        if (p.y > 1e-4f || s.normals[i].y < 0.99f || std::abs(p.z) > 1.2f) continue;
        // Measured from the centre of the surfel's footprint: a vertex on a tile border
        // stands for its own tile's side only (its centroid lies inside that tile).
        float d = glm::dot(s.centroids[i] - edge, normal);
        if (std::abs(d) < 2.0f * h) near.emplace_back(d, Mean(e[i]) / 1000.0f);
    }
    ASSERT_GT(near.size(), 100u);
    int between = 0;
    for (const auto& [d, v] : near) {
        if (v > 0.05f && v < 0.95f) ++between;
        if (d < -h) {
            EXPECT_LT(v, 0.05f) << "in the umbra, " << d << " m from the edge";
        }
        if (d > h) {
            EXPECT_GT(v, 0.95f) << "in the light, " << d << " m from the edge";
        }
    }
    // Monotone in the distance, up to a tenth of the lit value.
    int inversions = 0;
    float worst = 0.0f;
    for (size_t a = 0; a < near.size(); ++a)
        for (size_t c = 0; c < near.size(); ++c)
            if (near[a].first < near[c].first - 0.25f * h) {
                float inv = near[a].second - near[c].second;
                worst = std::max(worst, inv);
                if (inv > 0.1f) ++inversions;
            }
    std::printf(
        "edge: %zu vertices within 2 elements, %d with partial light, %d inversions (worst %.3f)\n",
        near.size(), between, inversions, worst);
    // Measured 92 of 850 partly lit (the ramp is about one footprint wide), no inversion.
    EXPECT_GT(between, static_cast<int>(near.size() / 20));
    EXPECT_EQ(inversions, 0);
}

// Moving, recolouring and dimming a light changes E_d (a new direct pass; the CPU back end's
// shadow rays keep their BVH, since the geometry did not move).
TEST(DirectLight, LightEditsTakeOneShadowPass) {
    SceneBuilder b = Floor(true);
    b.AddLight(testing::MakeLight("lamp", LightType::kPoint, {0, 1, 0}, {0, -1, 0}, 20.0f));
    Scene scene = b.Build();
    auto solver = CreateSolver(scene, Settings(0.05f));
    size_t under = testing::NearestSurfel(solver->GetSurfels(), {0, 0, 0}, {0, 1, 0});
    EXPECT_LT(Mean(solver->SurfelIrradiance(Channel::kDirect)[under]), 0.1f);

    // Move the lamp sideways: the point under the blocker is lit from the side now.
    int node = FindNode(scene, "lamp");
    ASSERT_GE(node, 0);
    SetNodeTransform(scene, node, glm::translate(glm::mat4(1.0f), glm::vec3(1.5f, 1.0f, 0.0f)));
    EXPECT_EQ(scene.lights[0].position, glm::vec3(1.5f, 1.0f, 0.0f));
    solver->UpdateLights(scene);
    glm::vec3 v = glm::vec3(1.5f, 1.0f, 0.0f);
    float want = 20.0f * (1.0f / glm::length(v)) / glm::dot(v, v);
    EXPECT_NEAR(Mean(solver->SurfelIrradiance(Channel::kDirect)[under]), want, 0.02f * want);

    // Dim and recolour.
    scene.lights[0].intensity = 5.0f;
    scene.lights[0].color = glm::vec3(1.0f, 0.0f, 0.0f);
    solver->UpdateLights(scene);
    glm::vec3 e = solver->SurfelIrradiance(Channel::kDirect)[under];
    EXPECT_NEAR(e.x, want / 4.0f, 0.02f * want);
    EXPECT_EQ(e.y, 0.0f);
    EXPECT_GT(solver->Stats().lighting.msDirect, 0.0);
}

// Direct light bounces: a lamp that only lights the floor makes a wall that it cannot see
// receive indirect light, and no antiradiance is made from the direct light (a wall behind
// an opaque plate stays dark in `total`).
TEST(DirectLight, DirectLightBouncesAndMakesNoAntiradiance) {
    SceneBuilder b;
    testing::AddWhiteCorner(b, 10, 8);
    PunctualLight spot =
        testing::MakeLight("spot", LightType::kSpot, {0.8f, 0.9f, 0}, {-0.3f, -1, 0}, 10.0f);
    spot.outerCone = 0.6f;
    spot.innerCone = 0.5f;
    b.AddLight(spot);
    auto solver = CreateSolver(b.Build(), Settings(0.1f));
    size_t wall = testing::NearestSurfel(solver->GetSurfels(), {1, 0.3f, 0}, {-1, 0, 0});
    EXPECT_EQ(Mean(solver->SurfelIrradiance(Channel::kDirect)[wall]), 0.0f);
    solver->Iterate(4);
    float indirect = Mean(solver->SurfelIrradiance(Channel::kIndirect)[wall]);
    float total = Mean(solver->SurfelIrradiance(Channel::kTotal)[wall]);
    std::printf("wall: indirect %.4f lux, total %.4f lux\n", indirect, total);
    EXPECT_GT(indirect, 0.05f);
    EXPECT_FLOAT_EQ(indirect, total);
    // Energy: the wall cannot receive more than the floor reflects, ρ Σ a E_d.
    const Surfels& s = solver->GetSurfels();
    std::vector<glm::vec3> d = solver->SurfelIrradiance(Channel::kDirect);
    std::vector<glm::vec3> in = solver->SurfelIrradiance(Channel::kIndirect);
    double reflected = 0.0, received = 0.0;
    for (size_t i = 0; i < s.size(); ++i) {
        if (s.normals[i].y > 0.9f) reflected += 0.8 * s.areas[i] * Mean(d[i]);
        if (s.normals[i].x < -0.9f) received += s.areas[i] * Mean(in[i]);
    }
    EXPECT_LT(received, reflected);
}

TEST(DirectLight, GltfLightsRoundTrip) {
    auto dir = testing::TempDir("lights");
    SceneBuilder b = Floor(false);
    PunctualLight spot =
        testing::MakeLight("spot", LightType::kSpot, {0.5f, 2, 0}, {0, -1, 0.2f}, 40.0f);
    spot.innerCone = 0.2f;
    spot.outerCone = 0.4f;
    spot.range = 8.0f;
    spot.color = glm::vec3(1, 0.9f, 0.8f);
    b.AddLight(spot);
    b.AddLight(testing::MakeLight("sun", LightType::kDirectional, {0, 5, 0}, {0, -1, 0}, 100.0f));
    b.WriteGltf((dir / "lights.gltf").string());
    Scene loaded = LoadGltf((dir / "lights.gltf").string());
    Scene built = b.Build();
    ASSERT_EQ(loaded.lights.size(), 2u);
    for (size_t i = 0; i < 2; ++i) {
        const PunctualLight &x = loaded.lights[i], &y = built.lights[i];
        EXPECT_EQ(x.name, y.name);
        EXPECT_EQ(x.type, y.type);
        EXPECT_NEAR(glm::length(x.position - y.position), 0.0f, 1e-5f);
        EXPECT_NEAR(glm::length(x.direction - y.direction), 0.0f, 1e-5f);
        EXPECT_EQ(x.color, y.color);
        EXPECT_EQ(x.intensity, y.intensity);
        EXPECT_EQ(x.range, y.range);
        EXPECT_FLOAT_EQ(x.outerCone, y.outerCone);
        EXPECT_EQ(FindLight(loaded, x.name), static_cast<int>(i));
    }
}

TEST(DirectLight, BrokenLightsFailWithTheReason) {
    auto dir = testing::TempDir("broken-lights");
    SceneBuilder b = Floor(false);
    b.AddLight(testing::MakeLight("lamp", LightType::kPoint, {0, 1, 0}, {0, -1, 0}, 20.0f));
    std::string path = (dir / "lamp.gltf").string();
    b.WriteGltf(path);
    std::string text;
    {
        std::FILE* f = std::fopen(path.c_str(), "rb");
        ASSERT_TRUE(f);
        char buf[4096];
        size_t n;
        while ((n = std::fread(buf, 1, sizeof buf, f)) > 0) text.append(buf, n);
        std::fclose(f);
    }
    auto broken = [&](const std::string& from, const std::string& to) {
        std::string t = text;
        size_t at = t.find(from);
        EXPECT_NE(at, std::string::npos) << from;
        t.replace(at, from.size(), to);
        std::string p = (dir / "broken.gltf").string();
        std::FILE* f = std::fopen(p.c_str(), "wb");
        std::fwrite(t.data(), 1, t.size(), f);
        std::fclose(f);
        try {
            LoadGltf(p);
        } catch (const Error& e) {
            return std::string(e.what());
        }
        return std::string("(loaded)");
    };
    EXPECT_NE(broken("\"point\"", "\"area\"").find("is not point, spot or directional"),
              std::string::npos);
    EXPECT_NE(broken("\"intensity\": 20", "\"intensity\": -20").find("intensity"),
              std::string::npos);
    EXPECT_NE(broken("\"light\": 0", "\"light\": 7").find("light 7 does not exist"),
              std::string::npos);
}

// Whether a straight line from the sun reaches point `p` (facing `n`) of the sunlit maze
// (scenes::SunlitMaze): `p` faces the sun, and the line to it meets the roof's plane inside
// the hole without passing through an inner wall's box on the way.
bool SunReaches(const glm::vec3& p, const glm::vec3& n) {
    const glm::vec3 toSun = -scenes::SunlitMazeSun();
    if (glm::dot(n, toSun) <= 0.0f) return false;
    const float t = (scenes::kSunlitMazeHeight - p.y) / toSun.y;
    const glm::vec3 q = p + t * toSun;
    const float lo = scenes::kSunlitMazeHoleLo, hi = scenes::kSunlitMazeHoleHi;
    if (q.x < lo || q.x > hi || q.z < lo || q.z > hi) return false;
    for (const auto& [a, c] : scenes::SunlitMazeWalls()) {
        float near = 1e-4f, far = t;  // slabs along the segment, past p's own surface
        for (int k = 0; k < 3; ++k) {
            if (std::abs(toSun[k]) < 1e-9f) {
                if (p[k] < a[k] || p[k] > c[k]) near = far + 1.0f;
                continue;
            }
            float t0 = (a[k] - p[k]) / toSun[k], t1 = (c[k] - p[k]) / toSun[k];
            if (t0 > t1) std::swap(t0, t1);
            near = std::max(near, t0);
            far = std::min(far, t1);
        }
        if (near < far) return false;
    }
    return true;
}

// How the sun reaches the disc of radius `r` about p on its surface: 1 everywhere, 0
// nowhere, -1 in part (its centre and eight points on its rim).
int SunOverDisc(const glm::vec3& p, const glm::vec3& n, float r) {
    glm::vec3 t = glm::normalize(
        glm::cross(n, std::abs(n.y) < 0.9f ? glm::vec3(0, 1, 0) : glm::vec3(1, 0, 0)));
    glm::vec3 s = glm::cross(n, t);
    int lit = SunReaches(p, n) ? 1 : 0, points = 1;
    for (int k = 0; k < 8; ++k) {
        const float a = float(k) * std::numbers::pi_v<float> / 4.0f;
        lit += SunReaches(p + r * (std::cos(a) * t + std::sin(a) * s), n) ? 1 : 0;
        ++points;
    }
    return lit == points ? 1 : lit == 0 ? 0 : -1;
}

// Issue 61: no light through walls. The sun reaches the sunlit maze only through its roof's
// hole; the direct stage (shadow maps) and the reference's direct channel must give zero
// wherever no straight line from the sun arrives (the roof seen from its back, the hollow
// inner walls without tops, the contacts of walls and roof), and the sun's E⊥ cos θ where
// one does. Elements within one element size of a shadow's edge are left out.
TEST(DirectLight, SunThroughARoofHoleLightsOnlyWhatItReaches) {
    const Scene scene = scenes::SunlitMaze().Build();
    const float element = 0.1f;
    const float sun = 1000.0f;
    auto solver = CreateSolver(scene, Settings(element));
    const std::vector<glm::vec3> e = solver->SurfelIrradiance(Channel::kDirect);
    const Surfels& s = solver->GetSurfels();
    int dark = 0, lit = 0, leaks = 0, wrong = 0;
    for (size_t i = 0; i < s.size(); ++i) {
        if (s.areas[i] <= 0.0f) continue;
        const int over = SunOverDisc(s.positions[i], s.normals[i], element);
        const float want = sun * std::max(0.0f, glm::dot(s.normals[i], -scenes::SunlitMazeSun()));
        if (over == 0) {
            ++dark;
            if (e[i].x > 1e-3f * sun && leaks++ < 10)
                ADD_FAILURE() << "sun through a wall at " << s.positions[i].x << ","
                              << s.positions[i].y << "," << s.positions[i].z << " (normal "
                              << s.normals[i].x << "," << s.normals[i].y << "," << s.normals[i].z
                              << "): " << e[i].x << " lux, want 0";
        } else if (over == 1) {
            ++lit;
            if (std::abs(e[i].x - want) > 0.02f * want && wrong++ < 10)
                ADD_FAILURE() << "sunlit element at " << s.positions[i].x << "," << s.positions[i].y
                              << "," << s.positions[i].z << ": " << e[i].x << " lux, want " << want;
        }
    }
    std::printf("sunlit maze: %d dark elements (%d lit through a wall), %d lit (%d wrong)\n", dark,
                leaks, lit, wrong);
    EXPECT_GT(lit, 20);
    EXPECT_EQ(leaks, 0);
    EXPECT_EQ(wrong, 0);

    // The reference's direct channel, at the input vertices: zero wherever no line arrives.
    ReferenceSettings rs;
    rs.samples = 16;
    rs.channel = Channel::kDirect;
    const ReferenceResult ref = RenderReference(scene, rs);
    int refLeaks = 0, refDark = 0;
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const Primitive& prim = scene.primitives[p];
        for (size_t v = 0; v < prim.positions.size(); ++v) {
            if (SunOverDisc(prim.positions[v], prim.normals[v], 0.01f) != 0) continue;
            ++refDark;
            if (ref.irradiance[p][v].x > 1e-3f * sun && refLeaks++ < 10)
                ADD_FAILURE() << "reference: sun through a wall at " << prim.positions[v].x << ","
                              << prim.positions[v].y << "," << prim.positions[v].z << " ("
                              << prim.node << "): " << ref.irradiance[p][v].x << " lux";
        }
    }
    std::printf("reference: %d dark vertices, %d lit through a wall\n", refDark, refLeaks);
    EXPECT_EQ(refLeaks, 0);
}

}  // namespace
}  // namespace penumbra
