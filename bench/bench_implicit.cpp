// The implicit-visibility solver (issue 21) on the paper's Table 1 scene class: a mesh of
// ~3,400 vertices moving in a room, the links rebuilt every frame, one bounce a frame, 864
// bins (the paper's 6 × 12 × 12 cube-map texels; here near-uniform bins). The paper's 8800
// GTX took 148 ms a frame including the relink; the goal on 2 CPU cores is ≤ 150 ms. Prints
// the split (update, create, refine and push, illumination) as the paper's table does, the
// link creation rate, and beside them the relative RMSE of the answer at the last pose
// against `penumbra reference`. Writes bench/results/implicit.json (with `--bin-cover
// closest`, the paper's closest-link rule: implicit-closest.json).
//
// The mesh deforms (`--motion deform`, the default: a wave travels over it, its vertices
// replaced each frame as SetVertices does) or moves rigidly (`--motion rigid`: a turn and a
// sway each frame); the solver relinks from scratch either way.
#include <CLI/CLI.hpp>
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <glm/gtc/matrix_transform.hpp>
#include <map>
#include <nlohmann/json.hpp>
#include <thread>

#include "bench_util.h"
#include "clutter_scenes.h"
#include "scene/scene_builder.h"
#include "solver/solver.h"
#include "solvers/implicit/settings.h"

