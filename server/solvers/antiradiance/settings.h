// The antiradiance solver's own options: declared for the registry (AntiradianceEntry) and
// read from SolverSettings::options into AntiradianceSettings.
#pragma once

#include <string>

#include "links/oracle.h"
#include "solvers/registry.h"

namespace penumbra {

// How the local pass's two operators are scheduled (Sec. 2.2, docs/SOLVER.md "Stability").
// kSymmetric: K and J in every pass (the paper's default; diverges on stacks of occluders).
// kAsymmetric: one radiance step (K), then `antiradianceSteps` antiradiance steps (J).
// kAdaptive: one radiance step, then antiradiance steps until the antiradiance has
// converged for that radiance (at most `maxAntiradianceSteps`).
enum class Scheme { kSymmetric, kAsymmetric, kAdaptive };
// How the CPU back end stores its I_ex tables (cpu_passes.h): fp32, or fp16 over each
// node's area (half the memory traffic, about 5·10⁻⁴ relative). kAuto: fp16 where the CPU
// has F16C. The Vulkan passes use fp32.
enum class TablePrecision { kAuto, kFp32, kFp16 };
// Where a move inside the bounds recomputes its links on a Vulkan back end: on the device
// (shaders/links.comp), or on the host with the links uploaded after. kAuto: the device,
// except lavapipe, whose "device" is the host's own cores and runs the pass slower than the
// host code does (bench/results/FINDINGS.md, "Constants in the code").
enum class LinkUpdate { kAuto, kDevice, kHost };

inline constexpr int kDefaultBins = 128;
// Behind a final gather (SolverSettings::behindGather; docs/SOLVER.md "Settings behind the
// gather"): the gather reads the solver's answer only one bounce away, through 256 rays, so
// fewer bins and a looser settling of each bounce cost little accuracy there.
inline constexpr int kBinsBehindGather = 64;
inline constexpr float kSettleBehindGather = 3e-2f;

struct AntiradianceSettings {
    int bins = kDefaultBins;  // direction bins, 32…1024, a multiple of 4
    // Adaptive by default: the paper's symmetric scheme diverges on rows and stacks of
    // occluders (docs/SOLVER.md "Stability"); where it converges, both reach one fixed point.
    Scheme scheme = Scheme::kAdaptive;
    int antiradianceSteps = 3;  // asymmetric: antiradiance steps after each radiance step
    // Adaptive: antiradiance steps end when no leaf's irradiance moved by more than
    // `antiradianceTolerance` × the largest leaf irradiance in the last step, or after
    // `maxAntiradianceSteps` (the stats' antiradiance_cap_hits count those).
    float antiradianceTolerance = 1e-4f;
    int maxAntiradianceSteps = 64;
    float oracle = 1.0f;  // link refinement threshold in units of ω_bin
    // Receiver threshold relative to `oracle` (conservative and area oracles). 0.5: a
    // receiver cluster's error is of the first order in its size (docs/SOLVER.md, "Receiver
    // size"); against 1, at 128 bins and 0.1 m, the blocker goes from 16.2 to 12.5% RMSE, the
    // Cornell box from 9.9 to 8.7%, the maze from 13.6 to 12.8%, for 1.4–1.7× the links.
    float receiverOracle = 0.5f;
    LinkOracle linkOracle = LinkOracle::kConservative;  // links/oracle.h
    TablePrecision tables = TablePrecision::kAuto;
    // With SolverSettings::prepareMoves: when the links touching dynamic nodes would outnumber
    // the others by more than this factor, the usual links are built instead and moves
    // rebuild them (the stats' motion_declined says so). 0: no limit.
    float motionLinkBudget = 0.0f;
    LinkUpdate linkUpdate = LinkUpdate::kAuto;
};

// The registry's entry: name, options (each AntiradianceSettings field by its option name:
// "bins", "scheme", "link-oracle", …) and constructor.
SolverEntry AntiradianceEntry();
// The options in `settings`, checked and read, with the defaults behind a final gather
// (kBinsBehindGather, kSettleBehindGather) where those options are not given.
AntiradianceSettings ReadAntiradianceSettings(const SolverSettings& settings);
// `own` as options text (the inverse of ReadAntiradianceSettings for every field).
SolverOptions AntiradianceOptions(const AntiradianceSettings& own);

Scheme ParseScheme(const std::string& name);  // "adaptive" | "symmetric" | "asymmetric"
const char* SchemeName(Scheme scheme);
TablePrecision ParseTablePrecision(const std::string& name);  // "auto" | "fp32" | "fp16"
LinkOracle ParseLinkOracle(const std::string& name);          // "conservative" | "paper" | "area"
const char* LinkOracleName(LinkOracle oracle);

}  // namespace penumbra
