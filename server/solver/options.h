// The options a solver declares for itself and reads back typed: its registry entry
// (solvers/registry.h) lists them, and the CLI, LoadScene and --help take them from there.
#pragma once

#include <limits>
#include <map>
#include <string>
#include <vector>

namespace penumbra {

enum class OptionKind { kInt, kFloat, kChoice };

// One option: its name is the command line's --name and LoadScene's options key. Values
// travel as text ("64", "paper") and are parsed by the solver that declares them (as
// pbrt-v4's ParameterDictionary and Mitsuba's Properties do).
struct OptionSpec {
    std::string name;
    OptionKind kind = OptionKind::kInt;
    std::string defaultText;  // as --help shows it
    std::string help;
    double min = -std::numeric_limits<double>::infinity();  // kInt, kFloat: inclusive range
    double max = std::numeric_limits<double>::infinity();
    std::vector<std::string> choices;  // kChoice
};

// The direction-bin count of a solver with bins: "bins", 0…1024, 0 meaning `zeroMeans` (the
// solver's own default); the solver checks the rest (Directions::Check: 32…1024, a multiple
// of 4).
OptionSpec BinsOption(const std::string& zeroMeans);

// Options as given, by name, as text.
using SolverOptions = std::map<std::string, std::string>;

// Reads `given` against the declarations of solver `solver`. The constructor checks every
// given option (penumbra::Error: an undeclared name, naming the declared ones; a value that
// does not parse as its kind or lies outside its range or choices); the getters return the
// given value or the declared default.
class OptionReader {
  public:
    OptionReader(std::string solver, const std::vector<OptionSpec>& specs,
                 const SolverOptions& given);
    bool Given(const std::string& name) const;
    int Int(const std::string& name) const;
    float Float(const std::string& name) const;
    std::string Choice(const std::string& name) const;

  private:
    const OptionSpec& Spec(const std::string& name) const;  // CHECKs that it is declared
    double Number(const OptionSpec& spec, const std::string& text) const;
    std::string Text(const OptionSpec& spec) const;
    std::string solver_;
    std::vector<OptionSpec> specs_;
    SolverOptions given_;
};

// Sets option `name` from a number or a word, as text (floats with every digit kept).
void SetOption(SolverOptions& options, const std::string& name, double value);
void SetOption(SolverOptions& options, const std::string& name, const std::string& value);
inline void SetOption(SolverOptions& options, const std::string& name, const char* value) {
    SetOption(options, name, std::string(value));
}

// "a, b or c".
std::string JoinChoices(const std::vector<std::string>& words, const char* last = " or ");
// "it takes a, b or c" (or "it takes none"): a solver's options, for messages.
std::string TakesText(const std::vector<OptionSpec>& specs);

}  // namespace penumbra
