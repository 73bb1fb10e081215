// The solvers there are: each one's name, summary, options and constructor. The CLI, the
// net layer and --help consult this list; adding a solver is its folder and one line here.
#pragma once

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "solver/options.h"
#include "solver/solver.h"

namespace penumbra {

struct SolverEntry {
    std::string name;     // --solver NAME, LoadScene solver
    std::string summary;  // one line for --help
    std::vector<OptionSpec> options;
    // Builds the solver; reads settings.options against `options` (penumbra::Error for bad
    // ones, an unusable device or a scene it cannot take).
    std::function<std::unique_ptr<Solver>(const Scene&, const SolverSettings&, const ProgressFn&)>
        create;
    // Checks settings.options beyond each one's kind and range, without a scene
    // (penumbra::Error); may be empty.
    std::function<void(const SolverSettings&)> check;
};

// Every solver, built in ones first, then those registered from outside in the order they
// registered.
const std::vector<SolverEntry>& Solvers();
// The named solver; penumbra::Error naming the solvers there are when there is none.
const SolverEntry& FindSolver(const std::string& name);
// "antiradiance, constant": the solvers' names.
std::string SolverNames();
// Adds a solver linked in from outside the library (a test fixture, a plug-in built into a
// program): call it before main, from a static object's constructor. Returns true; a name
// that is taken is a CHECK failure.
bool RegisterSolver(SolverEntry entry);
// Checks settings.solver and settings.options against the registry without building
// anything (penumbra::Error as CreateSolver would throw it).
void CheckSolverSettings(const SolverSettings& settings);

// The solver a bake or a session goes on with when `settings.solver`'s solution diverged
// (Solver::Stats().divergence; docs/SOLVER.md "When a solution diverges"): the light-field
// solver, whose iteration carries only light that is there (no negative antiradiance to
// overshoot), with the settings' element size, device and back-side rule and those of
// their options it declares too. False, `fallback` untouched, for the light-field solver
// itself: it has no other to go on with.
bool FallbackSettings(const SolverSettings& settings, SolverSettings& fallback);

}  // namespace penumbra
