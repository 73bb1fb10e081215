// The `penumbra` command line. `bake`, `reference` and `compare` run in-process; the service
// commands (load, watch, move, light, ...) talk to penumbra-server (cmd/service_cli.h).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>

#include "base/check.h"
#include "cmd/offline_commands.h"
#include "cmd/service_cli.h"
#include "cmd/solver_options.h"
#include "output/compare.h"
#include "solvers/registry.h"

// The subcommand nearest to `word` by edit distance (empty when none is within 2 edits).
std::string Nearest(const CLI::App& app, const std::string& word) {
    std::string best;
    size_t bestCost = 3;
    for (const CLI::App* sub : app.get_subcommands({})) {
        const std::string& name = sub->get_name();
        std::vector<size_t> row(name.size() + 1);
        for (size_t j = 0; j <= name.size(); ++j) row[j] = j;
        for (size_t i = 1; i <= word.size(); ++i) {
            size_t diagonal = row[0];
            row[0] = i;
            for (size_t j = 1; j <= name.size(); ++j) {
                const size_t up = row[j];
                row[j] = std::min(
                    {row[j] + 1, row[j - 1] + 1, diagonal + (word[i - 1] == name[j - 1] ? 0 : 1)});
                diagonal = up;
            }
        }
        if (row[name.size()] < bestCost) bestCost = row[name.size()], best = name;
    }
    return best;
}

namespace {

using namespace penumbra;
using namespace penumbra::cli;

// `penumbra bake`: its options, and the run they ask for.
struct BakeCommand {
    CLI::App* cmd = nullptr;
    std::string scenePath, outPath, device = "auto", channel = "indirect";
    std::string bakeColor0 = "tonemapped", backOcclusion = "auto";
    SolverSettings settings;
    IterationOptions iterations;
    EnvironmentOptions bakeEnv;
    GatherOptions bakeGather;
    bool quiet = false;
    float refine = 0.0f;

    void Add(CLI::App& app) {
        cmd = app.add_subcommand("bake",
                                 "Light a glTF scene in-process and write per-vertex "
                                 "irradiance (.json, or .glb/.gltf with _IRRADIANCE)");
        cmd->add_option("scene", scenePath, "glTF 2.0 scene (.gltf or .glb)")->required();
        cmd->add_option("-o,--output", outPath,
                        "output file: .json, .glb or .gltf; - for JSON on standard output")
            ->required();
        AddColor0(cmd, bakeColor0);
        AddRefine(cmd, refine);
        cli::AddSolverOptions(cmd, settings.solver, settings.options);
        iterations.Add(cmd);
        cmd->add_option(
            "--element-size", settings.elementSize,
            "longest element edge after refinement, metres (default: scene diameter/24 behind the "
            "final gather, /40 without)");
        cmd->add_option("--device", device,
                        "auto, gpu, lavapipe or cpu (auto: a real GPU if present, else cpu)")
            ->capture_default_str();
        cmd->add_option("--threads", settings.threads, "CPU threads (0: all cores)")
            ->capture_default_str();
        cmd->add_option(
               "--channel", channel,
               "indirect (all but punctual lights' direct light), direct (punctual lights, "
               "shadowed) or total")
            ->capture_default_str();
        cmd->add_option("--shadow-map-size", settings.shadowMapSize,
                        "texels per side of each shadow map (cube face), 16..8192; 0: from the "
                        "element size (256..2048)")
            ->capture_default_str();
        bakeEnv.Add(cmd);
        cmd->add_option("--back-occlusion", backOcclusion,
                        "auto|on|off: surfaces that do not bound a solid also block light arriving "
                        "at their backs (auto: on with an environment)")
            ->capture_default_str();
        cmd->add_flag("--motion-links", settings.prepareMoves,
                      "prepare dynamic nodes to move in place, as the service does (antiradiance: "
                      "links built for their motion bounds, Sec. 3.3)");
        bakeGather.Add(cmd);
        cmd->add_flag("--validation", settings.validation, "enable Vulkan validation layers");
        cmd->add_flag("-q,--quiet", quiet, "no progress or summary on stderr");
    }
    int Run() {
        settings.backOcclusion = ParseBackOcclusion(backOcclusion);
        return Bake(scenePath, outPath, settings, iterations, device, channel, bakeEnv, bakeGather,
                    ParseDisplayColor(bakeColor0), quiet, refine);
    }
};

// `penumbra reference`.
struct ReferenceCommand {
    CLI::App* cmd = nullptr;
    std::string refScene, refOut, refChannel = "indirect", refColor0 = "tonemapped";
    ReferenceSettings refSettings;
    EnvironmentOptions refEnv;
    bool refQuiet = false;
    float refine = 0.0f;

