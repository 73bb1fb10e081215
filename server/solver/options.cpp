// Parsing and checking a solver's options against its declarations (solver/options.h).
#include "solver/options.h"

#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <utility>

#include "base/check.h"

namespace penumbra {

OptionSpec BinsOption(const std::string& zeroMeans) {
    return {"bins", OptionKind::kInt,
            "0",    "direction bins, 32..1024, a multiple of 4; 0: " + zeroMeans,
            0,      1024,
            {}};
}

std::string JoinChoices(const std::vector<std::string>& words, const char* last) {
    std::string out;
    for (size_t i = 0; i < words.size(); ++i) {
        if (i > 0) out += i + 1 == words.size() ? last : ", ";
        out += words[i];
    }
    return out;
}

void SetOption(SolverOptions& options, const std::string& name, double value) {
    char text[40];
    std::snprintf(text, sizeof text, "%.9g", value);
    options[name] = text;
}

void SetOption(SolverOptions& options, const std::string& name, const std::string& value) {
    options[name] = value;
}

std::string TakesText(const std::vector<OptionSpec>& specs) {
    std::vector<std::string> names;
    for (const OptionSpec& s : specs) names.push_back(s.name);
    return names.empty() ? "it takes none" : "it takes " + JoinChoices(names);
}

OptionReader::OptionReader(std::string solver, const std::vector<OptionSpec>& specs,
                           const SolverOptions& given)
    : solver_(std::move(solver)), specs_(specs), given_(given) {
    for (const auto& [name, text] : given_) {
        const OptionSpec* spec = nullptr;
        for (const OptionSpec& s : specs_)
            if (s.name == name) spec = &s;
        if (!spec)
            throw Error("solver '" + solver_ + "' has no option '" + name + "' (" +
                        TakesText(specs_) + ")");
        if (spec->kind == OptionKind::kChoice) {
            bool known = false;
            for (const std::string& c : spec->choices) known = known || c == text;
            if (!known)
                throw Error("option '" + name + "' of solver '" + solver_ + "' is '" + text +
                            "' (use " + JoinChoices(spec->choices) + ")");
        } else {
            Number(*spec, text);
        }
    }
}

const OptionSpec& OptionReader::Spec(const std::string& name) const {
    for (const OptionSpec& s : specs_)
        if (s.name == name) return s;
    CheckFailed(__FILE__, __LINE__,
                "solver '" + solver_ + "' reads an undeclared option '" + name + "'");
}

std::string OptionReader::Text(const OptionSpec& spec) const {
    auto it = given_.find(spec.name);
    return it != given_.end() ? it->second : spec.defaultText;
}

double OptionReader::Number(const OptionSpec& spec, const std::string& text) const {
    const char* begin = text.c_str();
    char* end = nullptr;
    errno = 0;
    const double v = std::strtod(begin, &end);
    const bool whole = spec.kind != OptionKind::kInt || v == std::floor(v);
    if (text.empty() || end != begin + text.size() || errno == ERANGE || !std::isfinite(v) ||
        !whole)
        throw Error("option '" + spec.name + "' of solver '" + solver_ + "' is '" + text +
                    "', not " + (spec.kind == OptionKind::kInt ? "a whole number" : "a number"));
    if (v < spec.min || v > spec.max) {
        char range[96];
        std::snprintf(range, sizeof range, "%g…%g", spec.min, spec.max);
        throw Error("option '" + spec.name + "' of solver '" + solver_ + "' is " + text +
                    ", outside " + range);
    }
    return v;
}

bool OptionReader::Given(const std::string& name) const {
    Spec(name);
    return given_.count(name) > 0;
}

int OptionReader::Int(const std::string& name) const {
    const OptionSpec& s = Spec(name);
    if (s.kind != OptionKind::kInt)
        CheckFailed(__FILE__, __LINE__, "option '" + name + "' is not read as a int");
    return static_cast<int>(Number(s, Text(s)));
}

float OptionReader::Float(const std::string& name) const {
    const OptionSpec& s = Spec(name);
    if (s.kind != OptionKind::kFloat)
        CheckFailed(__FILE__, __LINE__, "option '" + name + "' is not read as a float");
    return static_cast<float>(Number(s, Text(s)));
}

std::string OptionReader::Choice(const std::string& name) const {
    const OptionSpec& s = Spec(name);
    if (s.kind != OptionKind::kChoice)
        CheckFailed(__FILE__, __LINE__, "option '" + name + "' is not read as a choice");
    return Text(s);
}

}  // namespace penumbra
