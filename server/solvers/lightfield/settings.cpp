// The light-field solver's registry entry and options (solvers/lightfield/settings.h).
#include "solvers/lightfield/settings.h"

#include "solvers/lightfield/lightfield_solver.h"

namespace penumbra {
namespace {

std::vector<OptionSpec> Options() {
    using K = OptionKind;
    return {
        {"directions",
         K::kInt,
         "64",
         "line directions a batch, each used both ways (a new random rotation a batch)",
         4,
         4096,
         {}},
        {"cells",
         K::kInt,
         "0",
         "lines a side of each direction's grid over the scene; 0: cells half an element wide",
         0,
         4096,
         {}},
        {"batches",
         K::kInt,
         "8",
         "batches of directions traced and kept; iterations past them bounce without new rays",
         1,
         4096,
         {}},
        {"seed", K::kInt, "1", "random rotations and jitter of the lines", 0, 2147483647, {}},
        {"layers",
         K::kInt,
         "8",
         "on a Vulkan device: surfaces peeled a submission along the lines (more follow while "
         "a line has any left)",
         1,
         256,
         {}},
        {"smoothing",
         K::kInt,
         "-1",
         "passes of smoothing the estimate over each surface where the cells are wider than "
         "the surfels (the interface read at its own resolution); -1: from the cells and the "
         "element size, 0: none",
         -1,
         1000,
         {}},
    };
}

}  // namespace

SolverEntry LightfieldEntry() {
    return {"lightfield",
            "virtual light field (Mortensen et al. 2008): parallel lines in "
            "batches of rotated directions, exact visibility along each; diffuse and glossy "
            "surfaces; lines traced by Embree and walked on the CPU, or rasterised, "
            "depth-peeled and walked on a Vulkan device (docs/SOLVER.md)",
            Options(),
            [](const Scene& scene, const SolverSettings& settings,
               const ProgressFn& progress) -> std::unique_ptr<Solver> {
                return std::make_unique<LightfieldSolver>(
                    scene, settings, ReadLightfieldSettings(settings), progress);
            },
            [](const SolverSettings& settings) { ReadLightfieldSettings(settings); }};
}

LightfieldSettings ReadLightfieldSettings(const SolverSettings& settings) {
    const OptionReader r("lightfield", Options(), settings.options);
    LightfieldSettings s;
    s.directions = r.Int("directions");
    s.cells = r.Int("cells");
    if (s.cells != 0 && s.cells < 4)
        throw Error("lightfield: --cells must be 0 (from the element size) or at least 4");
    s.batches = r.Int("batches");
    s.seed = static_cast<uint32_t>(r.Int("seed"));
    s.layers = r.Int("layers");
    s.smoothing = r.Int("smoothing");
    return s;
}

}  // namespace penumbra