    void Add(CLI::App& app) {
        cmd = app.add_subcommand(
            "reference",
            "Path-trace per-vertex irradiance with Embree (ground truth for the solvers), with a "
            "standard error per vertex");
        cmd->add_option("scene", refScene, "glTF 2.0 scene (.gltf or .glb)")->required();
        cmd->add_option("-o,--output", refOut,
                        "output file: .json, .glb or .gltf; - for JSON on standard output")
            ->required();
        AddColor0(cmd, refColor0);
        AddRefine(cmd, refine);
        cmd->add_option("--samples", refSettings.samples, "light paths per vertex (>= 2)")
            ->capture_default_str();
        cmd->add_option("--max-depth", refSettings.maxDepth,
                        "bounces after the vertex (Russian roulette ends most paths sooner)")
            ->capture_default_str();
        cmd->add_option("--seed", refSettings.seed, "random seed")->capture_default_str();
        cmd->add_option("--threads", refSettings.threads, "threads (0: all cores)")
            ->capture_default_str();
        cmd->add_option("--channel", refChannel,
                        "indirect (all but punctual lights' direct light), direct or total")
            ->capture_default_str();
        refEnv.Add(cmd);
        cmd->add_flag("-q,--quiet", refQuiet, "no progress or summary on stderr");
    }
    int Run() {
        refSettings.channel = ParseChannel(refChannel);
        return Reference(refScene, refOut, refSettings, refEnv, ParseDisplayColor(refColor0),
                         refQuiet, refine);
    }
};

// `penumbra render`.
struct RenderCommand {
    CLI::App* cmd = nullptr;
    RenderOptions ro;
    SolverSettings renderSettings;
    IterationOptions renderIterations;
    std::string renderSolverDevice = "auto", renderChannel = "total";
    EnvironmentOptions renderEnv;

    void Add(CLI::App& app) {
        cmd = app.add_subcommand(
            "render",
            "Render the lit scene to an image (headless Vulkan raster): OpenEXR (linear, half) "
            "and/or PNG (tone-mapped)");
        cmd->add_option("scene", ro.scene, "glTF 2.0 scene (.gltf or .glb)")->required();
        cmd->add_option("-o,--output", ro.outputs, "image file(s): .exr and/or .png")->required();
        cmd->add_option("--size", ro.size, "WIDTHxHEIGHT")->capture_default_str();
        cmd->add_option("--camera", ro.camera,
                        "ex,ey,ez,tx,ty,tz,fov: eye, target (metres), vertical fov (degrees); "
                        "default: the file's first perspective camera, else one framing the "
                        "scene from -Z");
        cmd->add_option("--camera-name", ro.cameraName, "a perspective camera of the file");
        cmd->add_option("--lighting", ro.lighting,
                        "per-vertex irradiance instead of solving: JSON (bake, reference, get) "
                        "or the .glb/.gltf bake and reference write (its _IRRADIANCE)");
        cmd->add_option("--compare", ro.compare,
                        "reference irradiance JSON: render the relative error as a heat map");
        cmd->add_option("--error-scale", ro.errorScale, "relative error shown as red")
            ->capture_default_str();
        cmd->add_option("--exposure", ro.exposure, "EV added to the automatic exposure (PNG)")
            ->capture_default_str();
        cmd->add_option("--mesh", ro.mesh,
                        "auto|refined|input: shade the solver's refined mesh or the input "
                        "vertices (auto: refined when solving here)")
            ->capture_default_str();
        cmd->add_option("--render-device", ro.renderDevice,
                        "auto (a real GPU if any, else lavapipe) or lavapipe")
            ->capture_default_str();
        cmd->add_option("--channel", renderChannel, "indirect, direct or total")
            ->capture_default_str();
        cli::AddSolverOptions(cmd, renderSettings.solver, renderSettings.options);
        renderIterations.Add(cmd);
        ro.gather.Add(cmd);
        cmd->add_option("--element-size", renderSettings.elementSize,
                        "metres; 0 = scene diameter / 24 behind the final gather, / 40 without");
        cmd->add_option("--device", renderSolverDevice, "solver device: auto, gpu, lavapipe, cpu")
            ->capture_default_str();
        cmd->add_option("--shadow-map-size", renderSettings.shadowMapSize,
                        "texels per shadow map side; 0 = from the element size");
        renderEnv.Add(cmd);
        cmd->add_flag("--validation", renderSettings.validation, "enable Vulkan validation layers");
        cmd->add_flag("-q,--quiet", ro.quiet, "no progress or summary on stderr");
    }
    int Run() {
        return Render(ro, renderSettings, renderIterations, renderSolverDevice, renderChannel,
                      renderEnv);
    }
};

// `penumbra compare`.
struct CompareCommand {
    CLI::App* cmd = nullptr;
    std::string cmpA, cmpB;
    bool cmpJson = false;
    double maxRmse = -1.0, floor = kDefaultFloor;

