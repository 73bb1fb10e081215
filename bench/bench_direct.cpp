// Direct light on the office-scale scene (issue 5): the shadow pass and the direct-light
// initialisation for one point light and one directional light, against one solver
// iteration on the same device (goal: under 15% of an iteration on lavapipe). Light updates
// are timed as the service runs them (Solver::UpdateLights); then the binning of a sky map
// (environment light). Prints tables and writes JSON to --out.
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
#include "direct/environment_light.h"
#include "scene/gltf_loader.h"
#include "solver/solver.h"
#include "solvers/antiradiance/settings.h"

namespace {

using namespace penumbra;
using bench::Median;

// The office with a point light under the middle of its ceiling and a sun from the side.
Scene LitOffice(const std::string& path) {
    Scene scene = LoadGltf(path);
    glm::vec3 lo = scene.BoundsMin(), hi = scene.BoundsMax();
    glm::vec3 centre = 0.5f * (lo + hi);
    auto add = [&](const std::string& name, LightType type, glm::vec3 position, glm::vec3 direction,
                   float intensity) {
        SceneNode node;
        node.name = name;
        scene.nodes.push_back(node);
        PunctualLight l;
        l.name = name;
        l.node = static_cast<int>(scene.nodes.size() - 1);
        l.type = type;
        l.intensity = intensity;
        l.position = position;
        l.direction = glm::normalize(direction);
        scene.lights.push_back(l);
    };
    add("lamp", LightType::kPoint, {centre.x, hi.y - 0.3f, centre.z}, {0, -1, 0}, 200.0f);
    add("sun", LightType::kDirectional, centre, {-0.6f, -0.5f, 0.3f}, 2000.0f);
    return scene;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"penumbra direct-light benchmark (shadow pass + direct init, issue 5)"};
    std::string scenePath = "scenes/office.gltf", out = "bench/results";
    std::vector<std::string> devices{"cpu", "lavapipe"};
    std::vector<int> mapSizes{0, 1024};  // 0: the solver's default, from the element size
    int updates = 10, iterations = 4;
    SolverSettings settings;
    settings.solver = "antiradiance";  // its bins and oracle below
    SetOption(settings.options, "bins", 128);
    settings.elementSize = 0.5f;
    SetOption(settings.options, "link-oracle", "paper");
    SetOption(settings.options, "oracle", 2.15f);
    app.add_option("--scene", scenePath, "office-scale glTF")->capture_default_str();
    app.add_option("--out", out, "folder for the results JSON (empty: print only)")
        ->capture_default_str();
    app.add_option("--devices", devices, "cpu, lavapipe, gpu")->capture_default_str();
    app.add_option("--map-sizes", mapSizes, "shadow map sizes to run")->capture_default_str();
    app.add_option("--updates", updates, "light updates timed per case")->capture_default_str();
    app.add_option("--iterations", iterations, "solver iterations timed per case")
        ->capture_default_str();
    CLI11_PARSE(app, argc, argv);

    try {
        Scene scene = LitOffice(scenePath);
        nlohmann::json report;
        report["benchmark"] = "direct";
        report["scene"] = scenePath;
        report["triangles"] = scene.TriangleCount();
        report["lights"] = "one point light (cube map, 6 views) + one directional light (1 view)";
        report["machine"] = {{"cpu", bench::CpuModel()},
                             {"threads", std::thread::hardware_concurrency()}};
        std::printf(
            "office + point light + directional light: %zu triangles, median of %d light "
            "updates\n",
            scene.TriangleCount(), updates);
        std::printf("%-34s %6s %8s %10s %10s %10s %10s %8s\n", "device", "map", "elements",
                    "shadow ms", "direct ms", "update ms", "iter ms", "share");
        for (const auto& d : devices)
            for (int size : mapSizes) {
                SolverSettings s = settings;
                s.device = ParseDevice(d);
                s.shadowMapSize = size;
                std::unique_ptr<Solver> solver;
                try {
                    solver = CreateSolver(scene, s);
                } catch (const Error& e) {
                    std::printf("%-34s unavailable: %s\n", d.c_str(), e.what());
                    break;
                }
                solver->Iterate(1);  // warm-up
                auto t0 = std::chrono::steady_clock::now();
                solver->Iterate(iterations);
                double iterMs =
                    std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                        .count() /
                    iterations;
                std::vector<double> shadow, direct, wall;
                Scene moving = scene;
                for (int u = 0; u < updates; ++u) {
                    moving.lights[0].position.x += 0.01f;  // a light edit, as the service sees it
                    auto u0 = std::chrono::steady_clock::now();
                    solver->UpdateLights(moving);
                    wall.push_back(std::chrono::duration<double, std::milli>(
                                       std::chrono::steady_clock::now() - u0)
                                       .count());
                    SolverStats st = solver->Stats();
                    shadow.push_back(st.lighting.msShadow);
                    direct.push_back(st.lighting.msDirect);
                }
                SolverStats st = solver->Stats();
                double device = Median(shadow) + Median(direct);
                double share = device / iterMs;
                size = st.lighting.shadowMapSize;
                std::printf("%-34.34s %6d %8zu %10.2f %10.2f %10.2f %10.2f %7.1f%%\n",
                            st.device.c_str(), size, st.elements, Median(shadow), Median(direct),
                            Median(wall), iterMs, 100.0 * share);
                report["results"].push_back({{"device", st.device},
                                             {"map_size", size},
                                             {"shadow_views", st.lighting.shadowViews},
                                             {"elements", st.elements},
                                             {"links", st.links},
                                             {"shadow_ms_median", Median(shadow)},
                                             {"direct_ms_median", Median(direct)},
                                             {"update_wall_ms_median", Median(wall)},
                                             {"ms_per_iteration", iterMs},
                                             {"share_of_iteration", share}});
            }
        // The environment: binning a sky map (done at load and when the sky changes).
        std::printf("\nenvironment binning, %d bins, median of 5 (all threads)\n",
                    ReadAntiradianceSettings(settings).bins);
        std::printf("%-24s %10s\n", "sky", "ms");
        Directions dirs(ReadAntiradianceSettings(settings).bins);
        for (int width : {0, 512, 2048, 4096}) {
            Environment env = ConstantEnvironment(glm::vec3(1.0f));
            if (width) {
                auto image = std::make_shared<Image>(width, width / 2);
                for (int y = 0; y < image->height; ++y)
                    for (int x = 0; x < width; ++x)
                        image->At(x, y) = glm::vec3(1.0f + 0.5f * std::sin(0.01f * x * y));
                env.image = image;
                env.source = "synthetic";
            }
            std::vector<double> ms;
            for (int r = 0; r < 5; ++r) {
                auto t0 = std::chrono::steady_clock::now();
                std::vector<glm::vec3> bins = direct::EnvironmentBins(env, dirs);
                ms.push_back(
                    std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0)
                        .count());
                if (bins.empty()) return 1;
            }
            std::string name =
                width ? std::to_string(width) + "×" + std::to_string(width / 2) + " map"
                      : "constant";
            std::printf("%-24s %10.2f\n", name.c_str(), Median(ms));
            report["environment_binning"].push_back(
                {{"sky", name},
                 {"bins", ReadAntiradianceSettings(settings).bins},
                 {"ms_median", Median(ms)}});
        }
        bench::WriteReport(report, out, "direct.json");
    } catch (const std::exception& e) {
        std::fprintf(stderr, "bench: %s\n", e.what());
        return 1;
    }
    return 0;
}
