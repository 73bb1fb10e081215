// Stream benchmark (issue 64): the bytes a subscriber gets on the wire for each encoding it can
// ask for (f32 and f16 whole frames, a delta stream at 0.005 and one lossless to fp16), while a
// light is dimmed like a slider (1% a step, a step as each frame arrives), while a dynamic
// node moves (a step a frame), and idle; as bytes a frame and Mbps at 60 frames a second. Beside
// them, the delta streams' largest error against the f32 stream's values of the same frame
// (as a fraction of the tolerance's bound: at most 1; lossless: 0), 64 delta subscribers'
// p99 frame interval on one server, and the final frame's relative RMSE against
// `penumbra reference`. The server runs in this process on a Unix socket, on the CPU.
// Writes bench/results/stream.json.
#include <CLI/CLI.hpp>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "bench_client.h"
#include "bench_server.h"
#include "bench_util.h"
#include "protocol/frame.h"
#include "scene/gltf_loader.h"

namespace penumbra {
namespace {

using bench::Clock;
using bench::Ms;
using bench::Percentile;
namespace fs = std::filesystem;

struct Encoding {
    std::string name;
    client::Format format;
    float tolerance;
};
const Encoding kEncodings[] = {{"f32", client::Format::kFloat32, -1.0f},
                               {"f16", client::Format::kFloat16, -1.0f},
                               {"delta 0.005", client::Format::kDelta, 0.005f},
                               {"delta lossless", client::Format::kDelta, 0.0f}};

// Every frame one subscriber got: its number, edit, bytes on the wire and values.
struct Recorder {
    struct Got {
        uint64_t frame, lastEdit;
        size_t bytes;
        bool keyframe, converged;
        std::vector<float> values;
        Clock::time_point at;
    };
    std::mutex m;
    std::vector<Got> frames;
    bool keepValues = true;
    void operator()(const client::Frame& f) {
        Got g{f.frame, f.lastEdit, f.wireBytes, f.keyframe, f.converged, {}, Clock::now()};
        if (keepValues)
            for (const auto& p : f.primitives)
                g.values.insert(g.values.end(), p.rgb.begin(), p.rgb.end());
        std::lock_guard lock(m);
        frames.push_back(std::move(g));
    }
    uint64_t NewestEdit() {
        std::lock_guard lock(m);
        return frames.empty() ? 0 : frames.back().lastEdit;
    }
    bool ConvergedAt(uint64_t edit) {
        std::lock_guard lock(m);
        return !frames.empty() && frames.back().converged && frames.back().lastEdit >= edit;
    }
};

// Waits until every recorder has a frame with `edit` (true), or 60 s (false).
bool WaitFor(std::vector<std::unique_ptr<Recorder>>& recorders, uint64_t edit,
             bool converged = false) {
    const auto deadline = Clock::now() + std::chrono::seconds(60);
    while (Clock::now() < deadline) {
        bool all = true;
        for (auto& r : recorders)
            all = all && (converged ? r->ConvergedAt(edit) : r->NewestEdit() >= edit);
        if (all) return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    return false;
}

struct Options {
    std::vector<std::string> scenes{"office.gltf", "cornell-box.gltf"};
    int steps = 40, fanout = 64, samples = 256;
    std::string out = "bench/results", name = "stream";
    std::string root = std::string(PENUMBRA_SOURCE_DIR) + "/scenes";
};

nlohmann::json RunScene(const Options& o, const std::string& scene) {
    const fs::path root = o.root;
    bench::InProcessServer srv(root);
    client::Client loader(srv.url, "bench-stream");
    client::LoadOptions load;
    load.path = scene;
    load.device = "cpu";
    const client::SceneInfo info = loader.Load(load);
    // The light to dim (an emissive node; its material's emission gives its intensity) and
    // the node to move.
    const client::NodeInfo *light = nullptr, *mover = nullptr;
    float intensity = 0.0f;
    for (const auto& n : info.nodes) {
        if (n.dynamic && !mover) mover = &n;
        if (!n.emissive || light) continue;
        for (const auto& p : n.primitives)
            for (const auto& m : info.materials)
                if (m.name == p.material)
                    intensity = std::max({intensity, m.emission[0], m.emission[1], m.emission[2]});
        if (intensity > 0.0f) light = &n;
    }
    if (!light) throw std::runtime_error(scene + ": no emissive node to dim");

    std::vector<std::unique_ptr<client::Client>> clients;
    std::vector<std::unique_ptr<Recorder>> recorders;
    for (const Encoding& e : kEncodings) {
        clients.push_back(std::make_unique<client::Client>(srv.url, "bench-" + e.name));
        recorders.push_back(std::make_unique<Recorder>());
        Recorder* r = recorders.back().get();
        clients.back()->Subscribe([r](const client::Frame& f) { (*r)(f); },
                                  client::Channel::kIndirect, e.format, info.scene, {},
                                  std::max(e.tolerance, 0.0f));
    }
    WaitFor(recorders, 0, true);

    // The phases: each a range of edits whose frames it owns.
    struct Phase {
        std::string name;
        uint64_t first = 0, last = 0;
    };
    std::vector<Phase> phases;
    Phase slider{"light slider"};
    for (int i = 1; i <= o.steps; ++i) {
        const uint64_t edit = loader.SetLight(light->name, std::nullopt,
                                              intensity * (1.0f - 0.01f * float(i)), info.scene);
        if (i == 1) slider.first = edit;
        slider.last = edit;
        WaitFor(recorders, edit);
    }
    phases.push_back(slider);
    if (mover) {
        Phase move{"move"};
        for (int i = 1; i <= o.steps; ++i) {
            std::array<float, 16> m = mover->matrix;
            m[12] += 0.01f * float(i);
            const uint64_t edit = loader.SetTransform(mover->name, m, info.scene);
            if (i == 1) move.first = edit;
            move.last = edit;
            WaitFor(recorders, edit);
        }
        phases.push_back(move);
    }
    // Idle: converged, then two seconds of nothing to send.
    const uint64_t lastEdit = phases.back().last;
    WaitFor(recorders, lastEdit, true);
    std::vector<size_t> idleStart;
    for (auto& r : recorders) {
        std::lock_guard lock(r->m);
        idleStart.push_back(r->frames.size());
    }
    std::this_thread::sleep_for(std::chrono::seconds(2));
    for (auto& c : clients) c->Close();

    nlohmann::json out;
    out["scene"] = scene;
    out["vertices"] = recorders[0]->frames.back().values.size() / 3;
    const auto& full = recorders[0]->frames;  // f32: the values to compare with
    std::map<uint64_t, const Recorder::Got*> fullByFrame;
    for (const auto& g : full) fullByFrame[g.frame] = &g;
    std::printf("\n%s (%zu vertices), CPU, a step a frame\n", scene.c_str(),
                out["vertices"].get<size_t>());
    std::printf("  %-16s %-13s %8s %10s %8s %12s\n", "encoding", "phase", "frames", "B/frame",
                "Mbps@60", "max error");
    for (size_t k = 0; k < recorders.size(); ++k) {
        const Encoding& e = kEncodings[k];
        nlohmann::json enc;
        // The largest error against the f32 frame of the same number: for a tolerance, as a
        // fraction of its bound (SPEC.md "Delta frames"); else the largest relative one.
        double worst = 0.0;
        size_t compared = 0;
        for (const auto& g : recorders[k]->frames) {
            auto it = fullByFrame.find(g.frame);
            if (it == fullByFrame.end() || it->second->values.size() != g.values.size()) continue;
            const auto& v = it->second->values;
            double sum = 0.0;
            for (float x : v) sum += std::abs(x);
            const float floor = float(sum / double(std::max<size_t>(v.size(), 1))) / 20.0f;
            for (size_t i = 0; i < v.size(); ++i) {
                const double d = std::abs(double(g.values[i]) - v[i]);
                if (e.tolerance > 0.0f)
                    worst = std::max(worst, d / (e.tolerance * std::max(std::abs(v[i]), floor)));
                else if (e.tolerance == 0.0f)
                    worst = std::max(
                        worst, d == 0.0
                                   ? 0.0
                                   : std::abs(double(g.values[i]) -
                                              protocol::HalfToFloat(protocol::FloatToHalf(v[i]))));
                else
                    worst = std::max(worst, d / std::max(std::abs(v[i]), 1e-6f));
            }
            ++compared;
        }
        enc["max_error"] = worst;
        enc["max_error_is"] = e.tolerance > 0.0f    ? "fraction of the tolerance bound"
                              : e.tolerance == 0.0f ? "difference from the f32 value's fp16"
                                                    : "relative to the f32 value";
        enc["frames_compared"] = compared;
        for (const Phase& p : phases) {
            size_t frames = 0, bytes = 0, keyframes = 0;
            for (const auto& g : recorders[k]->frames)
                if (g.lastEdit >= p.first && g.lastEdit <= p.last)
                    ++frames, bytes += g.bytes, keyframes += g.keyframe;
            const double perFrame = frames ? double(bytes) / double(frames) : 0.0;
            enc[p.name] = {{"frames", frames},
                           {"bytes_per_frame", perFrame},
                           {"mbps_at_60hz", perFrame * 8.0 * 60.0 / 1e6},
                           {"keyframes", keyframes}};
            std::printf("  %-16s %-13s %8zu %10.0f %8.2f %12.2e\n", e.name.c_str(), p.name.c_str(),
                        frames, perFrame, perFrame * 8.0 * 60.0 / 1e6, worst);
        }
        size_t idleBytes = 0;
        {
            std::lock_guard lock(recorders[k]->m);
            for (size_t i = idleStart[k]; i < recorders[k]->frames.size(); ++i)
                idleBytes += recorders[k]->frames[i].bytes;
        }
        enc["idle_bytes_in_2s"] = idleBytes;
        std::printf("  %-16s %-13s %8s %10zu\n", e.name.c_str(), "idle (2 s)", "", idleBytes);
        out["encodings"][e.name] = enc;
    }

    // Fan-out: many delta subscribers at once during the slider.
    if (o.fanout > 0) {
        std::vector<std::unique_ptr<client::Client>> many;
        std::vector<std::unique_ptr<Recorder>> fan;
        for (int i = 0; i < o.fanout; ++i) {
            many.push_back(std::make_unique<client::Client>(srv.url, "bench-fan"));
            fan.push_back(std::make_unique<Recorder>());
            fan.back()->keepValues = false;
            Recorder* r = fan.back().get();
            many.back()->Subscribe([r](const client::Frame& f) { (*r)(f); },
                                   client::Channel::kIndirect, client::Format::kDelta, info.scene);
        }
        uint64_t first = 0;
        for (int i = 1; i <= o.steps; ++i) {
            const uint64_t edit =
                loader.SetLight(light->name, std::nullopt,
                                intensity * (1.0f - 0.01f * float(o.steps + i)), info.scene);
            if (i == 1) first = edit;
            WaitFor(fan, edit);
        }
        std::vector<double> intervals;
        size_t bytes = 0, frames = 0;
        for (auto& r : fan) {
            std::lock_guard lock(r->m);
            const Recorder::Got* previous = nullptr;
            for (const auto& g : r->frames) {
                if (g.lastEdit < first) continue;
                if (previous) intervals.push_back(Ms(g.at - previous->at));
                previous = &g;
                bytes += g.bytes, ++frames;
            }
        }
        for (auto& c : many) c->Close();
        out["fanout"] = {{"subscribers", o.fanout},
                         {"frame_interval_ms_p50", Percentile(intervals, 0.5)},
                         {"frame_interval_ms_p99", Percentile(intervals, 0.99)},
                         {"bytes_per_frame", frames ? double(bytes) / double(frames) : 0.0}};
        std::printf(
            "  %d delta subscribers, light slider: frame interval p50 %.1f ms, p99 %.1f ms\n",
            o.fanout, Percentile(intervals, 0.5), Percentile(intervals, 0.99));
    }

    // Accuracy at these settings: the edits undone, the converged frame against the reference
    // of the scene as loaded (every encoding carries the same solution).
    if (o.samples > 0) {
        uint64_t edit = loader.SetLight(light->name, std::nullopt, intensity, info.scene);
        if (mover) edit = loader.SetTransform(mover->name, mover->matrix, info.scene);
        const IrradianceFile truth = bench::Reference(LoadGltf((root / scene).string()), o.samples);
        for (int i = 0; i < 6000; ++i) {
            const client::Frame f =
                loader.Get(client::Channel::kIndirect, client::Format::kFloat32, info.scene);
            if (f.lastEdit >= edit && f.converged) {
                const double rmse = Compare(bench::FrameToFile(f), truth).overall.relRmse;
                out["rel_rmse"] = rmse;
                out["reference_samples"] = o.samples;
                std::printf("  rel. RMSE of the converged frame, edits undone: %.1f%% (%d paths)\n",
                            100.0 * rmse, o.samples);
                break;
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(10));
        }
    }
    loader.Close();
    return out;
}

}  // namespace
}  // namespace penumbra

int main(int argc, char** argv) {
    penumbra::Options o;
    CLI::App app{"penumbra-bench-stream: bytes on the wire for each frame encoding"};
    app.add_option("--scenes", o.scenes, "glTF files under --root")->capture_default_str();
    app.add_option("--root", o.root,
                   "the server's scene root (a 10× office: scripts/copies.py scenes/office.gltf "
                   "DIR/office10.glb 10 20)")
        ->capture_default_str();
    app.add_option("--steps", o.steps, "slider and move steps, one a frame")->capture_default_str();
    app.add_option("--fanout", o.fanout, "delta subscribers for the fan-out phase (0: none)")
        ->capture_default_str();
    app.add_option("--samples", o.samples, "reference paths per vertex for the RMSE (0: none)")
        ->capture_default_str();
    app.add_option("--out", o.out, "results folder (empty: print only)")->capture_default_str();
    app.add_option("--name", o.name, "results go to OUT/NAME.json")->capture_default_str();
    CLI11_PARSE(app, argc, argv);
    try {
        nlohmann::json report;
        report["benchmark"] = "stream";
        report["device"] = "cpu (" + penumbra::bench::CpuModel() + ", " +
                           std::to_string(std::thread::hardware_concurrency()) + " threads)";
        for (const auto& scene : o.scenes) report["scenes"].push_back(penumbra::RunScene(o, scene));
        penumbra::bench::WriteReport(report, o.out, o.name + ".json");
    } catch (const std::exception& e) {
        std::fprintf(stderr, "penumbra-bench-stream: %s\n", e.what());
        return 1;
    }
    return 0;
}
