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

int main(int argc, char** argv) {
    using namespace penumbra;
    using namespace penumbra::cli;
    CLI::App app{
        "Penumbra: a headless lighting service (global illumination, per-vertex "
        "irradiance streamed to clients)"};
    app.footer(cli::SolversHelp());
    app.require_subcommand(1);
    app.set_version_flag("--version", std::string("penumbra ") + PENUMBRA_VERSION);
    // Options of the whole program (--connect, --session) may follow the subcommand too.
    app.fallthrough();
    cli::ServiceCommands service(app);

    auto* bake = app.add_subcommand("bake",
                                    "Light a glTF scene in-process and write per-vertex "
                                    "irradiance (.json, or .glb/.gltf with _IRRADIANCE)");
    std::string scenePath, outPath, device = "auto", channel = "indirect";
    SolverSettings settings;
    IterationOptions iterations;
    bool quiet = false;
    bake->add_option("scene", scenePath, "glTF 2.0 scene (.gltf or .glb)")->required();
    bake->add_option("-o,--output", outPath,
                     "output file: .json, .glb or .gltf; - for JSON on standard output")
        ->required();
    std::string bakeColor0 = "tonemapped";
    AddColor0(bake, bakeColor0);
    cli::AddSolverOptions(bake, settings.solver, settings.options);
    iterations.Add(bake);
    bake->add_option(
        "--element-size", settings.elementSize,
        "longest element edge after refinement, metres (default: scene diameter/24 behind the "
        "final gather, /40 without)");
    bake->add_option("--device", device,
                     "auto, gpu, lavapipe or cpu (auto: a real GPU if present, else cpu)")
        ->capture_default_str();
    bake->add_option("--threads", settings.threads, "CPU threads (0: all cores)")
        ->capture_default_str();
    bake->add_option("--channel", channel,
                     "indirect (all but punctual lights' direct light), direct (punctual lights, "
                     "shadowed) or total")
        ->capture_default_str();
    bake->add_option("--shadow-map-size", settings.shadowMapSize,
                     "texels per side of each shadow map (cube face), 16..8192; 0: from the "
                     "element size (256..2048)")
        ->capture_default_str();
    EnvironmentOptions bakeEnv;
    bakeEnv.Add(bake);
    std::string backOcclusion = "auto";
    bake->add_option("--back-occlusion", backOcclusion,
                     "auto|on|off: surfaces that do not bound a solid also block light arriving "
                     "at their backs (auto: on with an environment)")
        ->capture_default_str();
    bake->add_flag("--motion-links", settings.prepareMoves,
                   "prepare dynamic nodes to move in place, as the service does (antiradiance: "
                   "links built for their motion bounds, Sec. 3.3)");
    GatherOptions bakeGather;
    bakeGather.Add(bake);
    bake->add_flag("--validation", settings.validation, "enable Vulkan validation layers");
    bake->add_flag("-q,--quiet", quiet, "no progress or summary on stderr");

    auto* reference = app.add_subcommand(
        "reference",
        "Path-trace per-vertex irradiance with Embree (ground truth for the solvers), with a "
        "standard error per vertex");
    std::string refScene, refOut, refChannel = "indirect";
    ReferenceSettings refSettings;
    bool refQuiet = false;
    reference->add_option("scene", refScene, "glTF 2.0 scene (.gltf or .glb)")->required();
    reference
        ->add_option("-o,--output", refOut,
                     "output file: .json, .glb or .gltf; - for JSON on standard output")
        ->required();
    std::string refColor0 = "tonemapped";
    AddColor0(reference, refColor0);
    reference->add_option("--samples", refSettings.samples, "light paths per vertex (>= 2)")
        ->capture_default_str();
    reference
        ->add_option("--max-depth", refSettings.maxDepth,
                     "bounces after the vertex (Russian roulette ends most paths sooner)")
        ->capture_default_str();
    reference->add_option("--seed", refSettings.seed, "random seed")->capture_default_str();
    reference->add_option("--threads", refSettings.threads, "threads (0: all cores)")
        ->capture_default_str();
    reference
        ->add_option("--channel", refChannel,
                     "indirect (all but punctual lights' direct light), direct or total")
        ->capture_default_str();
    EnvironmentOptions refEnv;
    refEnv.Add(reference);
    reference->add_flag("-q,--quiet", refQuiet, "no progress or summary on stderr");

    auto* render = app.add_subcommand(
        "render",
        "Render the lit scene to an image (headless Vulkan raster): OpenEXR (linear, half) "
        "and/or PNG (tone-mapped)");
    RenderOptions ro;
    SolverSettings renderSettings;
    IterationOptions renderIterations;
    std::string renderSolverDevice = "auto", renderChannel = "total";
    render->add_option("scene", ro.scene, "glTF 2.0 scene (.gltf or .glb)")->required();
    render->add_option("-o,--output", ro.outputs, "image file(s): .exr and/or .png")->required();
    render->add_option("--size", ro.size, "WIDTHxHEIGHT")->capture_default_str();
    render->add_option("--camera", ro.camera,
                       "ex,ey,ez,tx,ty,tz,fov: eye, target (metres), vertical fov (degrees); "
                       "default: the file's first perspective camera, else one framing the "
                       "scene from -Z");
    render->add_option("--camera-name", ro.cameraName, "a perspective camera of the file");
    render->add_option("--lighting", ro.lighting,
                       "per-vertex irradiance JSON (bake, reference, get) instead of solving");
    render->add_option("--compare", ro.compare,
                       "reference irradiance JSON: render the relative error as a heat map");
    render->add_option("--error-scale", ro.errorScale, "relative error shown as red")
        ->capture_default_str();
    render->add_option("--exposure", ro.exposure, "EV added to the automatic exposure (PNG)")
        ->capture_default_str();
    render
        ->add_option("--mesh", ro.mesh,
                     "auto|refined|input: shade the solver's refined mesh or the input "
                     "vertices (auto: refined when solving here)")
        ->capture_default_str();
    render
        ->add_option("--render-device", ro.renderDevice,
                     "auto (a real GPU if any, else lavapipe) or lavapipe")
        ->capture_default_str();
    render->add_option("--channel", renderChannel, "indirect, direct or total")
        ->capture_default_str();
    cli::AddSolverOptions(render, renderSettings.solver, renderSettings.options);
    renderIterations.Add(render);
    ro.gather.Add(render);
    render->add_option("--element-size", renderSettings.elementSize,
                       "metres; 0 = scene diameter / 24 behind the final gather, / 40 without");
    render->add_option("--device", renderSolverDevice, "solver device: auto, gpu, lavapipe, cpu")
        ->capture_default_str();
    render->add_option("--shadow-map-size", renderSettings.shadowMapSize,
                       "texels per shadow map side; 0 = from the element size");
    EnvironmentOptions renderEnv;
    renderEnv.Add(render);
    render->add_flag("--validation", renderSettings.validation, "enable Vulkan validation layers");
    render->add_flag("-q,--quiet", ro.quiet, "no progress or summary on stderr");

    auto* compare = app.add_subcommand(
        "compare",
        "Per-vertex error of irradiance file A against reference B: relative RMSE, mean and "
        "max relative error, per node and overall (exit status 4 when --max-rmse is exceeded)");
    std::string cmpA, cmpB;
    bool cmpJson = false;
    double maxRmse = -1.0, floor = kDefaultFloor;
    compare->add_option("a", cmpA, "irradiance JSON to judge")->required();
    compare->add_option("b", cmpB, "reference irradiance JSON")->required();
    compare->add_flag("--json", cmpJson, "print the result as JSON");
    compare->add_option("--max-rmse", maxRmse,
                        "fail (exit 4) when the overall relative RMSE exceeds this (e.g. 0.1)");

    compare
        ->add_option("--floor", floor,
                     "relative errors are taken against max(|b|, floor × mean |b|)")
        ->capture_default_str();

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
        if (bake->parsed()) {
            settings.backOcclusion = ParseBackOcclusion(backOcclusion);
            return Bake(scenePath, outPath, settings, iterations, device, channel, bakeEnv,
                        bakeGather, ParseDisplayColor(bakeColor0), quiet);
        }
        if (reference->parsed()) {
            refSettings.channel = ParseChannel(refChannel);
            return Reference(refScene, refOut, refSettings, refEnv, ParseDisplayColor(refColor0),
                             refQuiet);
        }
        if (render->parsed())
            return Render(ro, renderSettings, renderIterations, renderSolverDevice, renderChannel,
                          renderEnv);
        if (compare->parsed()) return CompareFiles(cmpA, cmpB, cmpJson, maxRmse, floor);
    } catch (const penumbra::Error& e) {
        std::fprintf(stderr, "penumbra: error: %s\n", e.what());
        return 1;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "penumbra: internal error: %s\n", e.what());
        return 3;
    }
    return 0;
}
