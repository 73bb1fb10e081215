// The implicit-visibility solver (solvers/implicit/) against closed forms: a sky over an open
// plane, a white furnace with occluders, a patch and a disc over a receiver, a thin wall.
#include <gtest/gtest.h>

#include <glm/gtc/matrix_transform.hpp>
#include <numbers>
#include <random>

#include "bundled_scenes.h"
#include "clutter_scenes.h"
#include "gather/gather_stage.h"
#include "gpu/context.h"
#include "reference/path_tracer.h"
#include "scene/scene_builder.h"
#include "solvers/implicit/implicit_solver.h"
#include "solvers/implicit/vulkan_bounce.h"
#include "solvers/implicit/vulkan_composite.h"
#include "solvers/implicit/vulkan_links.h"
#include "solvers/registry.h"
#include "test_device.h"
#include "test_util.h"

namespace penumbra {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

SolverSettings Implicit(float elementSize, int bins = 128) {
    SolverSettings s;
    s.solver = "implicit";
    s.device = DeviceChoice::kCpu;
    s.elementSize = elementSize;
    SetOption(s.options, "bins", bins);
    return s;
}

// Mean over a leaf's front bins of the weight that has a sender: 1 where every bin sees a
// surface.
double FilledFraction(const ImplicitLinks& links, size_t leaf) {
    double filled = 0.0, all = 0.0;
    for (uint32_t k = links.offsets[leaf]; k < links.offsets[leaf + 1]; ++k) {
        all += links.weight[k];
        if (links.sender[k] != kNoSender) filled += links.weight[k];
    }
    return all > 0.0 ? filled / all : 0.0;
}

// Every vertex's irradiance from `samples` paths a vertex, one array (AllVertices' order).
std::vector<glm::vec3> Truth(const Scene& scene, int samples) {
    ReferenceSettings rs;
    rs.samples = samples;
    std::vector<glm::vec3> truth;
    for (const auto& v : RenderReference(scene, rs).irradiance)
        truth.insert(truth.end(), v.begin(), v.end());
    return truth;
}

// Relative RMS between `solver`'s answer and that of a solver built afresh for `scene` with
// `settings` and iterated `iterations` times.
double ApartFromAFreshBuild(Solver& solver, const Scene& scene, const SolverSettings& settings,
                            int iterations) {
    auto fresh = CreateSolver(scene, settings);
    fresh->Iterate(iterations);
    return testing::RelativeRms(testing::AllVertices(solver, scene, Channel::kIndirect),
                                testing::AllVertices(*fresh, scene, Channel::kIndirect));
}

// Two builds' links equal to the bit, share for share, with the same pair counts.
void ExpectSameLinks(const ImplicitLinks& a, const ImplicitLinks& b) {
    EXPECT_EQ(a.offsets, b.offsets);
    EXPECT_EQ(a.bin, b.bin);
    EXPECT_EQ(a.sender, b.sender);
    EXPECT_EQ(a.weight, b.weight);
    EXPECT_EQ(a.travel, b.travel);
    EXPECT_EQ(a.pairs, b.pairs);
    EXPECT_EQ(a.linked, b.linked);
}

// A grey box (dynamic, "box") on a grey ground under a constant sky of radiance 1.
Scene BoxOnGroundUnderASky() {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", glm::vec3(0.6f));
    b.AddTiledQuad("ground", grey, {-1, 0, -1}, {2, 0, 0}, {0, 0, 2}, 8, 8, {0, 1, 0});
    b.AddBox("box", grey, {0, 0.25f, 0}, {0.3f, 0.5f, 0.3f}, 0.0f, false);
    b.SetDynamic("box", {0, 0, 0});
    Scene scene = b.Build();
    scene.environment = ConstantEnvironment(glm::vec3(1.0f));
    return scene;
}

// Directions::Lookup (every pair of the link creation looks its bins up) reads candidate
// lists of a fine cube map: it finds the nearest bin, as a search over all bins does, also on
// the cube's face edges and corners, at the fewest and the most bins and the paper's 864.
TEST(Directions, LookupFindsTheNearestBin) {
    std::mt19937 rng(7);
    std::normal_distribution<float> n01;
    for (int count : {Directions::kMinBins, 128, 864, Directions::kMaxBins}) {
        const Directions dirs(count);
        std::vector<glm::vec3> probes;
        for (int i = 0; i < 50000; ++i) {
            const glm::vec3 d(n01(rng), n01(rng), n01(rng));
            if (glm::length(d) > 1e-6f) probes.push_back(glm::normalize(d));
        }
        for (float a : {-1.0f, 0.0f, 1.0f})
            for (float b : {-1.0f, 0.0f, 1.0f})
                for (float c : {-1.0f, 0.0f, 1.0f})
                    if (a != 0.0f || b != 0.0f || c != 0.0f)
                        probes.push_back(glm::normalize(glm::vec3(a, b, c)));
        size_t wrong = 0;
        for (const glm::vec3& d : probes) {
            float best = -2.0f;
            for (const glm::vec3& w : dirs.All()) best = std::max(best, glm::dot(d, w));
            if (glm::dot(d, dirs.Direction(dirs.Lookup(d))) < best - 1e-6f) ++wrong;
        }
        EXPECT_EQ(wrong, 0u) << count << " bins";
    }
}

// ForEachWithin (the spread of an end wider than half a bin) calls back exactly the bins within
// its reach, each once with its cosine, through the centre bin's neighbours nearest first (a
// small cap) or the groups nearest it first (a wider one), from the nearest bin or another
// one near `d`.
TEST(Directions, ForEachWithinVisitsExactlyTheBinsWithinReach) {
    std::mt19937 rng(11);
    std::normal_distribution<float> n01;
    std::uniform_real_distribution<float> angle(0.0f, 3.3f);
    for (int count : {Directions::kMinBins, 128, 864, Directions::kMaxBins}) {
        const Directions dirs(count);
        size_t wrong = 0, twice = 0, badCosine = 0, calls = 0;
        std::vector<int> seen(count);
        for (int i = 0; i < 2000; ++i) {
            const glm::vec3 d = glm::normalize(glm::vec3(n01(rng), n01(rng), n01(rng)));
            const float reach = i % 3 == 0 ? 0.5f * dirs.Spacing() : angle(rng);
            uint32_t from = dirs.Lookup(d);
            if (i % 2 == 1) from = dirs.Adjacent(from)[i % dirs.Adjacent(from).size()];
            const float offset =
                std::acos(std::clamp(glm::dot(d, dirs.Direction(from)), -1.0f, 1.0f));
            std::fill(seen.begin(), seen.end(), 0);
            dirs.ForEachWithin(
                from, offset, d, reach, [&](uint32_t b, const glm::vec3& w, float c) {
                    ++seen[b], ++calls;
                    if (w != dirs.Direction(b) || c != glm::dot(d, dirs.Direction(b))) ++badCosine;
                });
            const float cosReach = std::cos(std::min(reach, std::numbers::pi_v<float>));
            for (int b = 0; b < count; ++b) {
                if ((glm::dot(d, dirs.Direction(b)) >= cosReach) != (seen[b] > 0)) ++wrong;
                if (seen[b] > 1) ++twice;
            }
        }
        EXPECT_EQ(wrong, 0u) << count << " bins";
        EXPECT_EQ(twice, 0u) << count << " bins";
        EXPECT_EQ(badCosine, 0u) << count << " bins";
        EXPECT_GT(calls, 0u);
    }
}

// OverlapReach (how far out a spread end's bins are walked) keeps every bin the end's disc
// overlaps by more than kMinOverlap of a bin, and leaves out the ring of slivers beyond: the
// overlap of two discs on the plane, in doubles, against the reach over a fine sweep of the
// disc's radius, at the fewest bins, the paper's 864 and the most.
TEST(Implicit, OverlapReachKeepsEveryBinTheEndCovers) {
    auto lens = [](double d, double r, double R) {
        if (d >= r + R) return 0.0;
        const double small = std::min(r, R), large = std::max(r, R);
        if (d <= large - small) return std::numbers::pi * small * small;
        const double a = r * r * std::acos((d * d + r * r - R * R) / (2 * d * r));
        const double b = R * R * std::acos((d * d + R * R - r * r) / (2 * d * R));
        return a + b - 0.5 * std::sqrt((-d + r + R) * (d + r - R) * (d - r + R) * (d + r + R));
    };
    for (int count : {Directions::kMinBins, 864, Directions::kMaxBins}) {
        const Directions dirs(count);
        const ImplicitLinker linker(dirs, 0.2f);
        const double R = linker.BinRadius();
        const double least = ImplicitLinker::kMinOverlap * std::numbers::pi * R * R;
        size_t missed = 0, shorter = 0, tried = 0;
        for (double rho = 0.5 * dirs.Spacing(); rho < std::numbers::pi / 2; rho += 0.0037) {
            const double reach = linker.OverlapReach(float(rho));
            EXPECT_LE(reach, rho + R + 1e-6) << count << " bins, rho " << rho;
            // Every distance out to the whole disc's reach: beyond OverlapReach, slivers only.
            for (double d = 0.0; d < rho + R; d += 0.002 * R)
                if (d > reach && lens(d, rho, R) > least) ++missed;
            if (reach < rho + R - 0.05 * R) ++shorter;
            ++tried;
        }
        EXPECT_EQ(missed, 0u) << count << " bins";
        // It is not the whole reach in disguise: the ring it leaves out is a tenth of a bin's
        // radius or more, for nearly every disc.
        EXPECT_GT(shorter, tried * 9 / 10) << count << " bins";
    }
}

// An open plane under a constant sky of radiance 1: nothing stands above it, every front bin
// reads the sky, E = π everywhere.
TEST(Implicit, OpenPlaneUnderASkyReceivesPiL) {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
    b.AddTiledQuad("ground", grey, {-1, 0, -1}, {2, 0, 0}, {0, 0, 2}, 4, 4, {0, 1, 0});
    Scene scene = b.Build();
    scene.environment = ConstantEnvironment(glm::vec3(1.0f));
    auto solver = CreateSolver(scene, Implicit(0.25f));
    solver->Iterate(3);
    for (const glm::vec3& e : testing::AllVertices(*solver, scene, Channel::kIndirect))
        EXPECT_NEAR(e.x, kPi, 0.01 * kPi);
}

// A closed room: every front bin of every leaf sees a wall, and with every surface emitting
// L_e = 1 at albedo 0.5 the light converges to L = 2, E = 2π (a white furnace), with boxes
// in the room.
// The unit room with two boxes in it, every surface emitting L_e = 1 at albedo 0.5 (E = 2π
// everywhere once converged). The boxes are held off the floor, so that every vertex sees the
// room (a floor vertex under a box standing on it receives nothing, rightly).
Scene FurnaceRoomWithBoxes() {
    SceneBuilder b;
    uint32_t glow = b.AddMaterial("glow", glm::vec3(0.5f), glm::vec3(1.0f));
    testing::AddUnitRoom(b, glow, glow, 4);
    b.AddBox("box", glow, {0.3f, 0.3f, 0.3f}, {0.2f, 0.3f, 0.2f});
    b.AddBox("tall", glow, {0.7f, 0.45f, 0.6f}, {0.15f, 0.6f, 0.15f}, 20.0f);
    return b.Build();
}

TEST(Implicit, ClosedRoomFillsEveryBinAndKeepsTheFurnace) {
    Scene scene = FurnaceRoomWithBoxes();
    auto solver = CreateSolver(scene, Implicit(0.06f));
    auto& implicit = dynamic_cast<ImplicitSolver&>(*solver);
    double mean = 0.0, worst = 1.0;
    const size_t leaves = implicit.GetHierarchy().leaves.size();
    for (size_t i = 0; i < leaves; ++i) {
        const double f = FilledFraction(implicit.Links(), i);
        mean += f / leaves;
        worst = std::min(worst, f);
    }
    std::printf("closed room: filled %.4f on average, %.4f at the worst leaf, %zu links\n", mean,
                worst, implicit.Links().Count());
    EXPECT_GT(mean, 0.98);
    solver->Iterate(40);
    std::vector<glm::vec3> e = testing::AllVertices(*solver, scene, Channel::kIndirect);
    double sum = 0.0, far = 0.0;
    for (const glm::vec3& v : e) {
        sum += v.x / e.size();
        far = std::max(far, double(std::abs(v.x - 2 * kPi)) / (2 * kPi));
    }
    std::printf("furnace: mean E %.4f (2π = %.4f), worst vertex %.2f%% off\n", sum, 2 * kPi,
                100 * far);
    // The goal, 2%. Measured 0.3% low at 128 bins (8.7% before a closed solid's far
    // faces stood for its near ones, ImplicitLinker::Build's `solid`; 2.2% before a cluster of
    // a solid's far faces did too: read through the tables it was nearly black).
    EXPECT_NEAR(sum, 2 * kPi, 0.02 * 2 * kPi);
}

// `bin-cover closest`, the paper's Eq. 5 as written: each front bin of a leaf is one share,
// its closest link's (pushed down from the leaf's ancestors) covering the whole bin, or the
// environment; on a Vulkan device (each slot's closest link kept there by 64-bit atomicMin,
// the bounces there too) the links and the answer are the CPU's. The rule's known loss, in the
// closed furnace room above: 25% low at 128 bins, 0.1 m (a leaf wider than a bin marks only its
// centre's bin, and its neighbours see the environment, 9.6% of the shares here, or what lies
// behind; where a box's near faces' centres fell into other bins, its far face is the closest and
// blocks, black). The bounds catch a regression (the layered default keeps this room within 5%).
TEST(Implicit, ClosestLinkCoversItsBin) {
    Scene scene = FurnaceRoomWithBoxes();
    SolverSettings settings = Implicit(0.1f);
    SetOption(settings.options, "bin-cover", "closest");
    auto solver = CreateSolver(scene, settings);
    auto& implicit = dynamic_cast<ImplicitSolver&>(*solver);
    const ImplicitLinks& links = implicit.Links();
    const Hierarchy& h = implicit.GetHierarchy();
    const Directions& dirs = implicit.GetDirections();
    size_t wrong = 0, empty = 0;
    for (size_t i = 0; i < h.leaves.size(); ++i) {
        const glm::vec3& n = h.nodes[h.leaves[i]].normal;
        size_t front = 0;
        for (uint32_t k = 0; k < uint32_t(dirs.Count()); ++k)
            front += glm::dot(n, dirs.Direction(k)) > 0.0f;
        std::vector<uint8_t> seen(dirs.Count(), 0);
        for (uint32_t k = links.offsets[i]; k < links.offsets[i + 1]; ++k) {
            wrong += seen[links.bin[k]]++ > 0;  // at most one share a bin
            empty += links.sender[k] == kNoSender;
        }
        wrong += links.offsets[i + 1] - links.offsets[i] != front;  // one every front bin
    }
    std::printf("closest link: %zu leaves, %zu shares, %zu of the environment\n", h.leaves.size(),
                links.sender.size(), empty);
    EXPECT_EQ(wrong, 0u);
    EXPECT_EQ(solver->Stats().Text("bin_cover"), "closest");
    solver->Iterate(20);
    const std::vector<glm::vec3> e = testing::AllVertices(*solver, scene, Channel::kIndirect);
    double sum = 0.0;
    for (const glm::vec3& v : e) sum += v.x / e.size();
    std::printf("closest link, furnace: mean E %.4f (2π = %.4f)\n", sum, 2 * kPi);
    EXPECT_GT(sum, 0.7 * 2 * kPi);
    EXPECT_LT(sum, 1.02 * 2 * kPi);
    settings.device = testing::TestVulkanChoice();
    settings.validation = true;
    auto device = CreateSolver(scene, settings);
    device->Iterate(20);
    EXPECT_NE(device->Stats().Text("link_device"), "cpu");
    EXPECT_NE(device->Stats().Text("bounce_device"), "cpu");
    EXPECT_EQ(device->Stats().Number("candidate_pairs"), solver->Stats().Number("candidate_pairs"));
    // The same share a front bin; lavapipe rounds as the CPU does, a real GPU may take another
    // sender where two tie up to rounding (Vulkan's 2.5 ulp division, fused multiply-adds).
    const ImplicitLinks& on = dynamic_cast<ImplicitSolver&>(*device).Links();
    ASSERT_EQ(on.offsets, links.offsets);
    ASSERT_EQ(on.bin, links.bin);
    size_t other = 0;
    for (size_t k = 0; k < links.sender.size(); ++k) other += on.sender[k] != links.sender[k];
    std::printf("closest link on the device: %zu of %zu shares with another sender\n", other,
                links.sender.size());
    EXPECT_LE(double(other), (testing::TestOnRealGpu() ? 3e-4 : 0.0) * double(links.sender.size()));
    for (const auto& m : device->ValidationMessages()) ADD_FAILURE() << "validation: " << m;
    const std::vector<glm::vec3> d = testing::AllVertices(*device, scene, Channel::kIndirect);
    double num = 0.0, den = 0.0;
    for (size_t i = 0; i < e.size(); ++i)
        num += glm::dot(d[i] - e[i], d[i] - e[i]), den += glm::dot(e[i], e[i]);
    std::printf("closest link on the device: %.2e from the CPU's\n", std::sqrt(num / den));
    EXPECT_LT(std::sqrt(num / den), 1e-4);
}

// The bundled maze as a white furnace (every surface emitting 1 at albedo 0.5): thin
// partitions (thinner than an element), a closed lamp housing, vertices in contact. Against
// the path tracer on the same scene: within 10% (measured 7.7%; 13.4% when a closed solid's
// far faces, seen behind its near ones, were black blockers: they took 6% of the bins'
// weight).
TEST(Implicit, MazeFurnaceKeepsItsEnergy) {
    Scene scene = scenes::Maze().Build();
    for (Material& m : scene.materials) {
        m.albedo = glm::vec3(0.5f);
        m.emission = glm::vec3(1.0f);
    }
    SolverSettings s = Implicit(0.0f);  // the default element size
    auto solver = CreateSolver(scene, s);
    solver->Iterate(40);
    const std::vector<glm::vec3> e = testing::AllVertices(*solver, scene, Channel::kIndirect);
    const std::vector<glm::vec3> truth = Truth(scene, 256);
    double sum = 0.0, sumTruth = 0.0;
    for (size_t i = 0; i < e.size(); ++i) sum += e[i].x, sumTruth += truth[i].x;
    const double rms = testing::RelativeRms(e, truth);
    std::printf("maze furnace: %.4f relative RMS from 256 paths, total %.4f of the truth's\n", rms,
                sum / sumTruth);
    EXPECT_LT(rms, 0.10);
    EXPECT_NEAR(sum / sumTruth, 1.0, 0.06);
}

// Boxes standing on a floor under a constant sky, one without a bottom, one with: the floor
// under each sees only their far (inside) faces and stays dark, while the open floor around
// gets the sky (a closed solid's far faces stand for its near ones only where the receiver
// sees the near ones: from outside).
TEST(Implicit, FloorUnderABoxStaysDark) {
    SceneBuilder b;
    uint32_t grey = b.AddMaterial("grey", glm::vec3(0.5f));
    b.AddTiledQuad("ground", grey, {-2, 0, -2}, {4, 0, 0}, {0, 0, 4}, 16, 16, {0, 1, 0});
    b.AddBox("open_box", grey, {-0.75f, 0.5f, 0.0f}, {1.0f, 1.0f, 1.0f}, 0.0f, false);
    b.AddBox("closed_box", grey, {0.75f, 0.5f, 0.0f}, {1.0f, 1.0f, 1.0f}, 0.0f, true);
    Scene scene = b.Build();
    scene.environment = ConstantEnvironment(glm::vec3(1.0f));
    auto solver = CreateSolver(scene, Implicit(0.1f));
    solver->Iterate(5);
    const std::vector<glm::vec3> e = testing::AllVertices(*solver, scene, Channel::kIndirect);
    const std::vector<glm::vec3>& ground = scene.primitives[0].positions;
    ASSERT_EQ(scene.primitives[0].node, "ground");
    double under = 0.0, open = 0.0;
    for (size_t i = 0; i < ground.size(); ++i) {
        const glm::vec3& p = ground[i];
        const bool inside = std::abs(p.z) < 0.4f && std::abs(std::abs(p.x) - 0.75f) < 0.4f;
        if (inside) under = std::max(under, double(e[i].x));
        if (std::abs(p.z) > 1.5f) open = std::max(open, double(e[i].x));
    }
    std::printf("under the boxes: at most %.4f; open floor %.4f (π = %.4f)\n", under, open, kPi);
    EXPECT_GT(open, 0.5 * kPi);
    // Measured 1.5% of π (as before the rule): the grazing bins at the walls' foot, where
    // the inside faces' ends meet the floor's horizon.
    EXPECT_LT(under, 0.02 * kPi);
}

// The irradiance at the centre of a floor under one emitter facing it: the nearest floor
// vertex to (0, 0, 0), the first bounce only (the floor is black).
float CentreIrradiance(Scene scene) {
    auto solver = CreateSolver(scene, Implicit(0.05f));
    solver->Iterate(1);
    const Surfels& s = solver->GetSurfels();
    return solver
        ->SurfelIrradiance(
            Channel::kIndirect)[testing::NearestSurfel(s, glm::vec3(0.0f), glm::vec3(0, 1, 0))]
        .x;
}

// A patch far smaller than a bin: it covers its own solid angle of its bin, not the whole bin
// (the closest element standing for the bin would make it ten times too bright here):
// E = L A cosθ_r cosθ_e / d².
TEST(Implicit, SmallPatchCoversItsOwnSolidAngle) {
    SceneBuilder b;
    uint32_t black = b.AddMaterial("black", glm::vec3(0.0f));
    uint32_t lamp = b.AddMaterial("lamp", glm::vec3(0.0f), glm::vec3(10.0f));
    b.AddTiledQuad("floor", black, {-1, 0, -1}, {2, 0, 0}, {0, 0, 2}, 8, 8, {0, 1, 0});
    b.AddQuad("patch", lamp, {-0.05f, 1, -0.05f}, {0.05f, 1, -0.05f}, {0.05f, 1, 0.05f},
              {-0.05f, 1, 0.05f}, {0, 0, 0});
    const float e = CentreIrradiance(b.Build());
    const float expected = 10.0f * 0.01f / 1.0f;
    std::printf("small patch: E %.5f, expected %.5f\n", e, expected);
    EXPECT_NEAR(e, expected, 0.05f * expected);
}

// A lamp 1 cm under a ceiling (the clutter suite's panel; a light in its housing, books on a
// shelf): the lamp's faces lie in front of the ceiling's along every bin's axis, so they take
// the bins they cover before the ceiling behind them does. Ordered by their centres' distance
// instead, ceiling leaves beside the lamp came before lamp leaves farther out in the same
// bin, and the floor got 0.82 of the lamp's light at 128 bins, 0.70 at 864. Everything but
// the lamp is black and the solver carries the lamp's light itself (no first shot): the
// floor's light against the exact irradiance from the lamp's rectangle (Lambert's polygon
// formula), over the floor's surfels.
TEST(Implicit, LampUnderACeilingLightsTheFloor) {
    SceneBuilder b;
    scenes::AddClutterRoom(b, 1.0f, 0.0f);  // the panel: 0.6 m, 1 cm under the 2 m ceiling
    const float y = 1.99f, lo = 0.7f, hi = 1.3f;
    const std::vector<glm::vec3> panel = {{lo, y, lo}, {hi, y, lo}, {hi, y, hi}, {lo, y, hi}};
    const Scene scene = b.Build();
    // E = L/2 Σ over the rectangle's edges of the angle the edge subtends times the cosine
    // between the receiver's normal and the normal of the plane through the edge and the
    // receiver (the lamp's radiance L = 1).
    auto exact = [&](const glm::vec3& p, const glm::vec3& n) {
        double e = 0.0;
        for (size_t k = 0; k < panel.size(); ++k) {
            const glm::vec3 a = glm::normalize(panel[k] - p);
            const glm::vec3 c = glm::normalize(panel[(k + 1) % panel.size()] - p);
            const float angle = std::acos(std::clamp(glm::dot(a, c), -1.0f, 1.0f));
            e += 0.5 * angle * glm::dot(n, glm::normalize(glm::cross(a, c)));
        }
        return std::abs(e);
    };
    for (int bins : {128, 864}) {
        SolverSettings settings = Implicit(0.25f, bins);
        auto solver = CreateSolver(scene, settings);
        solver->Iterate(2);
        const std::vector<glm::vec3> e = solver->SurfelIrradiance(Channel::kIndirect);
        const Surfels& s = solver->GetSurfels();
        double got = 0.0, want = 0.0, worst = 0.0;
        for (size_t p = 0; p < scene.primitives.size(); ++p) {
            if (scene.primitives[p].node != "floor") continue;
            for (size_t i = s.firstSurfel[p]; i < s.End(p); ++i) {
                const double truth = exact(s.positions[i], s.normals[i]);
                got += e[i].x * s.areas[i];
                want += truth * s.areas[i];
                worst = std::max(worst, std::abs(e[i].x / truth - 1.0));
            }
        }
        std::printf(
            "lamp under a ceiling, %d bins: the floor's light %.4f of the exact, worst "
            "surfel %.1f%% off\n",
            bins, got / want, 100.0 * worst);
        EXPECT_GT(want, 0.0);
        EXPECT_NEAR(got / want, 1.0, 0.06) << bins << " bins";
    }
}

// A disc of radius r at height h over the receiver, wider than many bins: the bins it covers
// are full, those it only touches partly covered, E = π L r² / (r² + h²).
TEST(Implicit, CoaxialDiscFillsItsBins) {
    SceneBuilder b;
    uint32_t black = b.AddMaterial("black", glm::vec3(0.0f));
    uint32_t lamp = b.AddMaterial("lamp", glm::vec3(0.0f), glm::vec3(1.0f));
    b.AddTiledQuad("floor", black, {-1, 0, -1}, {2, 0, 0}, {0, 0, 2}, 8, 8, {0, 1, 0});
    // A 32-gon of radius r at height h, facing down.
    const float r = 0.5f, h = 0.5f;
    auto rim = [&](int k) {
        const float a = 2 * kPi * k / 32;
        return glm::vec3(r * std::cos(a), h, r * std::sin(a));
    };
    for (int k = 0; k < 32; k += 2)  // 16 quads: the centre and three rim points each
        b.AddQuad("disc", lamp, {0, h, 0}, rim(k), rim(k + 1), rim(k + 2), {0, 0, 0});
    const float e = CentreIrradiance(b.Build());
    const float polygon = 0.5f * 32 * r * r * std::sin(2 * kPi / 32);  // the 32-gon's area
    const float rEff = std::sqrt(polygon / kPi);
    const float expected = kPi * rEff * rEff / (rEff * rEff + h * h);
    std::printf("coaxial disc: E %.4f, expected %.4f\n", e, expected);
    // Measured 3.9% low at 128 bins (5.6% high while the rim's bins, covered more than half,
    // were filled though they border the black sky: session 34 fills only bins with no
    // near-empty neighbour). Under-filled bins would make it far too dark (the closest
    // element's own solid angle alone gave a room 13% of its light).
    EXPECT_NEAR(e, expected, 0.05f * expected);
}

// Two rooms side by side, split by a wall 2 cm thick (a fifth of an element): only one has
// a light. No light reaches the other room through the wall (the closest-layer rule hides
// the lit room behind the wall's near face): its floor gets at most 1% of the lit floor's.
TEST(Implicit, ThinWallKeepsTheDarkRoomDark) {
    const Scene scene = testing::ThinWallRooms(0.02f);
    auto solver = CreateSolver(scene, Implicit(0.1f));
    solver->Iterate(20);
    const std::vector<glm::vec3> e = solver->SurfelIrradiance(Channel::kIndirect);
    const Surfels& s = solver->GetSurfels();
    double lit = 0.0, dark = 0.0;
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        const std::string& node = scene.primitives[p].node;
        if (node != "floor_lit" && node != "floor_dark") continue;
        double& sum = node == "floor_lit" ? lit : dark;
        for (size_t i = s.firstSurfel[p]; i < s.End(p); ++i) sum += e[i].x * s.areas[i];
    }
    std::printf("thin wall: dark floor %.5f of the lit floor's light\n", dark / lit);
    EXPECT_GT(lit, 0.0);
    EXPECT_LT(dark, 0.01 * lit);
}

