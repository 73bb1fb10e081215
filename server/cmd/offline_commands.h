// The in-process commands of the `penumbra` CLI (bake, reference, render, compare): their
// shared option groups and one function per command (offline_commands.cpp). main() in
// penumbra.cpp parses into these and calls the command that was given.
#pragma once

#include <CLI/CLI.hpp>
#include <memory>
#include <string>
#include <vector>

#include "base/progress.h"
#include "gather/gather_stage.h"
#include "output/irradiance_writer.h"
#include "reference/path_tracer.h"
#include "scene/environment.h"
#include "scene/sun_sky.h"
#include "solver/solver.h"

namespace penumbra::cli {

// `--environment FILE.exr | --environment-color R,G,B | --sky clear`, `--environment-intensity`,
// `--environment-rotation` (degrees about +Y), `--sun AZIMUTH,ELEVATION,LUX`, `--turbidity`,
// shared by bake, reference and render (scene/sun_sky.h).
struct EnvironmentOptions {
    std::string file;
    std::vector<float> color;
    float intensity = 1.0f;
    float rotationDegrees = 0.0f;
    std::vector<float> sun;  // azimuth, elevation (degrees), illuminance (lux)
    std::string sky;         // "clear": Preetham's sky for the sun
    float turbidity = kDefaultTurbidity;

    void Add(CLI::App* app) {
        auto* f = app->add_option("--environment", file,
                                  "equirectangular OpenEXR sky (radiance in nits; the image's "
                                  "centre looks down -Z, its top is +Y)");
        auto* c = app->add_option("--environment-color", color,
                                  "a constant sky instead: r,g,b radiance in nits")
                      ->delimiter(',')
                      ->expected(3);
        f->excludes(c);
        auto* s = app->add_option("--sun", sun,
                                  "a sun (a directional light on a node 'sun'): azimuth "
                                  "(degrees from north, -Z, towards east, +X), elevation "
                                  "(degrees above the horizon), illuminance (lux on a surface "
                                  "facing it), e.g. 135,30,80000")
                      ->delimiter(',')
                      ->expected(3);
        auto* k = app->add_option("--sky", sky,
                                  "clear: Preetham's analytic clear sky for the --sun position "
                                  "(instead of --environment or --environment-color)")
                      ->check(CLI::IsMember({"clear"}));
        k->excludes(f)->excludes(c)->needs(s);
        app->add_option("--turbidity", turbidity,
                        "the clear sky's turbidity, 1.7 (very clear) … 10 (hazy)")
            ->capture_default_str()
            ->needs(k);
        app->add_option("--environment-intensity", intensity, "scales the sky")
            ->capture_default_str();
        app->add_option("--environment-rotation", rotationDegrees,
                        "turns the sky about +Y, degrees (counter-clockwise from above)")
            ->capture_default_str();
    }

    void Apply(Scene& scene) const {
        SunPosition position;
        if (!sun.empty()) {
            position = {sun[0], sun[1]};
            AddSun(scene, position, sun[2]);
        }
        if (file.empty() && color.empty() && sky.empty()) return;
        if (!sky.empty() && rotationDegrees != 0.0f)
            throw Error("--environment-rotation does not turn a clear sky: turn the --sun");
        scene.environment = !sky.empty()   ? ClearSky(position, turbidity)
                            : file.empty() ? ConstantEnvironment({color[0], color[1], color[2]})
                                           : LoadEnvironment(file);
        scene.environment.intensity = intensity;
        scene.environment.rotation = glm::radians(rotationDegrees);
        ValidateEnvironment(scene.environment);
    }
};

// The gather stage's options (gather/gather_stage.h), the same for bake and render.
struct GatherOptions {
    std::string gather = "on";
    int gatherRays = 256;
    int directRays = 256;

    void Add(CLI::App* app) {
        app->add_option("--gather", gather,
                        "on|off: the final gather at each output vertex (rays against the "
                        "solver's answer); off: the solver's own irradiance, faster and "
                        "coarser")
            ->capture_default_str();
        app->add_option("--gather-rays", gatherRays, "final gather rays per output vertex")
            ->capture_default_str();
        app->add_option("--direct-rays,--emitter-direct", directRays,
                        "shadow rays per surfel for the emitters' direct light, handed to the "
                        "solver as its first shot; 0: the solver carries the emission")
            ->capture_default_str();
    }

    GatherSettings Settings() const {
        if (gather != "on" && gather != "off")
            throw Error("--gather must be on or off, not '" + gather + "'");
        GatherSettings s;
        s.gatherRays = gather == "on" ? gatherRays : 0;
        s.emitterRays = directRays;
        CheckGatherRays(gatherRays, "--gather-rays");
        CheckGatherRays(directRays, "--direct-rays");
        return s;
    }

