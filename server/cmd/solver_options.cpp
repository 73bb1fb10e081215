// --solver and the solvers' own options on the command line (cmd/solver_options.h).
#include "cmd/solver_options.h"

#include <map>
#include <vector>

#include "solvers/registry.h"

namespace penumbra::cli {

std::string SolversHelp() {
    std::string out = "Solvers (--solver):";
    for (const SolverEntry& e : Solvers()) out += "\n  " + e.name + ": " + e.summary;
    return out;
}

void AddSolverOptions(CLI::App* command, std::string& solver, SolverOptions& options) {
    command
        ->add_option("--solver", solver,
                     "the solver: " + SolverNames() + " (penumbra --help says what each is)")
        ->capture_default_str()
        ->check(CLI::Validator(
            [](std::string& name) -> std::string {
                try {
                    FindSolver(name);
                } catch (const std::exception& e) {
                    return e.what();
                }
                return {};
            },
            "SOLVER", "solver"));
    // One command-line option per name, whichever solvers declare it.
    std::vector<std::string> order;
    std::map<std::string, std::vector<std::pair<const SolverEntry*, const OptionSpec*>>> takers;
    for (const SolverEntry& e : Solvers())
        for (const OptionSpec& spec : e.options) {
            if (!takers.count(spec.name)) order.push_back(spec.name);
            takers[spec.name].push_back({&e, &spec});
        }
    for (const std::string& name : order) {
        const OptionSpec& spec = *takers[name].front().second;  // the first solver's
        // Solvers that share a name but not its meaning (what `--bins 0` picks) say theirs each.
        std::string who, each;
        bool same = true;
        for (const auto& [e, own] : takers[name]) {
            who += (who.empty() ? "" : ", ") + e->name;
            each += (each.empty() ? "" : "; ") + e->name + ": " + own->help + " (default " +
                    own->defaultText + ")";
            same = same && own->help == spec.help && own->defaultText == spec.defaultText;
        }
        std::string help =
            same ? spec.help + " [" + who + "; default " + spec.defaultText + "]" : each;
        const char* type = spec.kind == OptionKind::kInt     ? "INT"
                           : spec.kind == OptionKind::kFloat ? "FLOAT"
                                                             : "TEXT";
        // A value that is not of the option's kind or outside its range is a usage error
        // (the chosen solver checks the rest).
        const CLI::Validator kind(
            [spec, who](std::string& value) -> std::string {
                try {
                    OptionReader(who, {spec}, {{spec.name, value}});
                } catch (const std::exception& e) {
                    return e.what();
                }
                return {};
            },
            type);
        command
            ->add_option_function<std::string>(
                "--" + name, [&options, name](const std::string& v) { options[name] = v; }, help)
            ->type_name(type)
            ->check(kind)
            ->group("Solver options");
    }
}

}  // namespace penumbra::cli