// A thin slab floating over a glowing floor, seen from above: the slab (2 cm, a fifth of an
// element) hides the floor behind its outline and no more. Its far face lies within `thin` of
// its near one, so inside the outline it fills the gaps the near face's ends leave; at the
// outline it added its coverage to the near face's and made the slab look larger (the
// blocker's emitter 15% bright with the gather off). E = π L (F_floor − F_slab), the form
// factors of a point to parallel rectangles (sums of corner rectangles, closed form).
TEST(Implicit, ThinSlabHidesOnlyItsOutline) {
    SceneBuilder b;
    const uint32_t black = b.AddMaterial("black", glm::vec3(0.0f));
    const uint32_t glow = b.AddMaterial("glow", glm::vec3(0.0f), glm::vec3(1.0f));
    b.AddQuad("floor", glow, {-2, 0, -2}, {2, 0, -2}, {2, 0, 2}, {-2, 0, 2}, {0, 1, 0}, 16);
    b.AddBox("slab", black, {0.0f, 0.5f, 0.0f}, {0.6f, 0.02f, 0.6f});
    b.AddQuad("receiver", black, {-0.01f, 1, -0.01f}, {0.01f, 1, -0.01f}, {0.01f, 1, 0.01f},
              {-0.01f, 1, 0.01f}, {0, 0, 0});
    const Scene scene = b.Build();
    ASSERT_EQ(scene.primitives.back().node, "receiver");
    auto solver = CreateSolver(scene, Implicit(0.1f, 512));
    solver->Iterate(2);
    const std::vector<glm::vec3> e = testing::AllVertices(*solver, scene, Channel::kIndirect);
    // Form factor from a point at height c over a corner of an a × b rectangle, facing it.
    auto corner = [](double a, double b2, double c) {
        const double x = a / c, y = b2 / c, sx = std::sqrt(1 + x * x), sy = std::sqrt(1 + y * y);
        return (x / sx * std::atan(y / sx) + y / sy * std::atan(x / sy)) / (2 * std::numbers::pi);
    };
    // ... of a square of side `side` centred under the point (px, pz) at height c.
    auto square = [&](double side, double px, double pz, double c) {
        double f = 0.0;
        for (double sx : {-1.0, 1.0})
            for (double sz : {-1.0, 1.0}) f += corner(side / 2 + sx * px, side / 2 + sz * pz, c);
        return f;
    };
    const std::vector<glm::vec3>& at = scene.primitives.back().positions;
    const size_t first = e.size() - at.size();
    double got = 0.0, want = 0.0;
    for (size_t i = 0; i < at.size(); ++i) {
        got += e[first + i].x;
        want += std::numbers::pi *
                (square(4.0, at[i].x, at[i].z, 1.0) - square(0.6, at[i].x, at[i].z, 1.0 - 0.51));
    }
    got /= double(at.size());
    want /= double(at.size());
    std::printf("over a thin slab: E %.4f, expected %.4f (%+.1f%%)\n", got, want,
                100.0 * (got / want - 1.0));
    // Measured −0.6% (−5.0% when the far face added its coverage at the outline too); the
    // bound leaves the bins' quantisation of the outline its margin.
    EXPECT_NEAR(got, want, 0.025 * want);
}

