// The solver choice on the command line: --solver and every registered solver's own options
// (solvers/registry.h), shared by bake, render and load.
#pragma once

#include <CLI/CLI.hpp>
#include <string>

#include "solver/options.h"

namespace penumbra::cli {

// Adds --solver (into `solver`) and one --NAME for each option any registered solver
// declares (given values land in `options`, checked later by the chosen solver) to `command`,
// in a group of their own, each saying which solvers take it and its default.
void AddSolverOptions(CLI::App* command, std::string& solver, SolverOptions& options);

// The solvers with their summaries, one a line, for --help.
std::string SolversHelp();

}  // namespace penumbra::cli
