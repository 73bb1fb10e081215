// Shared by the stability tests (CPU and lavapipe): settings for the clutter suite and the
// convergence check of issue 18.
#pragma once

#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "clutter_scenes.h"
#include "solver/solver.h"
#include "solvers/antiradiance/antiradiance_solver.h"

namespace penumbra::testing {

// CI-sized settings: 64 bins and 0.2 m elements keep 200 iterations of the whole suite
// within about three minutes of ctest's slots (185 s in session 43's clean-clone `make
// check`; 243 s at 300 iterations, 350 s at 500). The boxes' 8 cm faces and 5 mm gaps stay
// finer than the elements, so the stacks are as deep as at the default settings (the
// symmetric scheme diverges here too, in 42 iterations on a row of ten boxes 2 cm apart);
// the coarser elements are the room's walls, which hold most of the elements and links
// (0.12 m: 7,565 elements and 1.2M links on that row, 14 ms a pass; 0.2 m: 2,165, 0.34M,
// 3.6 ms).
inline SolverSettings ClutterSettings(DeviceChoice device) {
    SolverSettings s;
    s.solver = "antiradiance";
    s.device = device;
    SetOption(s.options, "scheme", "adaptive");
    SetOption(s.options, "bins", 64);
    s.elementSize = 0.2f;
    s.validation = device != DeviceChoice::kCpu;
    return s;
}

// Σ|a − b| / Σ|b| over all surfels and channels.
inline double Change(const std::vector<glm::vec3>& a, const std::vector<glm::vec3>& b) {
    double num = 0, den = 0;
    for (size_t i = 0; i < a.size(); ++i)
        for (int c = 0; c < 3; ++c) num += std::abs(a[i][c] - b[i][c]), den += std::abs(b[i][c]);
    return den > 0 ? num / den : 0.0;
}

// `iterations` (200 in the CPU suite): |E| of every surfel within the furnace bound after
// every iteration, and the last fifth of them (iterations 160 → 200) change the answer by
// less than 0.1%. Every scene of the suite has settled long before: no iteration after the
// 22nd changed its answer by 10⁻⁴ (session 43, each scene run 500 iterations); a mode that
// grew by 11% an iteration from rounding (10⁻⁷ of the answer) would pass the bound, at most
// ~50 times a scene's largest irradiance, within 200 (`make bench-stability` runs the suite
// longer, at the default settings).
inline void ExpectConverges(const std::string& name, const Scene& scene, DeviceChoice device,
                            int iterations = 200) {
    SCOPED_TRACE(name);
    const float bound = scenes::FurnaceBound(scene);
    auto solver = CreateSolver(scene, ClutterSettings(device));
    std::vector<glm::vec3> atFourFifths;
    const int fourFifths = iterations * 4 / 5;
    float largest = 0.0f;
    for (int iteration = 1; iteration <= iterations; ++iteration) {
        solver->Iterate(1);
        ASSERT_EQ(solver->Stats().divergence, "") << "iteration " << iteration;
        const std::vector<glm::vec3> e = solver->SurfelIrradiance();
        for (const glm::vec3& v : e)
            largest = std::max({largest, std::abs(v.x), std::abs(v.y), std::abs(v.z)});
        ASSERT_LE(largest, bound) << "iteration " << iteration
                                  << ": a surfel past the furnace bound";
        if (iteration == fourFifths) atFourFifths = e;
    }
    const double change = Change(solver->SurfelIrradiance(), atFourFifths);
    EXPECT_LT(change, 1e-3) << "iterations " << fourFifths << " → " << iterations
                            << " still change the answer";
    const SolverStats s = solver->Stats();
    EXPECT_EQ(s.Number("antiradiance_cap_hits"), 0.0);
    if (auto* ar = dynamic_cast<AntiradianceSolver*>(solver.get())) {
        const std::vector<std::string> messages = ar->ValidationMessages();
        EXPECT_TRUE(messages.empty()) << messages.front();
    }
    std::printf(
        "  %-26s %s: max |E| %.3g of bound %.3g, change %d→%d %.2g, %d bounces, "
        "%d passes, %d antiradiance steps in the last bounce\n",
        name.c_str(), s.device.c_str(), largest, bound, fourFifths, iterations, change, s.bounces,
        s.gathers, int(s.Number("last_antiradiance_steps")));
}

}  // namespace penumbra::testing