// A room's edges: a 2 m cube room, its floor emitting 1 nit, every surface black, so that a
// wall receives the floor's light alone, E = ∫ cos θ_r cos θ_e / d² dA over the floor. Along
// a wall's middle row the corner vertices see the other wall edge-on from a few centimetres:
// when its leaves covered the round cones of their bounding spheres, they took the bins that
// look past them into the room (16% low here; half the truth in the glossy box's empty room).
TEST(Implicit, RoomCornersSeeTheRoom) {
    SceneBuilder b;
    const uint32_t black = b.AddMaterial("black", glm::vec3(0.0f));
    const uint32_t glow = b.AddMaterial("glow", glm::vec3(0.0f), glm::vec3(1.0f));
    const glm::vec3 c(1.0f);  // the room's centre: every face looks at it
    auto quad = [&](const char* node, uint32_t m, glm::vec3 o, glm::vec3 u, glm::vec3 v) {
        b.AddQuad(node, m, o, o + u, o + u + v, o + v, c, 8);
    };
    quad("floor", glow, {0, 0, 0}, {2, 0, 0}, {0, 0, 2});
    quad("ceiling", black, {0, 2, 0}, {2, 0, 0}, {0, 0, 2});
    quad("south", black, {0, 0, 0}, {2, 0, 0}, {0, 2, 0});
    quad("north", black, {0, 0, 2}, {2, 0, 0}, {0, 2, 0});
    quad("west", black, {0, 0, 0}, {0, 0, 2}, {0, 2, 0});
    quad("east", black, {2, 0, 0}, {0, 0, 2}, {0, 2, 0});
    const Scene scene = b.Build();
    auto solver = CreateSolver(scene, Implicit(0.1f));
    solver->Iterate(2);
    const std::vector<glm::vec3> e = solver->SurfelIrradiance(Channel::kIndirect);
    const Surfels& s = solver->GetSurfels();
    // Midpoint rule over the floor, 400 × 400 cells.
    auto truth = [](glm::vec3 q) {
        const int n = 400;
        const double h = 2.0 / n;
        double sum = 0.0;
        for (int i = 0; i < n; ++i)
            for (int k = 0; k < n; ++k) {
                const glm::dvec3 d((i + 0.5) * h - q.x, -q.y, (k + 0.5) * h - q.z);
                const double d2 = glm::dot(d, d);
                sum += d.z * q.y / (d2 * d2);  // cos θ_r = d.z / |d| (normal +z), cos θ_e = y / |d|
            }
        return sum * h * h;
    };
    double worst = 0.0, worstCorner = 0.0;
    int corners = 0;
    for (size_t p = 0; p < scene.primitives.size(); ++p) {
        if (scene.primitives[p].node != "south") continue;
        for (size_t i = s.firstSurfel[p]; i < s.End(p); ++i) {
            const glm::vec3 q = s.positions[i];
            if (std::abs(q.y - 1.0f) > 1e-3f ||
                i >= s.firstSurfel[p] + scene.primitives[p].positions.size())
                continue;  // the input vertices of the middle row
            const double t = truth(q), off = std::abs(e[i].x / t - 1.0);
            worst = std::max(worst, off);
            if (q.x < 1e-3f || q.x > 2.0f - 1e-3f) {
                worstCorner = std::max(worstCorner, off);
                ++corners;
            }
        }
    }
    std::printf("room corners: worst corner %.1f%% off, worst of the row %.1f%%\n",
                100 * worstCorner, 100 * worst);
    EXPECT_EQ(corners, 2);
    // Measured 4.6% (15.7% before). The row's worst, 12% low inside, is the bins' own error
    // (the same before): the bound catches a regression there.
    EXPECT_LT(worstCorner, 0.08);
    EXPECT_LT(worst, 0.15);
}

