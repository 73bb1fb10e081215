// The implicit-visibility solver's registry entry and options (solvers/implicit/settings.h).
#include "solvers/implicit/settings.h"

#include "hierarchy/directions.h"
#include "solvers/implicit/implicit_solver.h"

namespace penumbra {
namespace {

std::vector<OptionSpec> Options() {
    using K = OptionKind;
    return {
        BinsOption("64 behind the final gather, 128 without (the paper's 6×12×12 cube map is 864)"),
        {"link-threshold",
         K::kFloat,
         "0.2",
         "refine a link end while it subtends more than this many bins' solid angle (its "
         "bounding sphere's disc, foreshortened as far as its members' slab allows)",
         0.05,
         4,
         {}},
        {"bin-cover",
         K::kChoice,
         "layer",
         "layer: each bin takes the nearest links until it is full, each covering its own "
         "solid angle; closest: the paper's rule, the closest link covers the whole bin (faster; "
         "a light smaller than a bin lights it whole, an element wider than a bin leaves its "
         "neighbours empty; links created on the CPU)",
         0,
         0,
         {"layer", "closest"}},
    };
}

}  // namespace

SolverEntry ImplicitEntry() {
    return {"implicit",
            "implicit visibility (Dong et al. 2007): links rebuilt every frame, the closest "
            "surfaces in each direction bin, any move or deformation taken in place; on the CPU "
            "(on a Vulkan device the link creation, the compositing and the bounces; "
            "docs/SOLVER.md)",
            Options(),
            [](const Scene& scene, const SolverSettings& settings,
               const ProgressFn& progress) -> std::unique_ptr<Solver> {
                return std::make_unique<ImplicitSolver>(scene, settings,
                                                        ReadImplicitSettings(settings), progress);
            },
            [](const SolverSettings& settings) { ReadImplicitSettings(settings); }};
}

ImplicitSettings ReadImplicitSettings(const SolverSettings& settings) {
    const OptionReader r("implicit", Options(), settings.options);
    ImplicitSettings s;
    const int bins = r.Int("bins");
    if (bins != 0) Directions::Check(bins);
    s.bins = bins > 0                ? bins
             : settings.behindGather ? kImplicitBinsBehindGather
                                     : kImplicitDefaultBins;
    s.linkThreshold = r.Float("link-threshold");
    s.closest = r.Choice("bin-cover") == "closest";
    return s;
}

}  // namespace penumbra
