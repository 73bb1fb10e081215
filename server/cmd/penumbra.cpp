// The `penumbra` command line. `bake`, `reference` and `compare` run in-process; the service
// commands (load, watch, move, light, ...) talk to penumbra-server (cmd/service_cli.h).
#include <CLI/CLI.hpp>
#include <cstdio>
#include <iostream>

#include "base/check.h"
#include "base/progress.h"
#include "cmd/service_cli.h"
#include "cmd/solver_options.h"
#include "gather/gather_stage.h"
#include "output/compare.h"
#include "output/irradiance_writer.h"
#include "reference/path_tracer.h"
#include "render/renderer.h"
#include "scene/gltf_loader.h"
#include "solver/registry.h"

namespace {

using namespace penumbra;

bool EndsWith(const std::string& s, const std::string& suffix) {
    return s.size() >= suffix.size() &&
           s.compare(s.size() - suffix.size(), suffix.size(), suffix) == 0;
}

void WriteResult(const std::string& scenePath, const std::string& outPath, const Scene& scene,
                 const IrradianceResult& result, DisplayColor color) {
    if (outPath == "-" || EndsWith(outPath, ".json"))
        WriteIrradianceJson(outPath, scene, result);
    else
        WriteIrradianceGltf(scenePath, outPath, scene, result, color);
}

// `--color0` of bake and reference: what glTF out puts in COLOR_0 beside _IRRADIANCE.
void AddColor0(CLI::App* app, std::string& color0) {
    app->add_option("--color0", color0,
                    "glTF out: COLOR_0 for viewers, none or tonemapped (the irradiance scaled so "
                    "the 99th percentile is 1, clamped to [0, 1]); the values themselves are in "
                    "_IRRADIANCE")
        ->capture_default_str();
}

// `--environment FILE.exr | --environment-color R,G,B`, `--environment-intensity`,
// `--environment-rotation` (degrees about +Y), shared by bake and reference.
struct EnvironmentOptions {
    std::string file;
    std::vector<float> color;
    float intensity = 1.0f;
    float rotationDegrees = 0.0f;

    void Add(CLI::App* app) {
        auto* f = app->add_option("--environment", file,
                                  "equirectangular OpenEXR sky (radiance in nits; the image's "
                                  "centre looks down -Z, its top is +Y)");
        auto* c = app->add_option("--environment-color", color,
                                  "a constant sky instead: r,g,b radiance in nits")
                      ->delimiter(',')
                      ->expected(3);
        f->excludes(c);
        app->add_option("--environment-intensity", intensity, "scales the sky")
            ->capture_default_str();
        app->add_option("--environment-rotation", rotationDegrees,
                        "turns the sky about +Y, degrees (counter-clockwise from above)")
            ->capture_default_str();
    }