// The hierarchy should only save work: links between clusters no wider than half a bin
// against links between every pair of elements (a threshold so small that every pair is
// split down to its leaves), the Cornell box at coarse elements.
TEST(Implicit, HierarchicalLinksMatchBruteForce) {
    Scene scene = scenes::CornellBox().Build();
    SolverSettings settings = Implicit(0.08f);
    ImplicitSolver hierarchical(scene, settings, ReadImplicitSettings(settings), {});
    ImplicitSettings every = ReadImplicitSettings(settings);
    every.linkThreshold = 1e-6f;
    ImplicitSolver brute(scene, settings, every, {});
    hierarchical.Iterate(20);
    brute.Iterate(20);
    const double rel =
        testing::RelativeRms(testing::AllVertices(hierarchical, scene, Channel::kIndirect),
                             testing::AllVertices(brute, scene, Channel::kIndirect));
    std::printf("hierarchical (%zu pairs) against every pair (%zu): %.4f relative RMS\n",
                hierarchical.Links().pairs, brute.Links().pairs, rel);
    // Measured 54% (605,937 of 1,127,879): the default threshold (0.2) splits finely, and in a
    // box this coarse few pairs lie far apart.
    EXPECT_LT(hierarchical.Links().pairs, brute.Links().pairs * 6 / 10);
    // Measured 4.2% (7.4% at session 40's threshold 0.5 with the sphere's whole disc as an end's
    // size): a cluster's link, measured from the cluster's centre, stands for all its leaves in
    // one bin and one layer order. Against the truth the brute force is 12.5% off, the
    // hierarchy 13.8% (docs/STATUS.md, issue 21; session 36). This bound catches a regression.
    EXPECT_LT(rel, 0.06);

    // At the defaults the emitters' direct light is the first shot and the links carry the
    // bounces only: measured 0.94% (the goal is 1%; 1.30% in session 40, at a threshold
    // of 0.5 without the foreshortening, 549K pairs).
    GatherSettings shot;
    shot.gatherRays = 0;
    auto withShot = [&](const ImplicitSettings& own) {
        auto s = WithGather(std::make_unique<ImplicitSolver>(scene, settings, own, ProgressFn{}),
                            scene, shot);
        s->Iterate(20);
        return testing::AllVertices(*s, scene, Channel::kIndirect);
    };
    const double shotRel =
        testing::RelativeRms(withShot(ReadImplicitSettings(settings)), withShot(every));
    std::printf("with the first shot: %.4f relative RMS\n", shotRel);
    EXPECT_LT(shotRel, 0.01);
}

