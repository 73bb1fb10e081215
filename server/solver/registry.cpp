// The registry of solvers (solver/registry.h) and the factory that builds from it.
#include "solver/registry.h"

#include <utility>

#include "base/check.h"
#include "solver/antiradiance/settings.h"
#include "solver/implicit/settings.h"
#include "solver/lightfield/settings.h"

namespace penumbra {
namespace {

std::vector<SolverEntry>& Registry() {
    // Built in: one line a solver.
    static std::vector<SolverEntry> solvers = {AntiradianceEntry(), ImplicitEntry(),
                                               LightfieldEntry()};
    return solvers;
}

}  // namespace

const std::vector<SolverEntry>& Solvers() { return Registry(); }

bool RegisterSolver(SolverEntry entry) {
    for (const SolverEntry& e : Registry())
        if (e.name == entry.name)
            CheckFailed(__FILE__, __LINE__, "solver '" + entry.name + "' registered twice");
    Registry().push_back(std::move(entry));
    return true;
}

std::string SolverNames() {
    std::vector<std::string> names;
    for (const SolverEntry& e : Solvers()) names.push_back(e.name);
    return JoinChoices(names, ", ");
}

const SolverEntry& FindSolver(const std::string& name) {
    for (const SolverEntry& e : Solvers())
        if (e.name == name) return e;
    throw Error("unknown solver '" + name + "' (available: " + SolverNames() + ")");
}

void CheckSolverSettings(const SolverSettings& settings) {
    const SolverEntry& e = FindSolver(settings.solver);
    OptionReader(e.name, e.options, settings.options);
    if (e.check) e.check(settings);
}

bool FallbackSettings(const SolverSettings& settings, SolverSettings& fallback) {
    const SolverEntry& to = FindSolver("lightfield");
    if (settings.solver == to.name) return false;
    fallback = settings;
    fallback.solver = to.name;
    fallback.options.clear();
    for (const auto& [name, value] : settings.options)
        for (const OptionSpec& spec : to.options)
            if (spec.name == name) fallback.options[name] = value;
    return true;
}

std::unique_ptr<Solver> CreateSolver(const Scene& scene, const SolverSettings& settings,
                                     const ProgressFn& progress) {
    return FindSolver(settings.solver).create(scene, settings, progress);
}

}  // namespace penumbra
