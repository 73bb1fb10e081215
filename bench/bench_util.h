// Shared by the benchmarks: what machine a result was measured on.
#pragma once

#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "output/compare.h"
#include "output/irradiance_writer.h"
#include "reference/path_tracer.h"
#include "solver/solver.h"

namespace penumbra::bench {

inline std::string CpuModel() {
    std::ifstream in("/proc/cpuinfo");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("model name", 0) == 0) return line.substr(line.find(':') + 2);
    return "unknown";
}

// The options of a benchmark that runs one solver on devices (bench_office, bench_glossy):
// the scene, the results' folder, the devices, frames measured, iterations a frame, the
// reference's paths a vertex (0: no RMSE), bins and element size.
struct DeviceBenchOptions {
    std::string scene;
    std::string out = "bench/results";
    std::vector<std::string> devices{"cpu", "lavapipe"};
    int frames = 10, iterations = 1, samples = 1024, bins = 128;
    float elementSize = 0.5f;

    void AddTo(CLI::App& app, const std::string& sceneHelp, const std::string& framesHelp) {
        app.add_option("--scene", scene, sceneHelp)->capture_default_str();
        app.add_option("--out", out, "folder for the results JSON (empty: print only)")
            ->capture_default_str();
        app.add_option("--devices", devices, "devices to run: cpu, lavapipe, gpu")
            ->capture_default_str();
        app.add_option("--frames", frames, framesHelp)->capture_default_str();
        app.add_option("--iterations", iterations, "iterations (bounces) per frame")
            ->capture_default_str();
        app.add_option("--samples", samples, "reference paths per vertex for the RMSE (0: none)")
            ->capture_default_str();
        app.add_option("--bins", bins)->capture_default_str();
        app.add_option("--element-size", elementSize)->capture_default_str();
    }
};

// A report's opening: the benchmark's name, its scene and triangles, the machine.
inline nlohmann::json ReportHeader(const std::string& benchmark, const std::string& scenePath,
                                   size_t triangles) {
    nlohmann::json report;
    report["benchmark"] = benchmark;
    report["scene"] = scenePath;
    report["triangles"] = triangles;
    report["machine"] = {{"cpu", CpuModel()}, {"threads", std::thread::hardware_concurrency()}};
    return report;
}

inline double Median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    size_t n = v.size();
    return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

// Writes `report` as `folder/name` (pretty JSON) and says so; throws on failure. An empty
// `folder` (`--out ""`) writes nothing: the table printed is the result.
inline void WriteReport(const nlohmann::json& report, const std::string& folder,
                        const std::string& name) {
    if (folder.empty()) {
        std::printf("%s not written (--out is empty)\n", name.c_str());
        return;
    }
    std::filesystem::create_directories(folder);
    std::string path = folder + "/" + name;
    std::ofstream file(path);
    if (!file) throw std::runtime_error(path + ": cannot write");
    file << report.dump(2) << "\n";
    std::printf("wrote %s\n", path.c_str());
}

// `penumbra reference` of `scene` (channel `indirect`, the solvers' default) at `samples`
// paths per vertex, as `compare` reads it.
inline IrradianceFile Reference(const Scene& scene, int samples,
                                Channel channel = Channel::kIndirect) {
    ReferenceSettings rs;
    rs.samples = samples;
    rs.channel = channel;
    return ReferenceFile(scene, rs);
}

// Accuracy beside speed (issue 18): the solver iterated on until an iteration changes the
// answer by less than 10⁻³ (at most 500), its relative RMSE against `truth`.
inline void AddAccuracy(nlohmann::json& j, const Scene& scene, Solver& solver,
                        const IrradianceFile& truth, Channel channel = Channel::kIndirect) {
    Convergence c = IterateUntilConverged(solver, 1e-3, 500);
    IrradianceFile mine = ToIrradianceFile(scene, CollectIrradiance(scene, solver, channel));
    j["rel_rmse"] = Compare(mine, truth).overall.relRmse;
    j["rmse_after_iterations"] = solver.Stats().iterations;
    j["rmse_converged"] = c.converged;
}

// Each pass's milliseconds between two Stats() of one solver (SolverStats keeps totals).
inline std::vector<std::pair<std::string, double>> PassDeltas(const SolverStats& before,
                                                              const SolverStats& after) {
    std::vector<std::pair<std::string, double>> d;
    for (size_t p = 0; p < after.passes.size(); ++p)
        d.push_back({after.passes[p].name,
                     after.passes[p].msTotal -
                         (p < before.passes.size() ? before.passes[p].msTotal : 0.0)});
    return d;
}

// Builds the solver, runs a warm-up frame, then `frames` frames of `iterationsPerFrame`
// iterations (bounces): the bake stats plus median frame and per-pass times; with `truth`, the
// relative RMSE of the answer those settings converge to (AddAccuracy).
inline nlohmann::json RunDevice(const Scene& scene, SolverSettings settings, int frames,
                                int iterationsPerFrame, const IrradianceFile* truth = nullptr) {
    auto solver = CreateSolver(scene, settings);
    solver->Iterate(iterationsPerFrame);  // warm-up frame
    std::vector<double> frameMs;
    std::map<std::string, std::vector<double>> passMs;
    SolverStats before = solver->Stats();
    const int gathersBefore = before.gathers;
    for (int f = 0; f < frames; ++f) {
        auto t0 = std::chrono::steady_clock::now();
        solver->Iterate(iterationsPerFrame);
        frameMs.push_back(
            std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                .count());
        SolverStats after = solver->Stats();
        const int passes = std::max(1, after.gathers - before.gathers);
        for (const auto& [name, ms] : PassDeltas(before, after))
            passMs[name].push_back(ms / passes);
        before = after;
    }
    SolverStats s = solver->Stats();
    double frame = Median(frameMs);
    nlohmann::json j = StatsToJson(s);  // totals over the whole run, as `bake` reports them
    j["links_per_second"] = s.links / s.linkBuildSeconds;
    j["iterations_per_frame"] = iterationsPerFrame;
    j["frames_measured"] = frames;
    j["frame_ms_median"] = frame;
    j["ms_per_iteration_median"] = frame / iterationsPerFrame;
    j["fps"] = 1000.0 / frame;
    for (const auto& [name, v] : passMs) j["passes"][name + "_ms_per_pass_median"] = Median(v);
    j["table_mib"] = s.tableBytes / 1048576.0;
    j["passes_per_frame"] = static_cast<double>(s.gathers - gathersBefore) / frames;
    if (truth) AddAccuracy(j, scene, *solver, *truth);
    return j;
}

}  // namespace penumbra::bench