// The Vulkan back end creates the links, composites the leaves' bins and bounces on the device
// (lavapipe, or a GPU under PENUMBRA_TEST_VULKAN=gpu; validation on): the same links and answers as
// the CPU's, up to the device's float rounding at a split or bin boundary, at rest (the Cornell
// box) and after a move (a box on a floor under a sky, moved and turned: the device examines every
// pair again).
TEST(Implicit, VulkanLinkCreationMatchesTheCpu) {
    auto compare = [](const Scene& scene, Solver& cpu, Solver& device, const char* what) {
        const auto& a = dynamic_cast<ImplicitSolver&>(cpu).Links();
        const auto& b = dynamic_cast<ImplicitSolver&>(device).Links();
        const double rel =
            testing::RelativeRms(testing::AllVertices(device, scene, Channel::kIndirect),
                                 testing::AllVertices(cpu, scene, Channel::kIndirect));
        std::printf("%s: pairs %zu / %zu, linked %zu / %zu, shares %zu / %zu, %.2e relative RMS\n",
                    what, b.pairs, a.pairs, b.linked, a.linked, b.Count(), a.Count(), rel);
        // Measured on lavapipe: the same pairs and links; the device's acos rounds otherwise,
        // so a few spread ends' overlaps with a bin fall on the other side of the smallest
        // kept (35 of 775,264 shares on the Cornell box), the answers 1.1·10⁻⁴ and 9·10⁻⁶
        // apart. A real GPU's arithmetic is looser still (Vulkan allows a division 2.5 ulp,
        // and its compiler fuses multiply-adds): on an H200 (session 46) the same pairs and
        // links, shares 6 of 913,123 and 35 of 277,990 apart, the answers 2.1·10⁻³ and
        // 3.8·10⁻⁵ apart (ends that tie up to rounding, a lamp's leaves and the ceiling's
        // about it, order otherwise).
        const bool gpu = testing::TestOnRealGpu();
        EXPECT_NEAR(double(b.pairs), double(a.pairs), 1e-4 * double(a.pairs)) << what;
        EXPECT_NEAR(double(b.linked), double(a.linked), 1e-4 * double(a.linked)) << what;
        EXPECT_NEAR(double(b.Count()), double(a.Count()), (gpu ? 3e-4 : 1e-4) * double(a.Count()))
            << what;
        EXPECT_LT(rel, gpu ? 5e-3 : 5e-4) << what;
        const SolverStats stats = device.Stats();
        EXPECT_NE(stats.Text("link_device"), "cpu");
        EXPECT_GT(stats.Number("device_rounds"), 10.0);
        EXPECT_EQ(stats.Text("composite_device"), stats.Text("link_device")) << what;
        EXPECT_EQ(stats.Text("bounce_device"), stats.Text("link_device"));
        EXPECT_EQ(stats.Number("device_bounces"), double(stats.iterations)) << what;
        // The device's own time (timestamps around each submission) within each pass's wall
        // time, which also holds the host's uploads, waits and read-backs.
        for (const char* pass : {"create", "composite", "bounce"}) {
            const std::string d = std::string("device_") + pass;
            EXPECT_GT(stats.Number(d + "_busy_ms"), 0.0) << what << " " << pass;
            EXPECT_LE(stats.Number(d + "_busy_ms"), stats.Number(d + "_ms")) << what << " " << pass;
        }
        for (const auto& m : device.ValidationMessages()) ADD_FAILURE() << "validation: " << m;
    };
    SolverSettings onDevice = Implicit(0.06f);
    onDevice.device = testing::TestVulkanChoice();
    onDevice.validation = true;
    {
        Scene scene = scenes::CornellBox().Build();
        auto cpu = CreateSolver(scene, Implicit(0.06f));
        auto device = CreateSolver(scene, onDevice);
        cpu->Iterate(10);
        device->Iterate(10);
        compare(scene, *cpu, *device, "Cornell box");
    }
    Scene scene = BoxOnGroundUnderASky();
    auto cpu = CreateSolver(scene, Implicit(0.08f));
    SolverSettings moving = onDevice;
    moving.elementSize = 0.08f;
    auto device = CreateSolver(scene, moving);
    const int node = FindNode(scene, "box");
    SetNodeTransform(scene, node,
                     glm::translate(glm::mat4(1.0f), glm::vec3(0.3f, 0.0f, -0.2f)) *
                         scene.nodes[node].local *
                         glm::rotate(glm::mat4(1.0f), glm::radians(25.0f), glm::vec3(0, 1, 0)));
    for (Solver* s : {cpu.get(), device.get()}) {
        ASSERT_EQ(s->GeometryMismatch(scene), "");
        s->UpdateGeometry(scene);
        s->Iterate(20);
    }
    compare(scene, *cpu, *device, "moved box");
}

