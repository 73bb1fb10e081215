// The antiradiance solver's registry entry and options (solvers/antiradiance/settings.h).
#include "solvers/antiradiance/settings.h"

#include <algorithm>
#include <cstdio>

#include "base/check.h"
#include "hierarchy/directions.h"
#include "solvers/antiradiance/antiradiance_solver.h"

namespace penumbra {
namespace {

std::vector<OptionSpec> Options() {
    using K = OptionKind;
    return {
        BinsOption("64 behind the final gather, 128 without"),
        {"scheme",
         K::kChoice,
         "adaptive",
         "adaptive, symmetric or asymmetric iteration (Sec. 2.2; docs/SOLVER.md)",
         0,
         0,
         {"adaptive", "symmetric", "asymmetric"}},
        {"antiradiance-steps",
         K::kInt,
         "3",
         "asymmetric scheme: antiradiance steps after each radiance step",
         1,
         64,
         {}},
        {"antiradiance-tolerance",
         K::kFloat,
         "0",
         "adaptive scheme: a bounce is settled when an antiradiance step moves no element's "
         "irradiance by more than this times the largest; 0: 1e-4, 3e-2 behind the final "
         "gather",
         0,
         0.5,
         {}},
        {"max-antiradiance-steps",
         K::kInt,
         "64",
         "adaptive scheme: antiradiance steps a bounce at most",
         1,
         4096,
         {}},
        {"oracle",
         K::kFloat,
         "1",
         "link refinement threshold, in units of a bin's solid angle",
         1e-3,
         1e3,
         {}},
        {"receiver-oracle",
         K::kFloat,
         "0.5",
         "receiver solid-angle threshold relative to the oracle",
         1e-3,
         1e3,
         {}},
        {"link-oracle",
         K::kChoice,
         "conservative",
         "conservative (accurate), paper (Sec. 3.2: fewer links) or area (the paper's with a "
         "receiver test)",
         0,
         0,
         {"conservative", "paper", "area"}},
        {"tables",
         K::kChoice,
         "auto",
         "how the CPU back end stores its radiance tables (fp16: half the memory traffic, "
         "~5e-4 relative; auto: fp16 where the CPU has F16C); the Vulkan passes use fp32",
         0,
         0,
         {"auto", "fp32", "fp16"}},
        {"motion-link-budget",
         K::kFloat,
         "0",
         "with --motion-links: build the usual links instead when the links touching dynamic "
         "nodes would outnumber the others by more than this factor (the service uses 1; 0: "
         "no limit)",
         0,
         1e6,
         {}},
        {"link-update",
         K::kChoice,
         "auto",
         "where a move recomputes its links on a Vulkan back end (auto: the device, except "
         "lavapipe)",
         0,
         0,
         {"auto", "device", "host"}},
    };
}

std::string Text(float v) {
    char s[32];
    std::snprintf(s, sizeof s, "%.9g", v);
    return s;
}

}  // namespace

SolverEntry AntiradianceEntry() {
    return {"antiradiance",
            "Dachsbacher et al. 2007: hierarchical links without visibility, occlusion as "
            "antiradiance",
            Options(),
            [](const Scene& scene, const SolverSettings& settings,
               const ProgressFn& progress) -> std::unique_ptr<Solver> {
                return std::make_unique<AntiradianceSolver>(
                    scene, settings, ReadAntiradianceSettings(settings), progress);
            },
            [](const SolverSettings& settings) { ReadAntiradianceSettings(settings); }};
}

AntiradianceSettings ReadAntiradianceSettings(const SolverSettings& settings) {
    const OptionReader r("antiradiance", Options(), settings.options);
    AntiradianceSettings s;
    const int bins = r.Int("bins");
    if (bins != 0) Directions::Check(bins);
    s.bins = bins > 0 ? bins : settings.behindGather ? kBinsBehindGather : kDefaultBins;
    s.scheme = ParseScheme(r.Choice("scheme"));
    s.antiradianceSteps = r.Int("antiradiance-steps");
    const float tolerance = r.Float("antiradiance-tolerance");
    s.antiradianceTolerance = tolerance > 0.0f        ? tolerance
                              : settings.behindGather ? kSettleBehindGather
                                                      : s.antiradianceTolerance;
    s.maxAntiradianceSteps = r.Int("max-antiradiance-steps");
    s.oracle = r.Float("oracle");
    s.receiverOracle = r.Float("receiver-oracle");
    s.linkOracle = ParseLinkOracle(r.Choice("link-oracle"));
    s.tables = ParseTablePrecision(r.Choice("tables"));
    s.motionLinkBudget = r.Float("motion-link-budget");
    const std::string update = r.Choice("link-update");
    s.linkUpdate = update == "device" ? LinkUpdate::kDevice
                   : update == "host" ? LinkUpdate::kHost
                                      : LinkUpdate::kAuto;
    return s;
}

SolverOptions AntiradianceOptions(const AntiradianceSettings& own) {
    const char* tables[] = {"auto", "fp32", "fp16"};
    const char* updates[] = {"auto", "device", "host"};
    return {{"bins", std::to_string(own.bins)},
            {"scheme", SchemeName(own.scheme)},
            {"antiradiance-steps", std::to_string(own.antiradianceSteps)},
            {"antiradiance-tolerance", Text(own.antiradianceTolerance)},
            {"max-antiradiance-steps", std::to_string(own.maxAntiradianceSteps)},
            {"oracle", Text(own.oracle)},
            {"receiver-oracle", Text(own.receiverOracle)},
            {"link-oracle", LinkOracleName(own.linkOracle)},
            {"tables", tables[static_cast<int>(own.tables)]},
            {"motion-link-budget", Text(own.motionLinkBudget)},
            {"link-update", updates[static_cast<int>(own.linkUpdate)]}};
}

LinkOracle ParseLinkOracle(const std::string& name) {
    if (name == "conservative") return LinkOracle::kConservative;
    if (name == "paper") return LinkOracle::kPaper;
    if (name == "area") return LinkOracle::kArea;
    throw Error("unknown link oracle '" + name + "' (use conservative, paper or area)");
}

const char* LinkOracleName(LinkOracle oracle) {
    switch (oracle) {
        case LinkOracle::kPaper:
            return "paper";
        case LinkOracle::kArea:
            return "area";
        default:
            return "conservative";
    }
}

Scheme ParseScheme(const std::string& name) {
    if (name == "symmetric") return Scheme::kSymmetric;
    if (name == "asymmetric") return Scheme::kAsymmetric;
    if (name == "adaptive") return Scheme::kAdaptive;
    throw Error("unknown scheme '" + name + "' (use adaptive, symmetric or asymmetric)");
}

const char* SchemeName(Scheme scheme) {
    switch (scheme) {
        case Scheme::kSymmetric:
            return "symmetric";
        case Scheme::kAsymmetric:
            return "asymmetric";
        case Scheme::kAdaptive:
            return "adaptive";
    }
    return "?";
}

TablePrecision ParseTablePrecision(const std::string& name) {
    if (name == "auto") return TablePrecision::kAuto;
    if (name == "fp32") return TablePrecision::kFp32;
    if (name == "fp16") return TablePrecision::kFp16;
    throw Error("unknown table precision '" + name + "' (use auto, fp32 or fp16)");
}

}  // namespace penumbra
