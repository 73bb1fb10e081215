// The in-process commands: bake, reference, render, compare (docs/CLI.md).
#include "cmd/offline_commands.h"

#include <cmath>
#include <cstdio>

#include "base/check.h"
#include "output/compare.h"
#include "render/renderer.h"
#include "scene/gltf_loader.h"
#include "scene/refine_output.h"
#include "solvers/registry.h"

namespace penumbra::cli {

namespace {

// What the scene's answer leaves out (SceneWarnings), on stderr even with -q: a warning is
// not progress. The JSON output carries the same list. `lightFromScene` false: the light is
// read from a file (render --lighting), so a scene without lights is no concern.
void Warn(const Scene& scene, const std::string& path, bool lightFromScene = true) {
    for (const std::string& w : SceneWarnings(scene, lightFromScene))
        std::fprintf(stderr, "penumbra: warning: %s: %s\n", path.c_str(), w.c_str());
}

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

// What WriteResult wrote: a .glb or .gltf's _IRRADIANCE, else the JSON.
IrradianceFile ReadResult(const std::string& path) {
    return EndsWith(path, ".glb") || EndsWith(path, ".gltf") ? ReadIrradianceGltf(path)
                                                             : ReadIrradianceJson(path);
}

// The solver `settings` names behind the gather, run for `iterations`. Where its solution
// diverged, the fallback solver (FallbackSettings) is built and run instead, with a warning
// on stderr (even with -q: the answer is another method's), and `fellBack` says why.
std::unique_ptr<Solver> Solve(const Scene& scene, const SolverSettings& settings,
                              const std::string& scenePath, const GatherOptions& gather,
                              const GatherSettings& gatherSettings,
                              const IterationOptions& iterations, bool quiet, Progress& progress,
                              std::string& fellBack) {
    std::unique_ptr<Solver> solver =
        gather.Create(scene, settings, scenePath, gatherSettings, quiet, progress);
    iterations.Run(*solver, scenePath, progress, quiet);
    SolverSettings fallback;
    const std::string why = solver->Stats().divergence;
    if (why.empty() || !FallbackSettings(settings, fallback)) return solver;
    progress.Done();
    fellBack = "the " + settings.solver + " solution " + why;
    std::fprintf(stderr, "penumbra: warning: %s: %s; going on with the %s solver\n",
                 scenePath.c_str(), fellBack.c_str(), fallback.solver.c_str());
    solver.reset();  // its links and tables go before the next solver's are built
    solver = gather.Create(scene, fallback, scenePath, gatherSettings, quiet, progress);
    iterations.Run(*solver, scenePath, progress, quiet);
    return solver;
}

}  // namespace

void AddColor0(CLI::App* app, std::string& color0) {
    app->add_option("--color0", color0,
                    "glTF out: COLOR_0 for viewers, none or tonemapped (the irradiance scaled so "
                    "the 99th percentile is 1, clamped to [0, 1]); the values themselves are in "
                    "_IRRADIANCE")
        ->capture_default_str();
}

void AddRefine(CLI::App* app, float& edge) {
    app->add_option("--refine", edge,
                    "refined output for coarse meshes: triangles subdivided until no edge is "
                    "longer than this many metres before lighting, and the output (glTF, JSON) "
                    "carries the refined meshes with a value at each of their vertices; 0: the "
                    "file's vertices")
        ->capture_default_str()
        ->check(CLI::Range(0.0f, 1e30f));
}

void CheckOutputPath(const std::string& outPath) {
    if (outPath != "-" && !EndsWith(outPath, ".json") && !EndsWith(outPath, ".glb") &&
        !EndsWith(outPath, ".gltf"))
        throw Error("output '" + outPath +
                    "' must end in .json, .glb or .gltf (or be -: JSON on standard output)");
}

int Bake(const std::string& scenePath, const std::string& outPath, SolverSettings settings,
         const IterationOptions& iterations, const std::string& device,
         const std::string& channelName, const EnvironmentOptions& environment,
         const GatherOptions& gather, DisplayColor color, bool quiet, float refine) {
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
    if (refine > 0.0f) RefineForOutput(scene, refine);
    Warn(scene, scenePath);
    std::string fellBack;
    std::unique_ptr<Solver> solver = Solve(scene, settings, scenePath, gather, gatherSettings,
                                           iterations, quiet, progress, fellBack);
    progress.Done();
    // A diverged solution is not written: no file is better than a wrong one.
    if (std::string why = solver->Stats().divergence; !why.empty()) {
        std::fprintf(stderr, "penumbra: error: %s: the %s solution %s; nothing written\n",
                     scenePath.c_str(), solver->Stats().solver.c_str(), why.c_str());
        return kDiverged;
    }

    IrradianceResult result = CollectIrradiance(scene, *solver, channel);
    if (!fellBack.empty())
        result.stats["fallback"] = {{"from", settings.solver}, {"why", fellBack}};
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
        if (s.lights && s.lighting.shadowViews)
            std::fprintf(stderr,
                         "\n  %d punctual lights: %d shadow maps of %d² in %.2f ms, direct light "
                         "%.2f ms",
                         s.lights, s.lighting.shadowViews, s.lighting.shadowMapSize,
                         s.lighting.msShadow, s.lighting.msDirect);
        else if (s.lights)
            std::fprintf(stderr,
                         "\n  %d punctual lights: shadow rays (their BVH in %.2f ms), direct "
                         "light %.2f ms",
                         s.lights, s.lighting.msShadow, s.lighting.msDirect);
        if (!s.lighting.environment.empty())
            std::fprintf(stderr,
                         "\n  environment %s × %.3g, turned %.1f°; %zu of %zu elements occlude "
                         "from both sides",
                         s.lighting.environment.c_str(), s.lighting.environmentIntensity,
                         glm::degrees(s.lighting.environmentRotation), s.twoSidedElements,
                         s.elements);
        if (s.glossyElements)
            std::fprintf(stderr, "\n  %zu of %zu elements glossy (%zu lobes)", s.glossyElements,
                         s.elements, size_t(s.Number("glossy_lobes")));
        if (s.gather.emitterRays)
            std::fprintf(
                stderr, "\n  first shot: %d rays a surfel%s in %.0f ms", s.gather.emitterRays,
                s.gather.sunRays
                    ? (" and " + std::to_string(s.gather.sunRays) + " to the sky's sun").c_str()
                    : "",
                s.gather.msFirstShot);
        if (s.gather.rays)
            std::fprintf(stderr,
                         "\n  final gather: %d rays at %zu vertices, traced in %.0f ms, "
                         "evaluated in %.1f ms (%s)",
                         s.gather.rays, s.gather.targets, s.gather.msTrace, s.gather.msEvaluate,
                         s.gather.device.c_str());
        std::fprintf(stderr, "\n  wrote %s (channel %s; %s)\n",
                     outPath == "-" ? "standard output" : outPath.c_str(), result.channel.c_str(),
                     kIrradianceUnits);
    }
    // As render: a Vulkan validation message is a bug of ours, reported and exit 3.
    const std::vector<std::string> messages = solver->ValidationMessages();
    for (const auto& m : messages)
        std::fprintf(stderr, "penumbra bake: validation: %s\n", m.c_str());
    return messages.empty() ? 0 : 3;
}