// The device's bounce (shaders/implicit_bounce.comp) against its definition, on a hierarchy
// of a real scene with shares of every kind drawn at random: each leaf's row of exitant
// intensity A L cos⁺(n, ω_b), the clusters' rows and Σ A L the sums of their children's, the
// environment after them; a leaf gathers Σ factor · table[index] over its shares. Then the
// solver on lavapipe with glossy leaves bounces on the host and says why.
TEST(Implicit, VulkanBounceMatchesItsDefinition) {
    Scene scene = scenes::CornellBox().Build();
    const Surfels surfels = RefineScene(scene, 0.15f);
    const Hierarchy h = BuildHierarchy(surfels);
    const Directions dirs(64);
    const size_t bins = size_t(dirs.Count()), nodes = h.size(), leaves = h.leaves.size();
    std::mt19937 rng(7);
    std::uniform_real_distribution<float> unit(0.0f, 1.0f);
    std::vector<glm::vec3> radiance(leaves), environment(bins);
    for (auto& l : radiance) l = {unit(rng), unit(rng), unit(rng)};
    for (auto& l : environment) l = {unit(rng), unit(rng), unit(rng)};
    // The table as defined, on the host.
    std::vector<glm::dvec3> table(nodes * bins + nodes + bins);
    for (size_t i = 0; i < leaves; ++i) {
        const HierarchyNode& n = h.nodes[h.leaves[i]];
        for (size_t b = 0; b < bins; ++b)
            table[h.leaves[i] * bins + b] = glm::dvec3(
                n.area * std::max(0.0f, glm::dot(n.normal, dirs.Direction(uint32_t(b)))) *
                radiance[i]);
        table[nodes * bins + h.leaves[i]] = glm::dvec3(n.area * radiance[i]);
    }
    for (size_t n = nodes; n-- > 0;) {  // preorder: children after their parent
        if (h.nodes[n].IsLeaf()) continue;
        const size_t l = n + 1, r = h.nodes[n + 1].end;
        for (size_t b = 0; b < bins; ++b)
            table[n * bins + b] = table[l * bins + b] + table[r * bins + b];
        table[nodes * bins + n] = table[nodes * bins + l] + table[nodes * bins + r];
    }
    for (size_t b = 0; b < bins; ++b) table[nodes * bins + nodes + b] = glm::dvec3(environment[b]);
    std::vector<uint32_t> offsets{0}, at;
    std::vector<float> factor;
    std::uniform_int_distribution<uint32_t> pick(0, uint32_t(table.size() - 1));
    for (size_t i = 0; i < leaves; ++i) {
        const uint32_t count = pick(rng) % 40;  // some leaves without shares
        for (uint32_t k = 0; k < count; ++k) at.push_back(pick(rng)), factor.push_back(unit(rng));
        offsets.push_back(uint32_t(at.size()));
    }
    gpu::Context ctx(testing::TestVulkanKind(), true);
    VulkanBounce bounce(ctx, dirs, h);
    ASSERT_EQ(bounce.Unfit(at.size()), "");
    bounce.SetShares(h, offsets, at, factor);
    for (int round = 0; round < 2; ++round) {  // the table rewritten whole by the second
        const std::vector<glm::vec3> got = bounce.Gather(radiance, environment);
        ASSERT_EQ(got.size(), leaves);
        double worst = 0.0;
        for (size_t i = 0; i < leaves; ++i) {
            glm::dvec3 e(0.0);
            for (uint32_t k = offsets[i]; k < offsets[i + 1]; ++k)
                e += double(factor[k]) * table[at[k]];
            for (int c = 0; c < 3; ++c)
                worst =
                    std::max(worst, std::abs(got[i][c] - e[c]) / std::max(1e-3, std::abs(e[c])));
        }
        std::printf("device bounce against its definition: %zu leaves, %zu shares, worst %.2e\n",
                    leaves, at.size(), worst);
        EXPECT_LT(worst, 1e-4);  // float sums in another order
        for (auto& l : radiance) l *= 0.5f;
        for (size_t n = 0; n < nodes * bins + nodes; ++n) table[n] *= 0.5;
    }
    for (const auto& m : ctx.ValidationMessages()) ADD_FAILURE() << "validation: " << m;

    SceneBuilder b;
    const Scene glossy =
        testing::SkyFurnaceRoom(b, b.AddPbrMaterial("white", glm::vec3(1.0f), 1.0f, 0.5f), 4);
    SolverSettings onDevice = Implicit(0.2f);
    onDevice.device = testing::TestVulkanChoice();
    onDevice.validation = true;
    auto solver = CreateSolver(glossy, onDevice);
    solver->Iterate(2);
    const SolverStats stats = solver->Stats();
    EXPECT_EQ(stats.Text("bounce_device"), "cpu");
    EXPECT_EQ(stats.Text("bounce_on_host"), "glossy leaves");
    EXPECT_EQ(stats.Number("device_bounces"), 0.0);
    for (const auto& m : solver->ValidationMessages()) ADD_FAILURE() << "validation: " << m;
}

// The device's rounds in chunks (a list of pairs or ends held to 64 KiB, so that a round goes
// up in many chunks and a chunk whose ends overflow runs again, larger or halved): the same
// links as the device's rounds whole, and as the CPU's linker from the same hierarchy up to
// the device's rounding (VulkanLinkCreationMatchesTheCpu); the closest rule's table held to
// its size and a byte less.
TEST(Implicit, VulkanLinkCreationInChunksMatchesTheCpu) {
    Scene scene = scenes::CornellBox().Build();
    ImplicitSolver solver(scene, Implicit(0.08f), ReadImplicitSettings(Implicit(0.08f)), {});
    const Hierarchy& h = solver.GetHierarchy();
    ImplicitLinks cpu, whole, chunked;
    ImplicitLinker(solver.GetDirections(), 0.5f).Build(h, solver.ProjectedAreas(), {}, 0.0f, cpu);
    gpu::Context ctx(testing::TestVulkanKind(), /*validation=*/true);
    auto onDevice = [&](size_t bytes, ImplicitLinks& out) {
        VulkanLinkCreation creation(ctx, solver.GetDirections(), 0.5f, bytes);
        ImplicitLinker linker(solver.GetDirections(), 0.5f);
        linker.UseDevice(&creation);
        linker.Build(h, solver.ProjectedAreas(), {}, 0.0f, out);
        return creation.rounds;
    };
    const size_t rounds = onDevice(0, whole);
    const size_t chunks = onDevice(size_t(64) << 10, chunked);
    std::printf("%zu pairs, %zu shares (CPU %zu), %zu dispatches whole, %zu in chunks\n",
                chunked.pairs, chunked.Count(), cpu.Count(), rounds, chunks);
    EXPECT_GT(chunks, 100u);
    EXPECT_LT(rounds, 40u);
    ExpectSameLinks(chunked, whole);
    EXPECT_EQ(chunked.pairs, cpu.pairs);
    EXPECT_EQ(chunked.linked, cpu.linked);
    EXPECT_NEAR(double(chunked.Count()), double(cpu.Count()), 1e-4 * double(cpu.Count()));

    // The closest rule (`bin-cover closest`): each slot's closest link kept on the device by
    // 64-bit atomicMin where its table fits the limit (the rounds in chunks), else made on the
    // CPU, saying why; the CPU's links either way (a real GPU may take another sender where
    // two tie up to rounding).
    const Directions& dirs = solver.GetDirections();
    ImplicitLinks closestCpu;
    ImplicitLinker(dirs, 0.5f, true).Build(h, solver.ProjectedAreas(), {}, 0.0f, closestCpu);
    const size_t table = h.nodes.size() * size_t(dirs.Count()) * sizeof(uint64_t);
    for (const size_t bytes : {table, table - 1}) {
        VulkanLinkCreation creation(ctx, dirs, 0.5f, bytes, /*closest=*/true);
        ImplicitLinker linker(dirs, 0.5f, true);
        linker.UseDevice(&creation);
        ImplicitLinks out;
        linker.Build(h, solver.ProjectedAreas(), {}, 0.0f, out);
        const bool fits = bytes == table;
        EXPECT_EQ(linker.LinkedOnHostBecause().empty(), fits) << linker.LinkedOnHostBecause();
        if (fits) {
            EXPECT_GT(creation.rounds, 0u);
        }
        EXPECT_EQ(out.pairs, closestCpu.pairs);
        EXPECT_EQ(out.linked, closestCpu.linked);
        ASSERT_EQ(out.offsets, closestCpu.offsets);
        ASSERT_EQ(out.bin, closestCpu.bin);
        size_t other = 0;
        for (size_t k = 0; k < out.sender.size(); ++k)
            other += out.sender[k] != closestCpu.sender[k];
        std::printf("closest rule, %s: %zu of %zu shares with another sender\n",
                    fits ? "on the device" : "on the CPU", other, out.sender.size());
        EXPECT_LE(double(other),
                  (fits && testing::TestOnRealGpu() ? 3e-4 : 0.0) * double(out.sender.size()));
    }
    for (const std::string& m : ctx.ValidationMessages()) ADD_FAILURE() << "validation: " << m;
}

