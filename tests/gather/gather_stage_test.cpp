// The emitters' direct light as a solver's first shot (gather/gather_stage.h): the answer gets
// closer to the reference where the bins blurred the direct light, edits of an emitter give
// what a fresh solve gives, and the Vulkan back end agrees with the CPU one.
#include "gather/gather_stage.h"

#include <gtest/gtest.h>

#include "output/compare.h"
#include "output/irradiance_writer.h"
#include "reference/path_tracer.h"
#include "scene/gltf_loader.h"
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
    IrradianceResult r;
    r.solver = "reference";
    r.primitives = RenderReference(scene, rs).irradiance;
    return ToIrradianceFile(scene, r);
}

// The first shot alone (no final gather).
GatherSettings ShotOnly() {
    GatherSettings g;
    g.gatherRays = 0;
    return g;
}

SolverSettings Cpu() {
    SolverSettings s;
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
    EXPECT_GT(shot.Stats().emitterRays, 0);
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
    s.bins = 64;
    s.elementSize = 0.2f;
    s.tables = TablePrecision::kFp32;
    GatherStage cpu(CreateSolver(scene, s), scene, ShotOnly());
    s.device = DeviceChoice::kLavapipe;
    s.tables = TablePrecision::kAuto;
    s.validation = true;
    GatherStage gpu(CreateSolver(scene, s), scene, ShotOnly());
    cpu.Iterate(6);
    gpu.Iterate(6);
    EXPECT_LT(testing::RelativeRms(gpu.SurfelIrradiance(Channel::kTotal),
                                   cpu.SurfelIrradiance(Channel::kTotal)),
              1e-3);
}

}  // namespace
}  // namespace penumbra