    // `solver` behind the gather stage; each part declined is a note on stderr.
    // The solver `settings` names behind the gather stage (CreateGatheredSolver); each part
    // declined is a note on stderr.
    std::unique_ptr<Solver> Create(const Scene& scene, const SolverSettings& settings,
                                   const std::string& scenePath, const GatherSettings& s,
                                   bool quiet, Progress& progress) const {
        std::vector<std::string> notes;
        std::unique_ptr<Solver> solver = CreateGatheredSolver(
            scene, settings, s,
            [&](const std::string& stage, double f) { progress.Update(stage, f); }, &notes);
        if (!quiet && !notes.empty()) progress.Done();
        for (const std::string& n : notes)
            if (!quiet)
                std::fprintf(stderr, "penumbra: note: %s: %s\n", scenePath.c_str(), n.c_str());
        return solver;
    }
};

// Exit status of `bake` when the solution diverged (SolverStats::divergence).
constexpr int kDiverged = 6;

// How many iterations `bake` and `render` run: --iterations N, or (0) until an iteration
// changes the answer by less than --tolerance, at most --max-iterations.
struct IterationOptions {
    int iterations = 0;
    double tolerance = 1e-3;
    int maxIterations = 500;

    void Add(CLI::App* command) {
        command
            ->add_option("--iterations", iterations,
                         "solver iterations (bounces of light); 0: until two iterations in a "
                         "row change the answer by less than --tolerance each")
            ->capture_default_str();
        command
            ->add_option("--tolerance", tolerance,
                         "with --iterations 0: the relative change (sum |dE| / sum |E|) of one "
                         "iteration at which the answer counts as converged")
            ->capture_default_str();
        command
            ->add_option("--max-iterations", maxIterations,
                         "with --iterations 0: give up converging after this many")
            ->capture_default_str();
    }
    void Check() const {
        if (iterations < 0 || iterations > 100000)
            throw Error("--iterations must be between 0 and 100000");
        if (!(tolerance > 0.0 && tolerance < 1.0))
            throw Error("--tolerance must be between 0 and 1 (exclusive)");
        if (maxIterations < 1 || maxIterations > 100000)
            throw Error("--max-iterations must be between 1 and 100000");
    }
    // Runs the solver; says on stderr (unless quiet) when it did not converge.
    void Run(Solver& solver, const std::string& scenePath, Progress& progress, bool quiet) const {
        auto report = [&](const std::string& stage, double f) { progress.Update(stage, f); };
        if (iterations > 0) {
            solver.Iterate(iterations);
            return;
        }
        Convergence c = IterateUntilConverged(solver, tolerance, maxIterations, report);
        if (!c.converged && solver.Stats().divergence.empty() && !quiet) {
            progress.Done();
            std::fprintf(stderr,
                         "penumbra: warning: %s: not converged after %d iterations (the last "
                         "changed the answer by %.2g, --tolerance %.2g); writing it anyway\n",
                         scenePath.c_str(), c.iterations, c.change, tolerance);
        }
    }
};

struct RenderOptions {
    std::string scene;
    std::vector<std::string> outputs;
    std::string size = "800x600";
    std::string camera, cameraName, lighting, compare, mesh = "auto", renderDevice = "auto";
    float errorScale = 0.5f, exposure = 0.0f;
    GatherOptions gather;
    bool quiet = false;
};

// Exit status when `compare --max-rmse` is exceeded.
constexpr int kGateFailed = 4;

// `--color0` of bake and reference: what glTF out puts in COLOR_0 beside _IRRADIANCE.
void AddColor0(CLI::App* app, std::string& color0);
// `--refine EDGE` of bake and reference (RefineForOutput: 0, the file's vertices).
void AddRefine(CLI::App* app, float& edge);
// Refuses an output path other than .json, .glb, .gltf or - (JSON on standard output).
void CheckOutputPath(const std::string& outPath);

int Bake(const std::string& scenePath, const std::string& outPath, SolverSettings settings,
         const IterationOptions& iterations, const std::string& device,
         const std::string& channelName, const EnvironmentOptions& environment,
         const GatherOptions& gather, DisplayColor color, bool quiet, float refine = 0.0f);
int Reference(const std::string& scenePath, const std::string& outPath, ReferenceSettings settings,
              const EnvironmentOptions& environment, DisplayColor color, bool quiet,
              float refine = 0.0f);
int Render(const RenderOptions& o, SolverSettings settings, const IterationOptions& iterations,
           const std::string& device, const std::string& channelName,
           const EnvironmentOptions& environment);
int CompareFiles(const std::string& aPath, const std::string& bPath, bool json, double maxRmse,
                 double floor);

}  // namespace penumbra::cli
