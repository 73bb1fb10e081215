// The light-field solver (issue 22) against the paper's Table 1 classes and on the bundled
// scenes at its defaults: time to an answer beside that answer's relative RMSE against
// `penumbra reference`. Prints a table and writes bench/results/lightfield.json.
//
// Classes (Mortensen et al. 2008, Table 1, GeForce 8800 GTX; 512 two-way directions, three
// propagation iterations): the Cornell box (19 faces, 34,816 diffuse elements, 64×64 cells:
// 4.067 s), the Grotto (318 faces, 816,640 elements: 17.2 s). Here: the bundled Cornell box
// and maze refined to as many surfels, one batch of 512 line directions (each both ways), three
// iterations (one trace, three walks), the emitters carried by the lines (no first shot); and
// the classes as the solver runs them, with the first shot and more iterations.
#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <thread>

#include "bench_util.h"
#include "gather/gather_stage.h"
#include "scene/gltf_loader.h"
#include "solver/solver.h"

namespace {

using namespace penumbra;
using Clock = std::chrono::steady_clock;

double Seconds(Clock::time_point t) {
    return std::chrono::duration<double>(Clock::now() - t).count();
}

struct Case {
    std::string name, scene;
    float elementSize = 0.0f;  // 0: the default
    int directions = 64, batches = 8, cells = 0;
    int iterations = 0;   // 0: until converged (10⁻³, at most 200)
    int emitterRays = 0;  // the gather stage's first shot (0: the lines carry the emitters)
    std::string paper;    // the paper's figure for the class
};

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{
        "penumbra light-field benchmark (issue 22): the paper's classes, accuracy beside speed"};
    std::string out = "bench/results";
    int samples = 1024;
    bool quick = false;
    std::vector<std::string> devices{"cpu"};
    std::string name = "lightfield.json";
    app.add_option("--out", out, "folder for the results JSON (empty: print only)")
        ->capture_default_str();
    app.add_option("--name", name, "the results file's name")->capture_default_str();
    app.add_option("--devices", devices, "devices to run each case on: cpu, lavapipe, gpu")
        ->capture_default_str();
    app.add_option("--samples", samples, "reference paths per vertex")->capture_default_str();
    app.add_flag("--quick", quick, "the bundled scenes at their defaults only");
    CLI11_PARSE(app, argc, argv);

    std::vector<Case> cases;
    if (!quick) {
        cases.push_back({"cornell class", "scenes/cornell-box.gltf", 0.01424f, 512, 1, 64, 3, 0,
                         "Cornell box, 19 faces, 34,816 elements, 64x64 cells: 4.067 s"});
        // The class as the solver runs it: the emitters' first shot (the gather stage's, as
        // at the defaults) and iterations until converged (three bounces leave light out).
        cases.push_back(
            {"cornell class, shot", "scenes/cornell-box.gltf", 0.01424f, 512, 1, 64, 0, 256, ""});
        // The same surfels with cells half an element wide, to convergence: what its answer
        // costs when the lines resolve the surfels.
        cases.push_back(
            {"cornell class, cells", "scenes/cornell-box.gltf", 0.01424f, 64, 8, 0, 0, 0, ""});
        cases.push_back({"grotto class", "scenes/maze.gltf", 0.01475f, 512, 1, 128, 3, 0,
                         "Grotto, 318 faces, 816,640 elements: 17.2 s (cells not given)"});
        // The Grotto class with a first shot of 16 rays a surfel (1.2M surfels): at eight
        // iterations (the paper's time), and to convergence.
        cases.push_back(
            {"grotto class, shot 8", "scenes/maze.gltf", 0.01475f, 512, 1, 128, 8, 16, ""});
        cases.push_back(
            {"grotto class, shot", "scenes/maze.gltf", 0.01475f, 512, 1, 128, 0, 16, ""});
    }
    for (const char* s : {"cornell-box", "blocker", "maze", "office"}) {
        cases.push_back({std::string(s) + " defaults", std::string("scenes/") + s + ".gltf", 0, 64,
                         8, 0, 0, 0, ""});
        cases.push_back({std::string(s) + " + first shot", std::string("scenes/") + s + ".gltf", 0,
                         64, 8, 0, 0, 256, ""});
    }

    nlohmann::json report;
    report["benchmark"] = "lightfield";
    report["device"] = "cpu: " + bench::CpuModel() + ", " +
                       std::to_string(std::thread::hardware_concurrency()) + " threads";
    report["reference_samples"] = samples;
    std::printf("light field on %s; reference %d paths a vertex\n",
                report["device"].get<std::string>().c_str(), samples);
    std::printf("%-22s %-8s %8s %6s %5s %6s %5s %8s %9s %9s %9s %8s %8s\n", "case", "device",
                "surfels", "dirs", "cells", "smooth", "iters", "hits M", "setup s", "trace s",
                "walk ms", "total s", "rel rmse");
    std::map<std::string, IrradianceFile> truths;
    try {
        for (const Case& c : cases) {
            const Scene scene = LoadGltf(c.scene);
            if (!truths.count(c.scene)) truths.emplace(c.scene, bench::Reference(scene, samples));
            for (const std::string& device : devices) {
                SolverSettings s;
                s.solver = "lightfield";
                s.device = ParseDevice(device);
                s.elementSize = c.elementSize;
                SetOption(s.options, "directions", c.directions);
                SetOption(s.options, "batches", c.batches);
                SetOption(s.options, "cells", c.cells);
                GatherSettings g;
                g.emitterRays = c.emitterRays;
                g.gatherRays = 0;
                const auto t = Clock::now();
                std::unique_ptr<Solver> solver;
                try {
                    solver = CreateGatheredSolver(scene, s, g);
                } catch (const Error& e) {
                    std::printf("%-22s %-8s unavailable: %s\n", c.name.c_str(), device.c_str(),
                                e.what());
                    continue;
                }
                const double setup = Seconds(t);
                int iterations = c.iterations;
                if (iterations > 0)
                    solver->Iterate(iterations);
                else
                    iterations = IterateUntilConverged(*solver, 1e-3, 200).iterations;
                const double total = Seconds(t);
                const SolverStats st = solver->Stats();
                const IrradianceFile mine =
                    ToIrradianceFile(scene, CollectIrradiance(scene, *solver, Channel::kIndirect));
                const double rel = Compare(mine, truths.at(c.scene)).overall.relRmse;
                const double walk = st.Number("last_walk_ms");
                const double trace = st.linkBuildSeconds;
                std::printf(
                    "%-22s %-8s %8zu %6d %5d %6d %5d %8.1f %9.2f %9.2f %9.1f %8.2f %7.2f%%\n",
                    c.name.c_str(), device.c_str(), st.elements,
                    c.directions * int(st.Number("batches")), int(st.Number("cells")),
                    int(st.Number("smoothing_passes")), iterations, st.Number("line_hits") / 1e6,
                    setup, trace, walk, total, 100 * rel);
                nlohmann::json j = StatsToJson(st);
                j["case"] = c.name;
                j["scene"] = c.scene;
                j["line_directions"] = c.directions * int(st.Number("batches"));
                j["iterations"] = iterations;
                j["first_shot_rays"] = c.emitterRays;
                j["setup_seconds"] = setup;
                j["trace_seconds"] = trace;
                j["last_walk_ms"] = walk;
                j["total_seconds"] = total;
                j["rel_rmse"] = rel;
                if (!c.paper.empty()) j["paper"] = c.paper;
                report["results"].push_back(j);
            }
        }
        bench::WriteReport(report, out, name);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "error: %s\n", e.what());
        return 1;
    }
    return 0;
}