// The device's compositing (vulkan_composite.h) against the CPU's, from the same ends (the
// device's rounds): the Cornell box, whose blocks are closed solids (their far faces, their
// outlines), and a box on a floor under a sky (bins partly covered at its silhouette, the
// environment). The same shares in the same order, each with the same bin, sender and travel,
// the weights within float rounding.
TEST(Implicit, VulkanCompositingMatchesTheCpu) {
    gpu::Context ctx(testing::TestVulkanKind(), /*validation=*/true);
    auto check = [&](const Scene& scene, float element, const char* what) {
        ImplicitSolver solver(scene, Implicit(element), ReadImplicitSettings(Implicit(element)),
                              {});
        const Directions& dirs = solver.GetDirections();
        VulkanLinkCreation creation(ctx, dirs, 0.5f);
        ImplicitLinker onHost(dirs, 0.5f), onDevice(dirs, 0.5f);
        onHost.UseDevice(&creation);
        onDevice.UseDevice(&creation);
        VulkanCompositing composite(ctx, dirs, onDevice.BinRadius());
        onDevice.UseDeviceCompositing(&composite);
        ImplicitLinks a, b;
        onHost.Build(solver.GetHierarchy(), solver.ProjectedAreas(), solver.Solids(), element, a);
        onDevice.Build(solver.GetHierarchy(), solver.ProjectedAreas(), solver.Solids(), element, b);
        EXPECT_FALSE(onHost.CompositedOnDevice());
        ASSERT_TRUE(onDevice.CompositedOnDevice()) << onDevice.CompositedOnHostBecause();
        ASSERT_EQ(a.sender.size(), b.sender.size()) << what;
        EXPECT_EQ(a.offsets, b.offsets) << what;
        size_t other = 0;
        double worst = 0.0;
        for (size_t k = 0; k < a.sender.size(); ++k) {
            if (a.bin[k] != b.bin[k] || a.sender[k] != b.sender[k] || a.travel[k] != b.travel[k]) {
                if (other++ < 5)
                    std::printf("%s: share %zu: bin %u / %u, sender %u / %u, travel %u / %u\n",
                                what, k, a.bin[k], b.bin[k], a.sender[k], b.sender[k], a.travel[k],
                                b.travel[k]);
                continue;
            }
            worst = std::max(worst, double(std::abs(a.weight[k] - b.weight[k])) /
                                        std::max(1e-12, double(std::abs(a.weight[k]))));
        }
        std::printf("%s: %zu shares (%zu of the environment), %zu differ, weights %.2e apart\n",
                    what, a.sender.size(), a.empty, other, worst);
        // On lavapipe the same shares bit for bit. On a real GPU, whose arithmetic is looser
        // (VulkanLinkCreationMatchesTheCpu), a few ends that tie up to rounding take another
        // order: on an H200 7 of the Cornell box's 348,434 shares had another sender.
        if (testing::TestOnRealGpu())
            EXPECT_LE(double(other), 1e-4 * double(a.sender.size())) << what;
        else
            EXPECT_EQ(other, 0u) << what;
        EXPECT_EQ(a.empty, b.empty) << what;
        EXPECT_LT(worst, 1e-5) << what;
        if (std::string(what) == "Cornell box") {  // its blocks: the solids' rules ran
            EXPECT_FALSE(solver.Solids().empty());
        }
    };
    check(scenes::CornellBox().Build(), 0.08f, "Cornell box");
    check(BoxOnGroundUnderASky(), 0.1f, "box under a sky");
    // A bin that meets more closed solids than the device tracks (one here: the Cornell box's
    // two blocks seen through one bin) is composited on the host, the same shares, and the
    // linker says why.
    Scene cornell = scenes::CornellBox().Build();
    ImplicitSolver solver(cornell, Implicit(0.08f), ReadImplicitSettings(Implicit(0.08f)), {});
    const Directions& dirs = solver.GetDirections();
    VulkanLinkCreation creation(ctx, dirs, 0.5f);
    ImplicitLinker onHost(dirs, 0.5f), fallsBack(dirs, 0.5f);
    onHost.UseDevice(&creation);
    fallsBack.UseDevice(&creation);
    VulkanCompositing one(ctx, dirs, fallsBack.BinRadius(), /*mostSolids=*/1);
    fallsBack.UseDeviceCompositing(&one);
    ImplicitLinks a, b;
    onHost.Build(solver.GetHierarchy(), solver.ProjectedAreas(), solver.Solids(), 0.08f, a);
    fallsBack.Build(solver.GetHierarchy(), solver.ProjectedAreas(), solver.Solids(), 0.08f, b);
    EXPECT_FALSE(fallsBack.CompositedOnDevice());
    EXPECT_NE(fallsBack.CompositedOnHostBecause().find("closed solids"), std::string::npos)
        << fallsBack.CompositedOnHostBecause();
    EXPECT_EQ(one.runs, 0u);
    ExpectSameLinks(a, b);
    for (const std::string& m : ctx.ValidationMessages()) ADD_FAILURE() << "validation: " << m;
}

// Any move is taken in place (the links are rebuilt every frame): a box on a floor under a sky,
// moved and turned, its links rebuilt on the refitted hierarchy, lands near a solver built
// afresh at the new pose (whose hierarchy is clustered there; the answers differ only by
// that).
TEST(Implicit, AMoveLandsNearAFreshBuild) {
    Scene scene = BoxOnGroundUnderASky();
    auto solver = CreateSolver(scene, Implicit(0.08f));
    solver->Iterate(30);
    const std::vector<glm::vec3> before = testing::AllVertices(*solver, scene, Channel::kIndirect);
    const int node = FindNode(scene, "box");
    const glm::mat4 moved = glm::translate(glm::mat4(1.0f), glm::vec3(0.3f, 0.0f, -0.2f)) *
                            scene.nodes[node].local *
                            glm::rotate(glm::mat4(1.0f), glm::radians(25.0f), glm::vec3(0, 1, 0));
    SetNodeTransform(scene, node, moved);
    ASSERT_EQ(solver->GeometryMismatch(scene), "");
    const std::string note = solver->UpdateGeometry(scene);
    EXPECT_NE(note.find("links rebuilt in place"), std::string::npos) << note;
    // The check and the update refine the moved scene once between them (the service calls
    // both for every move).
    EXPECT_EQ(solver->Stats().Number("refinements"), 1.0);
    solver->Iterate(20);
    auto fresh = CreateSolver(scene, Implicit(0.08f));
    fresh->Iterate(30);
    const double rel =
        testing::RelativeRms(testing::AllVertices(*solver, scene, Channel::kIndirect),
                             testing::AllVertices(*fresh, scene, Channel::kIndirect));
    std::printf("moved in place against a fresh build: %.4f relative RMS\n", rel);
    EXPECT_LT(rel, 0.03);
    // And the move changed the answer (the shadow went with the box).
    EXPECT_GT(testing::RelativeRms(before, testing::AllVertices(*fresh, scene, Channel::kIndirect)),
              3 * rel);
    // A scene with other primitives is refused with the reason.
    Scene fewer = scene;
    fewer.primitives.pop_back();
    EXPECT_NE(solver->GeometryMismatch(fewer).find("other primitives"), std::string::npos);
}

// A deformation (the bundled blob's morph targets posed) is taken in place: the hierarchy
// refitted and the links made again. A fresh build at the pose clusters the deformed
// surfels otherwise, so the two differ by what the hierarchy's links approximate (the
// hierarchical-vs-brute-force item of docs/SOLVER.md: 6.6% here); against the path tracer
// the in-place answer must be as good as the fresh one.
TEST(Implicit, ADeformationIsAsGoodAsAFreshBuild) {
    Scene scene = scenes::MorphRoom().Build();
    const SolverSettings settings = Implicit(0.12f, 64);
    auto solver = CreateSolver(scene, settings);
    solver->Iterate(30);
    const std::vector<glm::vec3> before = testing::AllVertices(*solver, scene, Channel::kIndirect);
    const int blob = FindNode(scene, "blob");
    SetNodeMorphWeights(scene, blob, {0.9f, 0.6f});
    ASSERT_EQ(solver->GeometryMismatch(scene), "");
    const std::string note = solver->UpdateGeometry(scene);
    EXPECT_NE(note.find("links rebuilt in place"), std::string::npos) << note;
    EXPECT_EQ(solver->Stats().Number("refinements"), 1.0);  // checked and taken: refined once
    solver->Iterate(20);
    auto fresh = CreateSolver(scene, settings);
    fresh->Iterate(30);
    const std::vector<glm::vec3> now = testing::AllVertices(*solver, scene, Channel::kIndirect),
                                 rebuilt = testing::AllVertices(*fresh, scene, Channel::kIndirect);
    const std::vector<glm::vec3> truth = Truth(scene, 512);
    const double inPlace = testing::RelativeRms(now, truth),
                 fromScratch = testing::RelativeRms(rebuilt, truth),
                 apart = testing::RelativeRms(now, rebuilt),
                 changed = testing::RelativeRms(before, rebuilt);
    std::printf(
        "against 512 paths: deformed in place %.4f, a fresh build %.4f (%.4f apart); the "
        "pose changed the answer by %.4f\n",
        inPlace, fromScratch, apart, changed);
    EXPECT_LT(inPlace, fromScratch + 0.01);
    EXPECT_LT(apart, 0.1);
    EXPECT_GT(changed, 3 * apart);  // the pose changed the answer, and it followed
}