    void Apply(Scene& scene) const {
        if (file.empty() && color.empty()) return;
        scene.environment = file.empty() ? ConstantEnvironment({color[0], color[1], color[2]})
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

void CheckOutputPath(const std::string& outPath) {
    if (outPath != "-" && !EndsWith(outPath, ".json") && !EndsWith(outPath, ".glb") &&
        !EndsWith(outPath, ".gltf"))
        throw Error("output '" + outPath +
                    "' must end in .json, .glb or .gltf (or be -: JSON on standard output)");
}

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

int Bake(const std::string& scenePath, const std::string& outPath, SolverSettings settings,
         const IterationOptions& iterations, const std::string& device,
         const std::string& channelName, const EnvironmentOptions& environment,
         const GatherOptions& gather, DisplayColor color, bool quiet) {
    Channel channel = ParseChannel(channelName);
    CheckOutputPath(outPath);
    const GatherSettings gatherSettings = gather.Settings();
    settings.device = ParseDevice(device);
    CheckSolverSettings(settings);  // before the (long) load: a bad option fails fast
    iterations.Check();

    Progress progress(!quiet && StderrIsTerminal());
    progress.Update("loading " + scenePath, 0.0);
    Scene scene = LoadGltf(scenePath);
    environment.Apply(scene);
    // Nothing lights the scene: the answer is zero everywhere; say so rather than write
    // zeros in silence (even with -q: it is a warning, not progress).
    const bool emits = std::any_of(
        scene.materials.begin(), scene.materials.end(),
        [](const auto& m) { return glm::any(glm::greaterThan(m.emission, glm::vec3(0.0f))); });
    if (!emits && scene.lights.empty() && !scene.environment.Active())
        std::fprintf(stderr,
                     "penumbra: warning: %s has no light (no emissive material, punctual light "
                     "or sky): its irradiance is zero everywhere\n",
                     scenePath.c_str());
    std::unique_ptr<Solver> solver =
        gather.Create(scene, settings, scenePath, gatherSettings, quiet, progress);
    iterations.Run(*solver, scenePath, progress, quiet);
    progress.Done();
    // A diverged solution is not written: no file is better than a wrong one.
    if (std::string why = solver->Stats().divergence; !why.empty()) {
        std::fprintf(stderr, "penumbra: error: %s: the solution %s; nothing written\n",
                     scenePath.c_str(), why.c_str());
        return kDiverged;
    }

    IrradianceResult result = CollectIrradiance(scene, *solver, channel);
    WriteResult(scenePath, outPath, scene, result, color);

    if (!quiet) {
        const SolverStats& s = solver->Stats();
        std::fprintf(stderr,
                     "%s: %zu triangles -> %zu elements, %zu links, %d bins, element size %.4g m\n"
                     "  device %s; links built in %.3f s; %d iterations (%d passes) "
                     "at %.2f ms a pass",
                     scenePath.c_str(), scene.TriangleCount(), s.elements, s.links, s.bins,
                     s.elementSize, s.device.c_str(), s.linkBuildSeconds, s.iterations, s.gathers,
                     s.gathers ? s.msTotal / s.gathers : 0.0);
        for (const auto& p : s.passes)
            std::fprintf(stderr, " | %s %.2f", p.name.c_str(),
                         s.gathers ? p.msTotal / s.gathers : 0.0);
        if (s.lights)
            std::fprintf(stderr,
                         "\n  %d punctual lights: %d shadow maps of %d² in %.2f ms, direct light "
                         "%.2f ms",
                         s.lights, s.shadowViews, s.shadowMapSize, s.msShadow, s.msDirect);
        if (!s.environment.empty())
            std::fprintf(stderr,
                         "\n  environment %s × %.3g, turned %.1f°; %zu of %zu elements occlude "
                         "from both sides",
                         s.environment.c_str(), s.environmentIntensity,
                         glm::degrees(s.environmentRotation), s.twoSidedElements, s.elements);
        if (s.glossyElements)
            std::fprintf(stderr, "\n  %zu of %zu elements glossy (%zu lobes)", s.glossyElements,
                         s.elements, size_t(s.Number("glossy_lobes")));
        if (s.emitterRays)
            std::fprintf(stderr, "\n  first shot: %d rays a surfel in %.0f ms", s.emitterRays,
                         s.msEmitterDirect);
        if (s.gatherRays)
            std::fprintf(stderr,
                         "\n  final gather: %d rays at %zu vertices, traced in %.0f ms, "
                         "evaluated in %.1f ms (%s)",
                         s.gatherRays, s.gatherTargets, s.msGatherTrace, s.msGatherEvaluate,
                         s.gatherDevice.c_str());
        std::fprintf(stderr, "\n  wrote %s (channel %s; %s)\n",
                     outPath == "-" ? "standard output" : outPath.c_str(), result.channel.c_str(),
                     kIrradianceUnits);
    }
    return 0;
}

std::string Duration(double seconds) {
    char buf[32];
    int s = static_cast<int>(seconds + 0.5);
    if (s >= 3600)
        std::snprintf(buf, sizeof buf, "%dh%02dm", s / 3600, s / 60 % 60);
    else if (s >= 60)
        std::snprintf(buf, sizeof buf, "%dm%02ds", s / 60, s % 60);
    else
        std::snprintf(buf, sizeof buf, "%ds", s);
    return buf;
}

int Reference(const std::string& scenePath, const std::string& outPath, ReferenceSettings settings,
              const EnvironmentOptions& environment, DisplayColor color, bool quiet) {
    CheckOutputPath(outPath);
    Progress progress(!quiet && StderrIsTerminal());
    progress.Update("loading " + scenePath, 0.0);
    Scene scene = LoadGltf(scenePath);
    environment.Apply(scene);
    settings.progress = [&](double f, double left) {
        progress.Update("path tracing, " + Duration(left) + " left", f);
    };
    ReferenceResult ref = RenderReference(scene, settings);
    progress.Done();

    const ReferenceStats& st = ref.stats;
    IrradianceResult result;
    result.solver = "reference";
    result.channel = ChannelName(settings.channel);
    result.primitives = std::move(ref.irradiance);
    result.standardError = std::move(ref.standardError);
    // Relative standard error of the whole estimate: √Σσ² / √Σ|E|², like compare's RMSE.
    double var = 0, sum2 = 0, worst = 0;
    for (size_t p = 0; p < result.primitives.size(); ++p)
        for (size_t i = 0; i < result.primitives[p].size(); ++i) {
            glm::dvec3 e(result.primitives[p][i]), s(result.standardError[p][i]);
            var += glm::dot(s, s);
            sum2 += glm::dot(e, e);
            double len = glm::length(e);
            if (len > 0) worst = std::max(worst, glm::length(s) / len);
        }
    double relStderr = sum2 > 0 ? std::sqrt(var / sum2) : 0.0;
    result.stats = {{"solver", "reference"},   {"device", "cpu (Embree)"},
                    {"samples", st.samples},   {"max_depth", st.maxDepth},
                    {"seed", st.seed},         {"threads", st.threads},
                    {"vertices", st.vertices}, {"rays", st.rays},
                    {"seconds", st.seconds},   {"rays_per_second", st.RaysPerSecond()},
                    {"rel_stderr", relStderr}, {"max_vertex_rel_stderr", worst}};
    WriteResult(scenePath, outPath, scene, result, color);
    if (!quiet)
        std::fprintf(stderr,
                     "%s: %zu vertices x %d samples in %.2f s (%.3g rays/s, %d threads)\n"
                     "  relative standard error %.3g%% overall, %.3g%% at the worst vertex\n"
                     "  wrote %s (channel %s; %s)\n",
                     scenePath.c_str(), st.vertices, st.samples, st.seconds, st.RaysPerSecond(),
                     st.threads, 100 * relStderr, 100 * worst,
                     outPath == "-" ? "standard output" : outPath.c_str(), result.channel.c_str(),
                     kIrradianceUnits);
    return 0;
}

struct RenderOptions {
    std::string scene;
    std::vector<std::string> outputs;
    std::string size = "800x600";
    std::string camera, cameraName, lighting, compare, mesh = "auto", renderDevice = "auto";
    float errorScale = 0.5f, exposure = 0.0f;
    GatherOptions gather;
    bool quiet = false;
};

int Render(const RenderOptions& o, SolverSettings settings, const IterationOptions& iterations,
           const std::string& device, const std::string& channelName,
           const EnvironmentOptions& environment) {
    // Everything the command line says is checked before any work.
    int w = 0, h = 0;
    char x = 0, rest = 0;
    if (std::sscanf(o.size.c_str(), "%d%c%d%c", &w, &x, &h, &rest) != 3 || x != 'x')
        throw Error("--size must be WIDTHxHEIGHT, e.g. 800x600");
    for (const std::string& out : o.outputs)
        if (!EndsWith(out, ".exr") && !EndsWith(out, ".png"))
            throw Error("output '" + out + "' must end in .exr or .png");
    if (o.mesh != "auto" && o.mesh != "refined" && o.mesh != "input")
        throw Error("--mesh must be auto, refined or input");
    if (o.renderDevice != "auto" && o.renderDevice != "lavapipe")
        throw Error("--render-device must be auto or lavapipe");
    const bool fromFile = !o.lighting.empty();
    if (fromFile && o.mesh == "refined")
        throw Error("--mesh refined needs the solver's own result (drop --lighting)");
    Channel channel = ParseChannel(channelName);
    settings.device = ParseDevice(device);
    CheckSolverSettings(settings);  // before the (long) load: a bad option fails fast
    iterations.Check();
    GatherSettings gatherSettings = o.gather.Settings();
    // Shading the refined mesh reads every surfel.
    gatherSettings.allSurfels = !fromFile && o.mesh != "input";

    Progress progress(!o.quiet && StderrIsTerminal());
    progress.Update("loading " + o.scene, 0.0);
    Scene scene = LoadGltf(o.scene);
    environment.Apply(scene);
    render::RenderSettings rs;
    rs.width = w;
    rs.height = h;
    rs.lavapipe = o.renderDevice == "lavapipe";
    rs.validation = settings.validation;

    // The camera: --camera, a named glTF camera, the file's first, or one framing the scene.
    Camera camera;
    if (!o.camera.empty()) {
        camera = render::ParseCamera(o.camera);
    } else if (!o.cameraName.empty()) {
        auto it = std::find_if(scene.cameras.begin(), scene.cameras.end(),
                               [&](const Camera& c) { return c.name == o.cameraName; });
        if (it == scene.cameras.end())
            throw Error(o.scene + " has no perspective camera called '" + o.cameraName + "'");
        camera = *it;
    } else {
        camera = scene.cameras.empty() ? render::FrameScene(scene) : scene.cameras.front();
    }

    // The lighting: a file, or the solver run here.
    std::vector<std::vector<glm::vec3>> perVertex;
    std::vector<glm::vec3> perSurfel;  // when solved here
    std::unique_ptr<Solver> solver;
    std::string source;
    if (fromFile) {
        perVertex = render::IrradianceForScene(scene, ReadIrradianceJson(o.lighting));
        source = o.lighting;
    } else {
        solver = o.gather.Create(scene, settings, o.scene, gatherSettings, o.quiet, progress);
        iterations.Run(*solver, o.scene, progress, o.quiet);
        perSurfel = solver->SurfelIrradiance(channel);
        for (size_t p = 0; p < scene.primitives.size(); ++p)
            perVertex.push_back(PrimitiveIrradiance(solver->GetSurfels(), perSurfel, scene, p));
        source = solver->Stats().solver + " on " + solver->Stats().device + ", " +
                 std::to_string(solver->Stats().iterations) + " iterations, channel " +
                 ChannelName(channel);
    }
    render::Mesh mesh;
    bool heat = !o.compare.empty();
    if (heat) {
        auto other = render::IrradianceForScene(scene, ReadIrradianceJson(o.compare));
        mesh = render::ErrorMesh(scene, perVertex, other, o.errorScale, kDefaultFloor);
    } else if (solver && o.mesh != "input") {
        mesh = render::ShadedRefinedMesh(scene, solver->GetSurfels(), perSurfel);
    } else {
        mesh = render::ShadedInputMesh(scene, perVertex);
    }
    progress.Update("rendering", 0.0);
    render::RenderOutput out = render::Rasterize(mesh, camera, rs);
    progress.Done();
    for (const auto& m : out.validationMessages)
        std::fprintf(stderr, "penumbra render: validation: %s\n", m.c_str());
    for (const std::string& path : o.outputs) {
        if (EndsWith(path, ".exr"))
            WriteExr(path, out.image);
        else  // a heat map keeps its colours; radiance is exposed
            WritePng(path, w, h, render::ToneMap(out.image, heat ? 0.0f : o.exposure, !heat));
    }
    if (!o.quiet) {
        std::fprintf(stderr,
                     "%s: %d×%d from camera '%s', %zu triangles, rendered on %s in %.1f ms\n",
                     o.scene.c_str(), w, h, camera.name.c_str(), mesh.indices.size() / 3,
                     out.device.c_str(), out.ms);
        if (heat)
            std::fprintf(stderr,
                         "  heat map: relative error of %s against %s, blue 0 → red ≥ %.0f%%\n",
                         source.c_str(), o.compare.c_str(), 100.0 * o.errorScale);
        else
            std::fprintf(stderr, "  lighting: %s; pixels are radiance ρE/π + Lₑ (nits)\n",
                         source.c_str());
        for (const std::string& path : o.outputs)
            std::fprintf(stderr, "  wrote %s\n", path.c_str());
    }
    return out.validationMessages.empty() ? 0 : 3;
}

// Exit status when `compare --max-rmse` is exceeded.
constexpr int kGateFailed = 4;

int CompareFiles(const std::string& aPath, const std::string& bPath, bool json, double maxRmse,
                 double floor) {
    if (!(floor > 0.0 && floor <= 1.0)) throw Error("--floor must be in (0, 1]");
    IrradianceFile a = ReadIrradianceJson(aPath), b = ReadIrradianceJson(bPath);
    if (a.channel != b.channel)
        throw Error("channels differ: " + aPath + " holds '" + a.channel + "', " + bPath +
                    " holds '" + b.channel + "'");
    Comparison c = Compare(a, b, floor);
    if (json) {
        std::printf("%s\n", ComparisonToJson(c, b).dump(1).c_str());
    } else {
        std::printf("%s (%s) against %s (%s), channel %s\n", aPath.c_str(), a.solver.c_str(),
                    bPath.c_str(), b.solver.c_str(), b.channel.c_str());
        std::printf("%-24s %9s %10s %10s %10s\n", "node", "vertices", "rel_rmse", "mean_rel",
                    "max_rel");
        auto row = [](const std::string& name, const ErrorSummary& s) {
            std::printf("%-24s %9zu %9.3f%% %9.3f%% %9.3f%%\n", name.c_str(), s.vertices,
                        100 * s.relRmse, 100 * s.meanRel, 100 * s.maxRel);
        };
        for (const auto& [name, s] : c.nodes) row(name, s);
        row("(all)", c.overall);
    }
    if (maxRmse >= 0 && !(c.overall.relRmse <= maxRmse)) {
        std::fprintf(stderr, "penumbra compare: relative RMSE %.4g exceeds --max-rmse %.4g\n",
                     c.overall.relRmse, maxRmse);
        return kGateFailed;
    }
    return 0;
}

}  // namespace

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
    bake->add_option("--element-size", settings.elementSize,
                     "longest element edge after refinement, metres (default: scene diameter/40)");
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
    bake->add_flag("--motion-links", settings.motionLinks,
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
                       "metres; 0 = scene diameter / 40");
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
