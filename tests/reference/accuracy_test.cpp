// The antiradiance solver against the Embree reference on the bundled scenes, at coarse
// settings fast enough for CI. Each bound is the measured relative RMSE plus a margin, with
// the reason the solver is off by that much; docs/ACCURACY.md has the full sweep.
#include <gtest/gtest.h>

#include <cstdio>

#include "output/compare.h"
#include "output/irradiance_writer.h"
#include "reference/path_tracer.h"
#include "scene/gltf_loader.h"
#include "solver/solver.h"

namespace penumbra {
namespace {

double SceneRmse(const Scene& scene, const std::string& label, float elementSize, int samples,
                 Channel channel = Channel::kIndirect) {
    SolverSettings s;
    s.solver = "antiradiance";
    SetOption(s.options, "bins", 128);
    s.elementSize = elementSize;
    s.device = DeviceChoice::kCpu;
    auto solver = CreateSolver(scene, s);
    solver->Iterate(8);
    IrradianceResult solved = CollectIrradiance(scene, *solver, channel);

    ReferenceSettings rs;
    rs.samples = samples;
    rs.channel = channel;
    Comparison c = Compare(ToIrradianceFile(scene, solved), ReferenceFile(scene, rs));
    std::printf("%s (%s): relative RMSE %.4f, mean relative %.4f over %zu vertices\n",
                label.c_str(), ChannelName(channel), c.overall.relRmse, c.overall.meanRel,
                c.overall.vertices);
    return c.overall.relRmse;
}

double SolverRmse(const std::string& file, float elementSize, int samples) {
    Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/" + file);
    return SceneRmse(scene, file, elementSize, samples);
}

// The Cornell box lit by a point light under the ceiling instead of its emissive panel.
Scene CornellWithPointLight() {
    Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf");
    for (Material& m : scene.materials) m.emission = glm::vec3(0.0f);
    SceneNode node;
    node.name = "bulb";
    scene.nodes.push_back(node);
    PunctualLight bulb;
    bulb.name = "bulb";
    bulb.node = static_cast<int>(scene.nodes.size() - 1);
    bulb.position = glm::vec3(0.278f, 0.45f, 0.28f);
    bulb.intensity = 1.0f;
    scene.lights.push_back(bulb);
    return scene;
}

// Measured 8.8% (128 bins, 0.1 m elements, 8 iterations of the adaptive scheme; 9.7% with
// the symmetric one before issue 18; reference 1024 samples, itself ≈ 1.7% noisy). The ceiling
// light spans about one bin from most of the room, so direct light is quantised to bin centres
// (±10–20% vertex to vertex, no overall bias: each wall's total is within 6%); the worst vertices
// are where walls meet the ceiling.
TEST(Accuracy, CornellBoxCoarse) { EXPECT_LT(SolverRmse("cornell-box.gltf", 0.1f, 1024), 0.13); }

// Measured 12.4% (16.1% before issue 18): the penumbra of the blocker is resolved at the bin and
// element scale (0.1 m), so the shadow's edge moves and the umbra is shallower than the
// reference's.
TEST(Accuracy, BlockerCoarse) { EXPECT_LT(SolverRmse("blocker.gltf", 0.1f, 1024), 0.20); }

// Measured 13.2% (13.7% before issue 18): elements (0.1 m) as thick as the partitions let light
// leak into the far corridors, where the reference is nearly black; the lit corridor is within a
// few per cent.
TEST(Accuracy, MazeCoarse) { EXPECT_LT(SolverRmse("maze.gltf", 0.1f, 1024), 0.18); }

// Direct light of a point light: the closed form behind shadow rays (reference) against
// shadow maps filtered over each element (solver). Measured 2.4% RMSE (mean relative error
// 27%): fully lit vertices agree to float precision; the difference is at the blocks'
// shadow edges, which the solver spreads over one element (0.1 m) by design, so vertices in
// the reference's umbra next to an edge get some light (large relative, small absolute).
TEST(Accuracy, CornellPointLightDirect) {
    EXPECT_LT(
        SceneRmse(CornellWithPointLight(), "cornell + point light", 0.1f, 2, Channel::kDirect),
        0.04);
}

// Its bounces (`indirect`): measured 8.6% (9.3% before issue 18) (reference 1024 samples); like the
// emissive box, the first bounce is quantised to bin directions.
TEST(Accuracy, CornellPointLightIndirect) {
    EXPECT_LT(SceneRmse(CornellWithPointLight(), "cornell + point light", 0.1f, 1024), 0.12);
}

// The Cornell box with its panel and a constant white sky coming in through its open front
// (the walls are one-sided quads: they occlude the sky from both sides; the blocks stand on
// the floor and keep the front-side rule). Measured 8.1% (10.4% before issue 18; reference
// 1024 samples): about the panel alone (8.8%); the sky's edge at the opening is blurred over a bin.
TEST(Accuracy, CornellBoxUnderASky) {
    Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/cornell-box.gltf");
    scene.environment = ConstantEnvironment(glm::vec3(1.0f));
    EXPECT_LT(SceneRmse(scene, "cornell + sky", 0.1f, 1024), 0.13);
}

// The maze under a sky that enters only through its opening. Measured 13.4% (15.6% before issue
// 18): as without the sky, 0.1 m elements are as thick as the partitions, so light leaks into the
// far corridors.
TEST(Accuracy, MazeUnderASky) {
    Scene scene = LoadGltf(std::string(PENUMBRA_SOURCE_DIR) + "/scenes/maze.gltf");
    scene.environment = ConstantEnvironment(glm::vec3(0.5f, 0.6f, 1.0f));
    EXPECT_LT(SceneRmse(scene, "maze + sky", 0.1f, 1024), 0.20);
}

// The glossy box (issue 5): a spot on a glossy metal cube, the room lit by what the cube and
// a gold column reflect. `indirect` (every bounce, the spot's direct light excluded).
// Measured 24.1% (26.0% before issue 18; 18.2% at 512 bins then). Each surface's mean is within 8%
// of the reference's; the error is where the light lands: the cube's lobe is carried by 128 bins
// (about 18° apart), so its reflection reaches the walls as bin-shaped patches instead of a smooth
// highlight (docs/ACCURACY.md).
TEST(Accuracy, GlossyBoxCoarse) { EXPECT_LT(SolverRmse("glossy-box.gltf", 0.1f, 1024), 0.30); }

}  // namespace
}  // namespace penumbra
