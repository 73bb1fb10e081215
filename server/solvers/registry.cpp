// The registry of solvers (solvers/registry.h) and the factory that builds from it.
#include "solvers/registry.h"

#include <utility>

#include "base/check.h"
#include "solvers/antiradiance/settings.h"
#include "solvers/implicit/settings.h"
#include "solvers/lightfield/settings.h"

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
    // An option the solver does not declare but others do: most likely a solver left
    // unnamed (the default is the light-field solver), so the message says whose it is.
    for (const auto& [name, value] : settings.options) {
        bool own = false;
        std::vector<std::string> takers;
        for (const OptionSpec& spec : e.options) own = own || spec.name == name;
        if (own) continue;
        for (const SolverEntry& other : Solvers())
            for (const OptionSpec& spec : other.options)
                if (spec.name == name) takers.push_back(other.name);
        if (!takers.empty())
            throw Error("solver '" + e.name + "' has no option '" + name + "' (" +
                        TakesText(e.options) + "; '" + name + "' is an option of " +
                        JoinChoices(takers, " and ") + ": name that solver, e.g. --solver " +
                        takers.front() + "; " + kDefaultSolver + " is the default)");
    }
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
