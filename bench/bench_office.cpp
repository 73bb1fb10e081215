// Office-scale benchmark of the antiradiance solver (issue 2): the paper's office has
// 5.6K triangles, 18.2K elements, 632K links, 128 bins, 4 symmetric iterations a frame,
// 10.1 fps on a GeForce 8800 GTX. Here the default (adaptive) scheme, one iteration (bounce)
// a frame; beside the frame rate, the relative RMSE of the answer these settings converge
// to against `penumbra reference` (issue 18). Prints a table and writes JSON to --out.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <thread>

#include "base/check.h"
#include "bench_util.h"
#include "output/irradiance_writer.h"
#include "scene/gltf_loader.h"
#include "solver/solver.h"
#include "solvers/antiradiance/settings.h"

using namespace penumbra;
using bench::RunDevice;

int main(int argc, char** argv) {
    CLI::App app{"penumbra office benchmark (antiradiance, issue 2)"};
    bench::DeviceBenchOptions o;
    o.scene = "scenes/office.gltf";
    o.AddTo(app, "office-scale glTF", "frames measured per device");
    float oracle = 2.15f;  // 626K links: the paper office has 632K
    app.add_option("--oracle", oracle, "paper oracle threshold")->capture_default_str();
    std::string tables = "auto";
    app.add_option("--tables", tables, "CPU back end tables: auto|fp32|fp16")
        ->capture_default_str();
    CLI11_PARSE(app, argc, argv);

    try {
        SolverSettings settings;
        settings.solver = "antiradiance";  // the paper office: its passes and oracle
        settings.elementSize = o.elementSize;
        SetOption(settings.options, "bins", o.bins);
        SetOption(settings.options, "link-oracle", "paper");
        SetOption(settings.options, "oracle", oracle);
        SetOption(settings.options, "tables", tables);
        Scene scene = LoadGltf(o.scene);
        nlohmann::json report = bench::ReportHeader("office", o.scene, scene.TriangleCount());
        report["settings"] = {{"bins", o.bins},
                              {"element_size", settings.elementSize},
                              {"link_oracle", "paper"},
                              {"oracle", oracle},
                              {"scheme", SchemeName(ReadAntiradianceSettings(settings).scheme)},
                              {"reference_samples", o.samples}};
        IrradianceFile truth;
        if (o.samples > 0) truth = bench::Reference(scene, o.samples);
        std::printf(
            "office: %zu triangles, %d bins, element %.2f m, paper oracle %.2f, "
            "%d iterations/frame, median of %d frames\n",
            scene.TriangleCount(), o.bins, settings.elementSize, oracle, o.iterations, o.frames);
        std::printf("%-34s %6s %8s %9s %8s %8s %8s %8s %8s %9s %7s %7s %8s %9s\n", "device",
                    "tables", "elements", "links", "build s", "global", "push", "local", "pull",
                    "ms/iter", "passes", "fps", "tbl MiB", "rel.RMSE");
        for (const auto& d : o.devices) {
            SolverSettings s = settings;
            s.device = ParseDevice(d);
            if (s.device != DeviceChoice::kCpu) SetOption(s.options, "tables", "auto");
            nlohmann::json r;
            try {
                r = RunDevice(scene, s, o.frames, o.iterations, o.samples > 0 ? &truth : nullptr);
            } catch (const Error& e) {
                std::printf("%-34s unavailable: %s\n", d.c_str(), e.what());
                continue;
            }
            // Passes a device does not have print as "-" (Vulkan folds the push into the
            // clusters' gather: docs/SOLVER.md).
            auto pass = [&](const char* n) {
                const std::string key = std::string(n) + "_ms_per_pass_median";
                char cell[16];
                if (r["passes"].contains(key))
                    std::snprintf(cell, sizeof cell, "%8.2f", r["passes"][key].get<double>());
                else
                    std::snprintf(cell, sizeof cell, "%8s", "-");
                return std::string(cell);
            };
            char rmse[16] = "-";
            if (r.contains("rel_rmse"))
                std::snprintf(rmse, sizeof rmse, "%.1f%%", 100 * r["rel_rmse"].get<double>());
            std::printf("%-34.34s %6s %8zu %9zu %8.3f %s %s %s %s %9.2f %7.1f %7.1f %8.1f %9s\n",
                        r["device"].get<std::string>().c_str(),
                        r["tables"].get<std::string>().c_str(), r["elements"].get<size_t>(),
                        r["links"].get<size_t>(), r["link_build_seconds"].get<double>(),
                        pass("global").c_str(), pass("push").c_str(), pass("local").c_str(),
                        pass("pull").c_str(), r["ms_per_iteration_median"].get<double>(),
                        r["passes_per_frame"].get<double>(), r["fps"].get<double>(),
                        r["table_mib"].get<double>(), rmse);
            report["results"].push_back(r);
        }
        bench::WriteReport(report, o.out, "office.json");
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench: %s\n", e.what());
        return 1;
    }
    return 0;
}