// A mesh deforming over 100 frames, one relink and one bounce a frame (the paper's Table 1
// loop): every frame finite and within the furnace bound, and no more temporal aliasing than
// the bounds stated in docs/SOLVER.md ("Deformations"): the room's frame-to-frame change at
// most 3% (relative RMS; measured 2.38%; 2.0% before session 41's foreshortened ends: the
// blob's clusters seen edge-on from the room now link whole, and their links change as the
// blob bends), the whole answer's at most 5% (measured 3.4%, 15.3% before them: the blob's
// own vertices jumped when its surface passed through convex and neighbouring elements left
// each other's horizon), and once the mesh stops, the answer settles within 3% of a fresh
// build.
TEST(Implicit, ADeformingMeshOverAHundredFramesStaysBoundedAndSmooth) {
    Scene scene = scenes::MorphRoom().Build();
    const SolverSettings settings = Implicit(0.15f, 64);
    auto solver = CreateSolver(scene, settings);
    solver->Iterate(20);
    const int blob = FindNode(scene, "blob");
    std::vector<uint8_t> room;  // per output vertex: not on the blob
    for (const Primitive& p : scene.primitives)
        room.insert(room.end(), p.positions.size(), p.node != "blob");
    auto change = [&](const std::vector<glm::vec3>& a, const std::vector<glm::vec3>& b,
                      bool roomOnly) {
        double num = 0, den = 0;
        for (size_t i = 0; i < a.size(); ++i) {
            if (roomOnly && !room[i]) continue;
            num += glm::dot(a[i] - b[i], a[i] - b[i]);
            den += glm::dot(b[i], b[i]);
        }
        return std::sqrt(num / den);
    };
    std::vector<glm::vec3> last = testing::AllVertices(*solver, scene, Channel::kIndirect);
    double worstRoom = 0.0, worstAll = 0.0;
    for (int f = 1; f <= 100; ++f) {
        const float t = float(f) / 100.0f;
        SetNodeMorphWeights(
            scene, blob, {0.5f - 0.5f * std::cos(2.0f * kPi * t), 0.8f * std::sin(2.0f * kPi * t)});
        ASSERT_EQ(solver->GeometryMismatch(scene), "") << "frame " << f;
        solver->UpdateGeometry(scene);
        solver->Iterate(1);
        const SolverStats stats = solver->Stats();
        ASSERT_TRUE(stats.divergence.empty()) << "frame " << f << ": " << stats.divergence;
        std::vector<glm::vec3> now = testing::AllVertices(*solver, scene, Channel::kIndirect);
        float peak = 0.0f;
        for (const glm::vec3& e : now)
            for (int c = 0; c < 3; ++c) {
                ASSERT_TRUE(std::isfinite(e[c])) << "frame " << f;
                peak = std::max(peak, e[c]);
            }
        ASSERT_LE(peak, stats.irradianceBound) << "frame " << f;
        worstRoom = std::max(worstRoom, change(now, last, true));
        worstAll = std::max(worstAll, change(now, last, false));
        last = std::move(now);
    }
    std::printf("largest frame-to-frame change: the room %.4f, everything %.4f\n", worstRoom,
                worstAll);
    EXPECT_LT(worstRoom, 0.03);
    EXPECT_LT(worstAll, 0.05);
    // Every relink after the first deformation kept the links of the pairs away from the blob.
    EXPECT_EQ(solver->Stats().Number("relinks_kept"), 99.0);
    solver->Iterate(20);
    const double rel = ApartFromAFreshBuild(*solver, scene, settings, 40);
    std::printf("after 100 frames, settled, against a fresh build: %.4f relative RMS\n", rel);
    EXPECT_LT(rel, 0.03);
}

// The links of a deformation with the unmoved pairs' links kept (ImplicitLinker::Build's
// `moving`) are those of a full build at the new pose, to the bit, pose after pose; a move
// outside the kept set builds everything again.
TEST(Implicit, KeptLinksEqualAFullBuild) {
    Scene scene = scenes::MorphRoom().Build();
    const int blob = FindNode(scene, "blob");
    const Directions dirs(64);
    Surfels surfels = RefineScene(scene, 0.15f);
    Hierarchy h = BuildHierarchy(surfels);
    RefitHierarchy(h,
                   surfels);  // as the solver's Relink: the clusters' spheres from their children's
    const size_t bins = size_t(dirs.Count());
    auto frontArea = [&] {  // as the solver's Relink: per leaf A cos⁺, summed up the tree
        std::vector<float> fa(h.size() * bins, 0.0f);
        for (size_t k = h.size(); k-- > 0;) {
            const HierarchyNode& n = h.nodes[k];
            for (size_t b = 0; b < bins; ++b)
                fa[k * bins + b] =
                    n.IsLeaf() ? n.area * std::max(0.0f, glm::dot(n.normal, dirs.Direction(b)))
                               : fa[(k + 1) * bins + b] + fa[size_t(h.nodes[k + 1].end) * bins + b];
        }
        return fa;
    };
    // The nodes above the blob's elements.
    std::vector<uint8_t> ofBlob(surfels.size(), 0), moving(h.size(), 0);
    for (size_t p = 0; p < scene.primitives.size(); ++p)
        if (scene.primitives[p].nodeIndex == blob)
            for (size_t i = surfels.firstSurfel[p]; i < surfels.End(p); ++i) ofBlob[i] = 1;
    for (size_t k = h.size(); k-- > 0;) {
        const HierarchyNode& n = h.nodes[k];
        moving[k] =
            n.IsLeaf() ? ofBlob[n.surfel] : uint8_t(moving[k + 1] | moving[h.nodes[k + 1].end]);
    }
    ImplicitLinker kept(dirs, 0.5f);
    ImplicitLinks links;
    kept.Build(h, frontArea(), {}, 0.15f, links, &moving);
    EXPECT_FALSE(kept.Incremental());
    {
        ImplicitLinker full(dirs, 0.5f);
        ImplicitLinks fresh;
        full.Build(h, frontArea(), {}, 0.15f, fresh);
        EXPECT_EQ(links.sender, fresh.sender);
        EXPECT_EQ(links.weight, fresh.weight);
        EXPECT_EQ(links.pairs, fresh.pairs);
        EXPECT_EQ(links.linked, fresh.linked);
        // Again with the same pose, kept.
        kept.Build(h, frontArea(), {}, 0.15f, links, &moving);
        EXPECT_TRUE(kept.Incremental());
        EXPECT_EQ(links.sender, fresh.sender);
        EXPECT_EQ(links.pairs, fresh.pairs);
    }
    for (int pose = 0; pose < 3; ++pose) {
        SetNodeMorphWeights(scene, blob, {0.3f * float(pose + 1), 0.8f - 0.3f * float(pose)});
        const Surfels now = RefineScene(scene, 0.15f);
        ASSERT_EQ(now.size(), surfels.size());
        surfels.centroids = now.centroids, surfels.normals = now.normals;
        surfels.areas = now.areas, surfels.positions = now.positions;
        RefitHierarchy(h, surfels);
        const std::vector<float> fa = frontArea();
        kept.Build(h, fa, {}, 0.15f, links, &moving);
        EXPECT_TRUE(kept.Incremental());
        ImplicitLinker full(dirs, 0.5f);
        ImplicitLinks fresh;
        full.Build(h, fa, {}, 0.15f, fresh);
        std::printf(
            "pose %d: %zu shares, %zu pairs, create %.1f ms, push %.1f ms (a full build: %zu "
            "shares, %zu pairs, create %.1f ms, push %.1f ms)\n",
            pose, links.sender.size(), links.pairs, links.msCreate, links.msPush,
            fresh.sender.size(), fresh.pairs, fresh.msCreate, fresh.msPush);
        ExpectSameLinks(links, fresh);
    }
    // Another moving set (the plinth's nodes as well): everything built again.
    std::vector<uint8_t> more(h.size(), 1);
    kept.Build(h, frontArea(), {}, 0.15f, links, &more);
    EXPECT_FALSE(kept.Incremental());
}

// Glossy leaves reflect through their lobes (implicit_glossy.cpp). The sky furnace (a unit
// room, half its ceiling open to a sky of radiance 1) built of white metal (F0 = 1, no
// diffuse part) against paths traced through the same lobes, and of white plastic: no
// radiance inside exceeds the sky's. Before the lobes a metal leaf was black.
TEST(Implicit, GlossySkyFurnaceKeepsItsBoundAndAgreesWithTheReference) {
    for (float metallic : {1.0f, 0.0f}) {
        SceneBuilder b;
        const Scene scene = testing::SkyFurnaceRoom(
            b, b.AddPbrMaterial("white", glm::vec3(1.0f), metallic, 0.5f), 4);
        auto solver = CreateSolver(scene, Implicit(0.1f));
        solver->Iterate(60);
        const std::vector<glm::vec3> mine =
            testing::AllVertices(*solver, scene, Channel::kIndirect);
        double sum = 0, most = 0;
        for (const glm::vec3& e : mine) {
            const double f = (e.x + e.y + e.z) / (3.0 * kPi);
            sum += f, most = std::max(most, f);
        }
        const double mean = sum / mine.size();
        std::printf("implicit glossy sky furnace (metallic %.0f): E/πL mean %.4f, max %.4f\n",
                    metallic, mean, most);
        EXPECT_LT(most, 1.05) << "metallic " << metallic;
        EXPECT_LT(mean, 1.01) << "metallic " << metallic;
        if (metallic == 0.0f) continue;
        const std::vector<glm::vec3> truth = Truth(scene, 4096);
        double truthSum = 0;
        for (const glm::vec3& e : truth) truthSum += (e.x + e.y + e.z) / (3.0 * kPi);
        const double rms = testing::RelativeRms(mine, truth);
        std::printf("  reference mean %.4f, relative RMS %.4f\n", truthSum / truth.size(), rms);
        EXPECT_NEAR(mean, truthSum / truth.size(), 0.2 * truthSum / truth.size());
        EXPECT_LT(rms, 0.25);
    }
}

}  // namespace
}  // namespace penumbra