namespace {

using namespace penumbra;
using Clock = std::chrono::steady_clock;

double Ms(Clock::time_point t) {
    return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

double Median(std::vector<double> v) {
    if (v.empty()) return 0.0;
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
}

// The clutter suite's 2 m room under its ceiling panel, and a "cloth": a 0.8 m square of
// side × side tiles hanging tilted in the middle, movable. `shared`: one mesh, its tiles
// sharing their corners ((side + 1)² vertices: 3,364 at 57), as a skinned or morphing mesh
// is; else a tile soup (4 vertices a tile: 3,364 at 29, each inner corner four times).
Scene ClothRoom(int side, bool shared) {
    SceneBuilder b;
    scenes::AddClutterRoom(b);
    const uint32_t cloth = b.AddMaterial("cloth", glm::vec3(0.6f, 0.5f, 0.4f));
    const glm::vec3 c(1.0f, 0.9f, 1.0f);
    const glm::vec3 corner = c + glm::vec3(-0.4f, -0.2f, -0.4f), u(0.8f, 0.0f, 0.0f),
                    v(0.0f, 0.4f, 0.8f), towards = c + glm::vec3(0.0f, 1.0f, -0.5f);
    if (shared)
        b.AddQuad("cloth", cloth, corner, corner + u, corner + u + v, corner + v, towards, side);
    else
        b.AddTiledQuad("cloth", cloth, corner, u, v, side, side, towards);
    b.SetDynamic("cloth", c);
    return b.Build();
}

}  // namespace

int main(int argc, char** argv) {
    CLI::App app{"penumbra implicit-visibility benchmark (issue 21): the paper's Table 1 class"};
    std::string out = "bench/results";
    int samples = 1024, frames = 20, bins = 864, side = 57;
    std::string motion = "deform", device = "cpu";
    float elementSize = 0.25f, threshold = 0.0f;
    app.add_option("--out", out, "folder for implicit.json (empty: print only)")
        ->capture_default_str();
    app.add_option("--samples", samples, "reference paths per vertex (0: no reference)")
        ->capture_default_str();
    app.add_option("--frames", frames, "frames timed (a move, a relink and a bounce each)")
        ->capture_default_str();
    app.add_option("--bins", bins, "direction bins (the paper: 6 x 12 x 12 = 864)")
        ->capture_default_str();
    app.add_option("--side", side,
                   "tiles a side of the moving mesh ((side + 1)² shared vertices; with "
                   "--tile-soup, 4 vertices a tile: 29 for the same count)")
        ->capture_default_str();
    bool soup = false;
    app.add_flag("--tile-soup", soup,
                 "the mesh as separate tiles, each with its own 4 vertices (sessions 25–34's "
                 "bench: each inner corner is four coincident surfels)");
    app.add_option("--link-threshold", threshold,
                   "the solver's link-threshold option (0: its default; the paper refines a "
                   "sender while it subtends more than a bin: 1)")
        ->capture_default_str();
    std::string binCover = "layer";
    app.add_option("--bin-cover", binCover,
                   "the solver's bin-cover option: layer (the default: the closest layer) or "
                   "closest (the paper's rule: the closest link covers the bin)")
        ->check(CLI::IsMember({"layer", "closest"}))
        ->capture_default_str();
    app.add_option("--element-size", elementSize,
                   "metres: the room's walls in elements this size (the mesh keeps its "
                   "vertices; the paper's room is a few quads)")
        ->capture_default_str();
    app.add_option("--motion", motion, "deform (a wave over the mesh) or rigid (a turn and a sway)")
        ->check(CLI::IsMember({"deform", "rigid"}))
        ->capture_default_str();
    app.add_option("--device", device,
                   "cpu, or lavapipe / gpu: the links created, composited and bounced on that "
                   "Vulkan device; writes implicit-DEVICE.json then")
        ->check(CLI::IsMember({"cpu", "lavapipe", "gpu"}))
        ->capture_default_str();
    CLI11_PARSE(app, argc, argv);

    Scene scene = ClothRoom(side, !soup);
    const int node = FindNode(scene, "cloth");
    const glm::mat4 rest = scene.nodes[node].local;
    std::vector<glm::vec3> restVertices;  // own space
    for (uint32_t p : scene.nodes[node].primitives)
        restVertices.insert(restVertices.end(), scene.primitives[p].objectPositions.begin(),
                            scene.primitives[p].objectPositions.end());
    // The cloth's plane (ClothRoom): spanned by (0.8, 0, 0) and (0, 0.4, 0.8).
    const glm::vec3 across =
        glm::normalize(glm::cross(glm::vec3(1, 0, 0), glm::vec3(0, 0.4f, 0.8f)));
    SolverSettings settings;
    settings.solver = "implicit";
    settings.device = device == "gpu"        ? DeviceChoice::kGpu
                      : device == "lavapipe" ? DeviceChoice::kLavapipe
                                             : DeviceChoice::kCpu;
    SetOption(settings.options, "bins", bins);
    if (threshold > 0.0f) SetOption(settings.options, "link-threshold", threshold);
    SetOption(settings.options, "bin-cover", binCover);
    settings.elementSize = elementSize;
    auto start = Clock::now();
    auto solver = CreateSolver(scene, settings);
    const double setupMs = Ms(start);
    solver->Iterate(1);  // warm-up frame

    std::map<std::string, std::vector<double>> split;
    std::vector<double> frameMs, linksPerSecond;
    SolverStats previous = solver->Stats();
    for (int f = 0; f < frames; ++f) {
        const float t = float(f + 1) / float(frames);
        if (motion == "rigid") {
            const glm::mat4 pose =
                glm::translate(glm::mat4(1.0f), glm::vec3(0.15f * t, 0.0f, -0.1f * t)) * rest *
                glm::rotate(glm::mat4(1.0f), glm::radians(40.0f * t), glm::vec3(0, 1, 0));
            SetNodeTransform(scene, node, pose);
        } else {
            // A wave of 8 cm along the cloth's x, half a wavelength over its 0.8 m, travelling
            // a wavelength over the frames, growing from the cloth's fixed (lower) edge.
            std::vector<glm::vec3> wave = restVertices;
            for (glm::vec3& v : wave) {
                const float u = (v.x + 0.4f) / 0.8f,
                            up = std::clamp((v.y + 0.2f) / 0.4f, 0.0f, 1.0f);
                v += 0.08f * up * std::sin(2.0f * 3.14159265f * (0.5f * u + t)) * across;
            }
            SetNodeVertices(scene, node, wave);
        }
        const auto frameStart = Clock::now();
        if (std::string why = solver->GeometryMismatch(scene); !why.empty()) {
            std::fprintf(stderr, "frame %d: the move was refused: %s\n", f, why.c_str());
            return 1;
        }
        solver->UpdateGeometry(scene);  // update, create, refine and push
        solver->Iterate(1);             // illumination: one bounce
        frameMs.push_back(Ms(frameStart));
        // The stats' pass times are totals so far: this frame's are the difference.
        const SolverStats s = solver->Stats();
        for (const auto& [name, ms] : bench::PassDeltas(previous, s)) {
            split[name].push_back(ms);
            if (name == "create" && ms > 0.0) linksPerSecond.push_back(double(s.links) / ms * 1e3);
        }
        previous = s;
    }
    const SolverStats s = solver->Stats();

    size_t clothVertices = 0;
    for (const Primitive& p : scene.primitives)
        if (p.nodeIndex == node) clothVertices += p.positions.size();

    nlohmann::json report;
    report["machine"] = {
        {"cpu", bench::CpuModel()},
        {"device", "cpu (" + std::to_string(std::thread::hardware_concurrency()) + " cores, TBB)"},
        {"link_device", s.device},
        {"composite_device", s.Text("composite_device")}};
    report["scene"] = {
        {"room", "the clutter suite's 2 m room, ceiling panel"},
        {"moving_mesh_vertices", clothVertices},
        {"mesh", soup ? "tile soup (4 vertices a tile)" : "one mesh, shared vertices"},
        {"motion", motion == "rigid" ? "rigid (a turn and a sway a frame)"
                                     : "deforming (SetVertices a frame: a travelling "
                                       "wave of 8 cm)"}};
    report["settings"] = {{"bins", bins},
                          {"bin_cover", binCover},
                          {"link_threshold", ReadImplicitSettings(settings).linkThreshold},
                          {"frames", frames},
                          {"bounces_per_frame", 1},
                          {"element_size", s.elementSize}};
    report["elements"] = s.elements;
    report["links"] = s.links;
    report["setup_ms"] = setupMs;
    report["frame_ms_median"] = Median(frameMs);
    for (const auto& [name, v] : split) report["split_ms_median"][name] = Median(v);
    report["link_creation_per_second_median"] = Median(linksPerSecond);
    report["paper"] = "GeForce 8800 GTX: 148 ms a frame including the relink";

    std::printf(
        "| moving mesh | elements | links | bins | frame ms (median) | update | create "
        "| refine+push | illumination | links/s created |\n|---|---|---|---|---|---|---"
        "|---|---|---|\n");
    std::printf("| %zu vertices | %zu | %zu | %d | %.1f | %.1f | %.1f | %.1f | %.1f | %.3g |\n",
                clothVertices, s.elements, s.links, bins, Median(frameMs), Median(split["update"]),
                Median(split["create"]), Median(split["refine_push"]),
                Median(split["illumination"]), Median(linksPerSecond));
    if (samples > 0) {
        const IrradianceFile truth = bench::Reference(scene, samples);
        nlohmann::json accuracy;
        bench::AddAccuracy(accuracy, scene, *solver, truth);
        report["accuracy"] = accuracy;
        report["accuracy"]["reference_samples"] = samples;
        std::printf(
            "relative RMSE at the last pose, converged (%d bounces), against %d paths: "
            "%.1f%%\n",
            accuracy["rmse_after_iterations"].get<int>(), samples,
            100.0 * accuracy["rel_rmse"].get<double>());
    }
    if (!out.empty())
        bench::WriteReport(report, out,
                           std::string("implicit") + (binCover == "closest" ? "-closest" : "") +
                               (device == "cpu" ? "" : "-" + device) + ".json");
    return 0;
}
