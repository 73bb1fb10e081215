// The `penumbra` command line. `bake` runs a solver in-process (no server) and writes
// per-vertex irradiance as JSON or as glTF with COLOR_0.
#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>

#include "base/check.h"
#include "base/progress.h"
#include "output/irradiance_writer.h"
#include "scene/gltf_loader.h"
#include "solver/solver.h"

namespace {

using namespace penumbra;

bool EndsWith(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

int Bake(const std::string& scenePath, const std::string& outPath, SolverSettings settings,
         int iterations, const std::string& device, const std::string& scheme, bool quiet) {
    if (!EndsWith(outPath, ".json") && !EndsWith(outPath, ".glb") && !EndsWith(outPath, ".gltf"))
        throw Error("output '" + outPath + "' must end in .json, .glb or .gltf");
    settings.device = ParseDevice(device);
    settings.scheme = ParseScheme(scheme);
    if (iterations < 0 || iterations > 100000)
        throw Error("--iterations must be between 0 and 100000");

    Progress progress(!quiet && StderrIsTerminal());
    progress.Update("loading " + scenePath, 0.0);
    Scene scene = LoadGltf(scenePath);
    auto solver = CreateSolver(
        scene, settings, [&](const std::string& stage, double f) { progress.Update(stage, f); });
    solver->Iterate(iterations);
    progress.Done();

    IrradianceResult result = CollectIrradiance(scene, *solver);
    if (EndsWith(outPath, ".json"))
        WriteIrradianceJson(outPath, scene, result);
    else
        WriteIrradianceGltf(scenePath, outPath, scene, result);

    if (!quiet) {
        const SolverStats& s = result.stats;
        std::fprintf(stderr,
                     "%s: %zu triangles -> %zu elements, %zu links, %d bins, element size %.4g m\n"
                     "  device %s; links built in %.3f s; %d iterations at %.2f ms each",
                     scenePath.c_str(), scene.TriangleCount(), s.elements, s.links, s.bins,
                     s.elementSize, s.device.c_str(), s.linkBuildSeconds, s.iterations,
                     s.MsPerIteration());
        for (const auto& p : s.passes)
            std::fprintf(stderr, " | %s %.2f", p.name.c_str(),
                         s.iterations ? p.msTotal / s.iterations : 0.0);
        std::fprintf(stderr, "\n  wrote %s (channel %s; %s)\n", outPath.c_str(),
                     result.channel.c_str(), kIrradianceUnits);
    }
    return 0;
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"Penumbra: a headless lighting service (antiradiance global illumination)"};
    app.require_subcommand(1);

    auto* bake = app.add_subcommand("bake",
                                    "Light a glTF scene in-process and write per-vertex "
                                    "irradiance (.json, or .glb/.gltf with COLOR_0)");
    std::string scenePath, outPath, device = "auto", scheme = "symmetric",
                                    linkOracle = "conservative";
    SolverSettings settings;
    int iterations = 8;
    bool quiet = false;
    bake->add_option("scene", scenePath, "glTF 2.0 scene (.gltf or .glb)")->required();
    bake->add_option("-o,--output", outPath, "output file: .json, .glb or .gltf")->required();
    bake->add_option("--solver", settings.solver, "solver (antiradiance)")->capture_default_str();
    bake->add_option("--bins", settings.bins, "direction bins, 32..1024, a multiple of 4")
        ->capture_default_str();
    bake->add_option("--iterations", iterations, "solver iterations")->capture_default_str();
    bake->add_option("--element-size", settings.elementSize,
                     "longest element edge after refinement, metres (default: scene diameter/40)");
    bake->add_option("--scheme", scheme, "symmetric or asymmetric iteration (Sec. 2.2)")
        ->capture_default_str();
    bake->add_option("--device", device,
                     "auto, gpu, lavapipe or cpu (auto: a real GPU if present, else cpu)")
        ->capture_default_str();
    bake->add_option("--oracle", settings.oracle,
                     "link refinement threshold, in units of a bin's solid angle")
        ->capture_default_str();
    bake->add_option("--receiver-oracle", settings.receiverOracle,
                     "receiver solid-angle threshold relative to --oracle")
        ->capture_default_str();
    bake->add_option("--link-oracle", linkOracle,
                     "conservative (accurate) or paper (Sec. 3.2: fewer links)")
        ->capture_default_str();
    bake->add_option("--threads", settings.threads, "CPU threads (0: all cores)")
        ->capture_default_str();
    bake->add_flag("--validation", settings.validation, "enable Vulkan validation layers");
    bake->add_flag("-q,--quiet", quiet, "no progress or summary on stderr");

    CLI11_PARSE(app, argc, argv);
    try {
        if (bake->parsed()) {
            settings.paperOracle = ParsePaperOracle(linkOracle);
            return Bake(scenePath, outPath, settings, iterations, device, scheme, quiet);
        }
    } catch (const penumbra::Error& e) {
        std::fprintf(stderr, "\npenumbra: error: %s\n", e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "\npenumbra: internal error: %s\n", e.what());
        return 3;
    }
    return 0;
}
