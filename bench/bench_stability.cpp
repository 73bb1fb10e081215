// Stability and accuracy on cluttered scenes (issue 18): each scene of the clutter suite
// (tools/clutter_scenes.h) iterated for a number of iterations on each device; per scene the
// largest |E| any iteration produced against the furnace bound, the change over the last 100
// iterations, the passes and antiradiance steps the schedule took, ms per pass, and the relative
// RMSE against `penumbra reference` at the same scene. Prints a table and writes
// bench/results/stability.json.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <sstream>

#include "bench_util.h"
#include "clutter_scenes.h"
#include "output/compare.h"
#include "output/irradiance_writer.h"
#include "reference/path_tracer.h"
#include "solver/solver.h"
#include "solvers/antiradiance/settings.h"

namespace {

using namespace penumbra;
using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

std::vector<std::string> Split(const std::string& s) {
    std::vector<std::string> out;
    std::stringstream in(s);
    for (std::string item; std::getline(in, item, ',');)
        if (!item.empty()) out.push_back(item);
    return out;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"Stability and accuracy of the solver on cluttered scenes"};
    std::string out, devices = "cpu", scenes, scheme = "adaptive", solverName = "antiradiance";
    int iterations = 500, samples = 2048, bins = 128;
    float elementSize = 0.0f;
    app.add_option("--out", out,
                   "folder for stability.json, or stability-SOLVER.json for another solver "
                   "(none: print only)");
    app.add_option("--solver", solverName, "antiradiance, implicit or lightfield")
        ->capture_default_str();
    app.add_option("--devices", devices, "comma-separated: cpu, lavapipe, gpu")
        ->capture_default_str();
    app.add_option("--scenes", scenes, "comma-separated scene names (default: the whole suite)");
    app.add_option("--scheme", scheme, "adaptive, symmetric or asymmetric (antiradiance)")
        ->capture_default_str();
    app.add_option("--iterations", iterations, "iterations (bounces) per scene (>= 101)")
        ->capture_default_str();
    app.add_option("--samples", samples, "reference samples per vertex (0: no reference)")
        ->capture_default_str();
    app.add_option("--bins", bins, "direction bins (antiradiance, implicit)")
        ->capture_default_str();
    app.add_option("--element-size", elementSize, "metres (0: the scene's default)");
    CLI11_PARSE(app, argc, argv);
    if (iterations < 101) {
        std::fprintf(stderr, "--iterations must be at least 101\n");
        return 2;
    }
    const std::vector<std::string> wanted = Split(scenes);

    nlohmann::json report;
    report["machine"] = {{"cpu", bench::CpuModel()}};
    const bool antiradiance = solverName == "antiradiance";
    report["settings"] = {
        {"solver", solverName}, {"iterations", iterations},     {"bins", bins},
        {"scheme", scheme},     {"reference_samples", samples}, {"element_size", elementSize}};
    std::printf(
        "| scene | device | elements | links | max |E| / bound | change last 100 | passes "
        "| AR steps (last) | ms/pass | rel. RMSE |\n|---|---|---|---|---|---|---|---|---|---|\n");
    for (auto& entry : scenes::ClutterSuite()) {
        std::string name = entry.name.substr(0, entry.name.size() - 5);
        if (!wanted.empty() && std::find(wanted.begin(), wanted.end(), name) == wanted.end())
            continue;
        const Scene scene = entry.builder.Build();
        const IrradianceFile truth =
            samples > 0 ? bench::Reference(scene, samples) : IrradianceFile{};
        for (const std::string& device : Split(devices)) {
            SolverSettings settings;
            settings.solver = solverName;
            settings.device = ParseDevice(device);
            if (antiradiance) SetOption(settings.options, "scheme", scheme);
            if (antiradiance || solverName == "implicit") SetOption(settings.options, "bins", bins);
            settings.elementSize = elementSize;
            auto solver = CreateSolver(scene, settings);
            // The solver's own bound where it states one (antiradiance: the furnace bound with
            // its lights, sky and gloss), else the scene's furnace bound (emitters only: the
            // clutter scenes have no other light).
            float bound = solver->Stats().irradianceBound;
            if (!(bound > 0.0f) || !std::isfinite(bound)) bound = scenes::FurnaceBound(scene);
            float largest = 0.0f;
            std::vector<glm::vec3> before;
            auto start = Clock::now();
            for (int i = 0; i < iterations; ++i) {
                solver->Iterate(1);
                if (!solver->Stats().divergence.empty()) break;
                std::vector<glm::vec3> e = solver->SurfelIrradiance();
                for (const glm::vec3& v : e)
                    largest = std::max({largest, std::abs(v.x), std::abs(v.y), std::abs(v.z)});
                if (i == iterations - 101) before = std::move(e);
            }
            const double ms = MsSince(start);
            const SolverStats s = solver->Stats();
            nlohmann::json row = {{"scene", name},
                                  {"device", s.device},
                                  {"elements", s.elements},
                                  {"links", s.links},
                                  {"iterations", s.iterations},
                                  {"passes", s.gathers},
                                  {"bound_lux", bound},
                                  {"max_abs_irradiance_lux", largest},
                                  {"bounces", s.bounces},
                                  {"last_antiradiance_steps", s.Number("last_antiradiance_steps")},
                                  {"antiradiance_cap_hits", s.Number("antiradiance_cap_hits")},
                                  {"ms_per_pass", ms / std::max(1, s.gathers)}};
            std::string change = "-", rmse = "-";
            if (!s.divergence.empty()) {
                row["divergence"] = s.divergence;
                change = "diverged at " + std::to_string(s.iterations);
            } else {
                const double c = RelativeChange(solver->SurfelIrradiance(), before);
                row["change_last_100"] = c;
                char buf[32];
                std::snprintf(buf, sizeof buf, "%.2g%%", 100 * c);
                change = buf;
                if (samples > 0) {
                    IrradianceFile mine = ToIrradianceFile(
                        scene, CollectIrradiance(scene, *solver, Channel::kIndirect));
                    const double r = Compare(mine, truth).overall.relRmse;
                    row["rel_rmse"] = r;
                    std::snprintf(buf, sizeof buf, "%.1f%%", 100 * r);
                    rmse = buf;
                }
            }
            std::printf("| %s | %s | %zu | %zu | %.3g | %s | %d | %d | %.2f | %s |\n", name.c_str(),
                        s.device.c_str(), s.elements, s.links, largest / bound, change.c_str(),
                        s.gathers, int(s.Number("last_antiradiance_steps")),
                        ms / std::max(1, s.gathers), rmse.c_str());
            std::fflush(stdout);
            report["runs"].push_back(row);
        }
    }
    if (!out.empty())
        bench::WriteReport(report, out,
                           antiradiance ? "stability.json" : "stability-" + solverName + ".json");
    return 0;
}