    void Add(CLI::App& app) {
        cmd = app.add_subcommand(
            "compare",
            "Per-vertex error of irradiance file A against reference B: relative RMSE, mean and "
            "max relative error, per node and overall (exit status 4 when --max-rmse is exceeded)");
        cmd->add_option("a", cmpA, "irradiance JSON to judge")->required();
        cmd->add_option("b", cmpB, "reference irradiance JSON")->required();
        cmd->add_flag("--json", cmpJson, "print the result as JSON");
        cmd->add_option("--max-rmse", maxRmse,
                        "fail (exit 4) when the overall relative RMSE exceeds this (e.g. 0.1)");

        cmd->add_option("--floor", floor,
                        "relative errors are taken against max(|b|, floor × mean |b|)")
            ->capture_default_str();
    }
    int Run() { return CompareFiles(cmpA, cmpB, cmpJson, maxRmse, floor); }
};

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{
        "Penumbra: a headless lighting service (global illumination, per-vertex "
        "irradiance streamed to clients)"};
    app.footer(cli::SolversHelp());
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("penumbra ") + PENUMBRA_VERSION);
    // Options of the whole program (--connect, --session) may follow the subcommand too.
    app.fallthrough();
    cli::ServiceCommands service(app);

    BakeCommand bake;
    ReferenceCommand reference;
    RenderCommand render;
    CompareCommand compare;
    bake.Add(app);
    reference.Add(app);
    render.Add(app);
    compare.Add(app);

    try {
        app.parse(argc, argv);
    } catch (const CLI::ParseError& e) {
        if (e.get_exit_code() == 0) return app.exit(e);  // --help, --version
        // A usage error: exit status 2, one line, and the command meant where it is a typo.
        std::string hint;
        const auto known = [&](const std::string& word) {
            for (const CLI::App* sub : app.get_subcommands({}))
                if (sub->get_name() == word) return true;
            return false;
        };
        if (argc > 1 && argv[1][0] != '-' && !known(argv[1])) {
            const std::string near = Nearest(app, argv[1]);
            hint = "unknown command '" + std::string(argv[1]) + "'" +
                   (near.empty() ? "" : "; did you mean '" + near + "'?");
        }
        std::fprintf(stderr, "penumbra: %s (penumbra --help lists the commands)\n",
                     hint.empty() ? e.what() : hint.c_str());
        return 2;
    }
    if (service.Parsed()) return service.Run();
    try {
        if (bake.cmd->parsed()) return bake.Run();
        if (reference.cmd->parsed()) return reference.Run();
        if (render.cmd->parsed()) return render.Run();
        if (compare.cmd->parsed()) return compare.Run();
    } catch (const penumbra::Error& e) {
        std::fprintf(stderr, "penumbra: error: %s\n", e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "penumbra: internal error: %s\n", e.what());
        return 3;
    }
    return 0;
}
