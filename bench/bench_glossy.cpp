// Glossy scenes (issue 5): the local pass with glossy lobes (Eq. 18 summed over incoming
// bins) against the diffuse fast path on the same scene, and the glossy box's frame time at
// 3 iterations (goal: under 200 ms per frame on this machine; the paper ran its glossy box,
// 4.6K elements and 177K links, at 14.9 fps for 3 iterations). The diffuse variant replaces
// every glossy material by a diffuse one of albedo ρ_d + F0; the all-glossy variant makes
// every material a glossy dielectric (roughness 0.4), the local pass's worst case. Prints a
// table and writes JSON to --out; beside each frame rate, the relative RMSE of the answer
// those settings converge to against `penumbra reference` (issue 18).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <thread>

#include "base/check.h"
#include "bench_util.h"
#include "scene/gltf_loader.h"
#include "solver/solver.h"
#include "solvers/antiradiance/settings.h"

using namespace penumbra;
using bench::RunDevice;

int main(int argc, char** argv) {
    CLI::App app{"penumbra glossy benchmark (local pass with lobes, issue 5)"};
    bench::DeviceBenchOptions o;
    o.scene = "scenes/glossy-box.gltf";
    o.iterations = 3;
    o.elementSize = 0.25f;
    o.AddTo(app, "glTF with glossy materials", "frames measured per case");
    CLI11_PARSE(app, argc, argv);

    try {
        SolverSettings settings;
        settings.solver = "antiradiance";  // its lobes are what this measures
        settings.elementSize = o.elementSize;
        SetOption(settings.options, "bins", o.bins);
        Scene glossy = LoadGltf(o.scene);
        Scene diffuse = glossy, allGlossy = glossy;
        for (Material& m : diffuse.materials)
            if (m.Glossy()) m = DiffuseMaterial(m.name, glm::min(m.albedo + m.specular, 1.0f));
        for (Material& m : allGlossy.materials)
            if (!m.Glossy()) m = PbrMaterial(m.name, m.baseColor, 0.0f, 0.4f, m.emission);
        const std::pair<const char*, const Scene*> variants[] = {
            {"glossy", &glossy}, {"diffuse", &diffuse}, {"all-glossy", &allGlossy}};
        nlohmann::json report = bench::ReportHeader("glossy", o.scene, glossy.TriangleCount());
        report["settings"] = {{"bins", o.bins},
                              {"element_size", settings.elementSize},
                              {"link_oracle", "conservative"},
                              {"scheme", SchemeName(ReadAntiradianceSettings(settings).scheme)},
                              {"iterations_per_frame", o.iterations},
                              {"reference_samples", o.samples}};
        std::map<std::string, IrradianceFile> truth;
        if (o.samples > 0)
            for (const auto& [name, scene] : variants)
                truth[name] = bench::Reference(*scene, o.samples);
        std::printf(
            "%s: %zu triangles, %d bins, element %.2f m, %d iterations/frame, median of "
            "%d frames\n",
            o.scene.c_str(), glossy.TriangleCount(), o.bins, settings.elementSize, o.iterations,
            o.frames);
        std::printf("%-30s %-10s %8s %7s %9s %9s %9s %9s %7s %9s\n", "device", "surfaces",
                    "elements", "glossy", "links", "local ms", "ms/iter", "frame ms", "fps",
                    "rel.RMSE");
        for (const auto& d : o.devices) {
            for (const auto& [name, scene] : variants) {
                SolverSettings s = settings;
                s.device = ParseDevice(d);
                nlohmann::json r;
                try {
                    r = RunDevice(*scene, s, o.frames, o.iterations,
                                  o.samples > 0 ? &truth.at(name) : nullptr);
                } catch (const Error& e) {
                    std::printf("%-30s unavailable: %s\n", d.c_str(), e.what());
                    break;
                }
                r["surfaces"] = name;
                double local = r["passes"].value("local_ms_per_pass_median", 0.0);
                char rmse[16] = "-";
                if (r.contains("rel_rmse"))
                    std::snprintf(rmse, sizeof rmse, "%.1f%%", 100 * r["rel_rmse"].get<double>());
                std::printf("%-30.30s %-10s %8zu %7zu %9zu %9.2f %9.2f %9.1f %7.1f %9s\n",
                            r["device"].get<std::string>().c_str(),
                            r["surfaces"].get<std::string>().c_str(), r["elements"].get<size_t>(),
                            r.value("glossy_elements", size_t(0)), r["links"].get<size_t>(), local,
                            r["ms_per_iteration_median"].get<double>(),
                            r["frame_ms_median"].get<double>(), r["fps"].get<double>(), rmse);
                report["results"].push_back(r);
            }
        }
        bench::WriteReport(report, o.out, "glossy.json");
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench: %s\n", e.what());
        return 1;
    }
    return 0;
}