namespace {

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

}  // namespace

int Reference(const std::string& scenePath, const std::string& outPath, ReferenceSettings settings,
              const EnvironmentOptions& environment, DisplayColor color, bool quiet, float refine) {
    CheckOutputPath(outPath);
    Progress progress(!quiet && StderrIsTerminal());
    progress.Update("loading " + scenePath, 0.0);
    Scene scene = LoadGltf(scenePath);
    environment.Apply(scene);
    if (refine > 0.0f) RefineForOutput(scene, refine);
    Warn(scene, scenePath);
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
    Warn(scene, o.scene, !fromFile);
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
        perVertex = render::IrradianceForScene(scene, ReadResult(o.lighting));
        source = o.lighting;
    } else {
        std::string fellBack;
        solver = Solve(scene, settings, o.scene, o.gather, gatherSettings, iterations, o.quiet,
                       progress, fellBack);
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
        auto other = render::IrradianceForScene(scene, ReadResult(o.compare));
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

int CompareFiles(const std::string& aPath, const std::string& bPath, bool json, double maxRmse,
                 double floor) {
    if (!(floor > 0.0 && floor <= 1.0)) throw Error("--floor must be in (0, 1]");
    IrradianceFile a = ReadResult(aPath), b = ReadResult(bPath);
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

}  // namespace penumbra::cli
