// One function per service command: what it sends through the client library and what it
// prints (docs/CLI.md).
#include <condition_variable>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <memory>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>

#include "base/check.h"
#include "base/progress.h"
#include "cmd/service_state.h"
#include "output/irradiance_writer.h"
#include "scene/gltf_loader.h"
#include "solver/solver.h"

namespace penumbra::cli {

namespace fs = std::filesystem;

std::array<float, 3> Triple(const std::vector<float>& v, const char* what) {
    if (v.size() != 3) throw Error(std::string(what) + " needs three numbers, e.g. 1,0.9,0.8");
    return {v[0], v[1], v[2]};
}

// The channels by the solver interface's names (solver.h), as the protocol numbers them.
namespace {

static_assert(int(client::Channel::kIndirect) == int(Channel::kIndirect) &&
              int(client::Channel::kDirect) == int(Channel::kDirect) &&
              int(client::Channel::kTotal) == int(Channel::kTotal));
client::Channel ParseClientChannel(const std::string& s) {
    return static_cast<client::Channel>(ParseChannel(s));
}

const char* ChannelName(client::Channel c) { return ChannelName(static_cast<Channel>(c)); }

client::Format ParseFormat(const std::string& s) {
    if (s == "f32" || s == "float32") return client::Format::kFloat32;
    if (s == "f16" || s == "float16") return client::Format::kFloat16;
    if (s == "delta") return client::Format::kDelta;
    throw Error("format must be delta, f32 or f16, not '" + s + "'");
}

// Splits a script line into words; "double quotes" group words with spaces.
void PrintFrame(const client::Frame& f, double fps, bool json) {
    double device = 0.0;
    for (const auto& p : f.passes) device += p.second;
    if (json) {
        nlohmann::json j = {{"scene", f.scene},
                            {"frame", f.frame},
                            {"edit", f.lastEdit},
                            {"iterations", f.iterations},
                            {"ms", f.frameMs},
                            {"device_ms", device},
                            {"fps", fps},
                            {"converged", f.converged},
                            {"note", f.note},
                            {"bytes", f.wireBytes},
                            {"keyframe", f.keyframe}};
        j["latency_ms"] = f.editLatencyMs > 0.0 ? nlohmann::json(f.editLatencyMs) : nullptr;
        for (const auto& [name, ms] : f.passes) j["passes"][name] = ms;
        std::printf("%s\n", j.dump().c_str());
        std::fflush(stdout);
        return;
    }
    std::printf("frame %6llu  edit %3llu  %7.2f ms  device %7.2f ms  %5.1f fps",
                (unsigned long long)f.frame, (unsigned long long)f.lastEdit, f.frameMs, device,
                fps);
    if (f.editLatencyMs > 0.0) std::printf("  latency %7.1f ms", f.editLatencyMs);
    if (f.converged) std::printf("  converged");
    if (!f.note.empty()) std::printf("  (%s)", f.note.c_str());
    std::printf("\n");
    std::fflush(stdout);
}

}  // namespace

int ServiceCommands::State::RunLoad(client::Client& c) {
    client::LoadOptions o = loadOptions;
    if (skyColor.size() == 3) o.environmentColor = {skyColor[0], skyColor[1], skyColor[2]};
    o.environmentRotation = skyRotationDegrees * 0.017453292519943295f;
    if (sun.size() == 3) o.sun = {sun[0], sun[1], sun[2]};
    o.clearSky = skyModel == "clear";
    if (turbidity) o.turbidity = *turbidity;
    if (upload) {
        std::ifstream in(loadPath, std::ios::binary);
        if (!in) throw Error(loadPath + ": cannot read");
        if (!IsGlbPath(loadPath)) throw Error("--upload sends binary glTF: give a .glb file");
        o.glb.assign(std::istreambuf_iterator<char>(in), {});
        o.name = fs::path(loadPath).filename().string();
    } else {
        o.path = loadPath;
    }
    // The server's build, drawn as it goes (a terminal only, as bake's).
    Progress progress(!quiet && StderrIsTerminal());
    if (!quiet && StderrIsTerminal())
        o.progress = [&progress](const std::string& stage, double fraction, double left) {
            char text[64] = "";
            if (left >= 0.0) std::snprintf(text, sizeof(text), ", %.0f s left", left);
            progress.Update("server: " + stage + text, fraction);
        };
    auto info = c.Load(o);
    progress.Done();
    std::string dynamic, lights;
    for (const auto& l : info.lights)
        lights += (lights.empty() ? "" : ", ") + l.name + " (" + l.type + ")";
    for (const auto& n : info.nodes) {
        if (n.dynamic) dynamic += (dynamic.empty() ? "" : ", ") + n.name;
        if (n.emissive) lights += (lights.empty() ? "" : ", ") + n.name + " (emissive)";
    }
    std::printf("%s %s: %u elements, %llu links, solver %s on %s, built in %.2f s\n",
                info.reused ? "joined" : "loaded", info.scene.c_str(), info.elements,
                (unsigned long long)info.links, info.solver.c_str(), info.device.c_str(),
                info.buildSeconds);
    if (!info.environment.empty())
        lights += (lights.empty() ? "" : ", ") + ("environment " + info.environment);
    if (!quiet)
        std::printf("  movable: %s\n  lights: %s\n", dynamic.empty() ? "(none)" : dynamic.c_str(),
                    lights.empty() ? "(none)" : lights.c_str());
    for (const auto& w : info.warnings)
        std::fprintf(stderr, "penumbra: warning: %s: %s\n", info.scene.c_str(), w.c_str());
    return kExitOk;
}

int ServiceCommands::State::RunInfo(client::Client& c) {
    auto i = c.Info(session);
    std::printf("scene %s: solver %s on %s, %u elements, %llu links\n", i.scene.c_str(),
                i.solver.c_str(), i.device.c_str(), i.elements, (unsigned long long)i.links);
    for (const auto& w : i.warnings) std::printf("  warning: %s\n", w.c_str());
    for (const auto& n : i.nodes) {
        uint32_t vertices = 0;
        for (const auto& p : n.primitives) vertices += p.vertices;
        std::string morph;
        if (n.morphTargets > 0) {
            morph = ", " + std::to_string(n.morphTargets) + " morph targets (weights";
            for (float w : n.morphWeights) morph += " " + std::to_string(w).substr(0, 6);
            morph += ")";
        }
        std::printf("  node %-20s %zu primitives, %u vertices%s%s%s\n", n.name.c_str(),
                    n.primitives.size(), vertices, n.dynamic ? ", dynamic" : "",
                    n.emissive ? ", light" : "", morph.c_str());
    }
    for (const auto& l : i.lights)
        std::printf(
            "  light %-19s %s on node %s, colour %.3g %.3g %.3g × %.4g %s, at %.3g %.3g %.3g, "
            "towards %.3g %.3g %.3g%s\n",
            l.name.c_str(), l.type.c_str(), l.node.c_str(), l.color[0], l.color[1], l.color[2],
            l.intensity, l.type == "directional" ? "lux" : "cd", l.position[0], l.position[1],
            l.position[2], l.direction[0], l.direction[1], l.direction[2],
            l.type == "spot" ? (", cone " + std::to_string(glm::degrees(l.innerCone)) + "°–" +
                                std::to_string(glm::degrees(l.outerCone)) + "°")
                                   .c_str()
                             : "");
    for (const auto& m : i.materials)
        std::printf(
            "  material %-16s albedo %.3g %.3g %.3g  emission %.3g %.3g %.3g  "
            "roughness %.3g  metallic %.3g\n",
            m.name.c_str(), m.albedo[0], m.albedo[1], m.albedo[2], m.emission[0], m.emission[1],
            m.emission[2], m.roughness, m.metallic);
    return kExitOk;
}

int ServiceCommands::State::RunWatch(client::Client& c) {
    // What the reader thread's callback shares with this function, owned by both: the
    // callback stays registered with the client after this returns, and a frame arriving
    // then (the client is closed later) must find a live mutex and `done`, not this stack
    // frame's remains (a glibc mutex assertion aborted `watch --frames 1` now and then).
    struct Shared {
        std::mutex m;
        std::condition_variable cv;
        int seen = 0;
        bool done = false;
        std::string ended;  // the server ended the subscription: why
        std::deque<Clock::time_point> arrivals;
    };
    const auto shared = std::make_shared<Shared>();
    c.Subscribe(
        [this, shared](const client::Frame& f) {
            Shared& s = *shared;
            std::lock_guard lock(s.m);
            if (s.done) return;
            auto now = Clock::now();
            s.arrivals.push_back(now);
            while (s.arrivals.size() > 10) s.arrivals.pop_front();
            double fps = 0.0;
            if (s.arrivals.size() > 1)
                fps = (s.arrivals.size() - 1) /
                      std::chrono::duration<double>(s.arrivals.back() - s.arrivals.front()).count();
            PrintFrame(f, fps, watchJson);
            ++s.seen;
            if ((watchFrames > 0 && s.seen >= watchFrames) ||
                (untilConverged && f.converged && f.lastEdit >= minEdit))
                s.done = true;
            s.cv.notify_all();
        },
        ParseClientChannel(channel), ParseFormat(format), session,
        [shared](const std::string& why) {
            Shared& s = *shared;
            std::lock_guard lock(s.m);
            if (s.done) return;
            s.ended = why;
            s.done = true;
            s.cv.notify_all();
        },
        tolerance);
    Shared& s = *shared;
    std::unique_lock lock(s.m);
    auto stop = [&] { return s.done || !c.Connected(); };
    if (timeout > 0.0) {
        if (!s.cv.wait_for(lock, std::chrono::duration<double>(timeout), stop)) {
            s.done = true;
            if (!quiet)  // on stderr when stdout is JSON Lines
                std::fprintf(watchJson ? stderr : stdout, "watch: %.1f s passed, %d frames\n",
                             timeout, s.seen);
            return kExitOk;
        }
    } else {
        while (!stop()) s.cv.wait_for(lock, std::chrono::milliseconds(200));
    }
    s.done = true;
    if (!s.ended.empty()) {
        std::fprintf(stderr, "penumbra: watch: %s\n", s.ended.c_str());
        return kExitRefused;
    }
    if (!c.Connected()) {
        std::fprintf(stderr, "penumbra: watch: the server closed the connection\n");
        return kExitConnection;
    }
    return kExitOk;
}

int ServiceCommands::State::RunMove(client::Client& c) {
    std::array<float, 16> out{};
    if (!matrix.empty()) {
        if (matrix.size() != 16) throw Error("--matrix needs 16 numbers");
        std::copy(matrix.begin(), matrix.end(), out.begin());
    } else {
        auto i = c.Info(session);
        const client::NodeInfo* n = i.Node(node);
        if (!n) {
            // As the server says it (Session::Submit): the nodes that can move.
            std::string movable;
            for (const auto& m : i.nodes)
                if (m.dynamic) movable += (movable.empty() ? "" : ", ") + m.name;
            throw Error("no node '" + node + "' in scene '" + i.scene +
                        "'; movable nodes: " + (movable.empty() ? "(none)" : movable));
        }
        glm::mat4 current;
        for (int k = 0; k < 16; ++k) current[k / 4][k % 4] = n->matrix[k];
        glm::mat4 t(1.0f);
        if (!translate.empty()) {
            auto v = Triple(translate, "--translate");
            t = glm::translate(t, glm::vec3(v[0], v[1], v[2]));
        }
        glm::mat4 r = glm::rotate(glm::mat4(1.0f), glm::radians(rotateY), glm::vec3(0, 1, 0));
        glm::mat4 next = t * current * r;
        for (int k = 0; k < 16; ++k) out[k] = next[k / 4][k % 4];
    }
    lastEdit = c.SetTransform(node, out, session);
    if (!quiet) std::printf("edit %llu: move %s\n", (unsigned long long)lastEdit, node.c_str());
    return kExitOk;
}

int ServiceCommands::State::RunDeform(client::Client& c) {
    if (verticesFile.empty() == weights.empty())
        throw Error("deform: give --weights (morph targets) or --vertices FILE");
    if (!weights.empty()) {
        lastEdit = c.SetMorphWeights(node, weights, session);
    } else {
        std::ifstream in(verticesFile);
        if (!in) throw Error("deform: cannot read " + verticesFile);
        nlohmann::json j;
        try {
            j = nlohmann::json::parse(in);
        } catch (const std::exception& e) {
            throw Error("deform: " + verticesFile + " is not JSON: " + e.what());
        }
        auto numbers = [&](const char* key) {
            std::vector<float> out;
            if (!j.is_object() || !j.contains(key)) return out;
            if (!j[key].is_array())
                throw Error("deform: \"" + std::string(key) + "\" must be a list of numbers");
            for (const auto& x : j[key]) {
                if (!x.is_number())
                    throw Error("deform: \"" + std::string(key) + "\" must be a list of numbers");
                out.push_back(x.get<float>());
            }
            return out;
        };
        const std::vector<float> positions = numbers("positions");
        if (positions.empty())
            throw Error("deform: " + verticesFile + " has no \"positions\" list");
        lastEdit = c.SetVertices(node, positions, numbers("normals"), session);
    }
    if (!quiet) std::printf("edit %llu: deform %s\n", (unsigned long long)lastEdit, node.c_str());
    return kExitOk;
}

int ServiceCommands::State::RunLight(client::Client& c) {
    std::optional<std::array<float, 3>> col;
    if (!color.empty()) col = Triple(color, "--color");
    client::Client::LightChange change;
    change.color = col;
    // SetLight reads a negative intensity or range as "unchanged" (SPEC): refuse it here.
    if (intensity && !(*intensity >= 0.0f))
        throw Error("light: --intensity must be a number ≥ 0 (cd, lux or nits)");
    if (range && !(*range >= 0.0f))
        throw Error("light: --range must be a number of metres ≥ 0 (0: infinite)");
    change.intensity = intensity;
    if (!position.empty()) change.position = Triple(position, "--position");
    if (!direction.empty()) change.direction = Triple(direction, "--direction");
    if (!cone.empty()) {
        if (cone.size() != 2) throw Error("--cone needs inner,outer (degrees)");
        change.innerCone = glm::radians(cone[0]);
        change.outerCone = glm::radians(cone[1]);
    }
    change.range = range;
    if (!change.color && !change.intensity && !change.position && !change.direction &&
        !change.innerCone && !change.range)
        throw Error(
            "light: give at least one of --intensity, --color, --position, --direction, "
            "--cone, --range");
    lastEdit = c.SetLight(node, change, session);
    if (!quiet) std::printf("edit %llu: light %s\n", (unsigned long long)lastEdit, node.c_str());
    return kExitOk;
}

int ServiceCommands::State::RunMaterial(client::Client& c) {
    client::Client::MaterialChange change;
    if (!albedo.empty()) change.albedo = Triple(albedo, "--albedo");
    if (!emission.empty()) change.emission = Triple(emission, "--emission");
    change.roughness = roughness;
    change.metallic = metallic;
    if (!change.albedo && !change.emission && !roughness && !metallic)
        throw Error(
            "material: give at least one of --albedo, --emission, --roughness, "
            "--metallic");
    lastEdit = c.SetMaterial(node, change, session);
    if (!quiet) std::printf("edit %llu: material %s\n", (unsigned long long)lastEdit, node.c_str());
    return kExitOk;
}

int ServiceCommands::State::RunSky(client::Client& c) {
    client::Client::EnvironmentChange change;
    change.path = skyPath;
    if (skyColor.size() == 3) change.color = {skyColor[0], skyColor[1], skyColor[2]};
    change.off = skyOff;
    change.intensity = skyIntensity;
    if (skyTurnDegrees) change.rotation = *skyTurnDegrees * 0.017453292519943295f;
    if (sun.size() >= 2) change.sun = {sun[0], sun[1]};
    if (sun.size() == 3) change.sunIlluminance = sun[2];
    change.clearSky = skyModel == "clear";
    change.turbidity = turbidity;
    if (change.path.empty() && !change.color && !change.off && !change.intensity &&
        !change.rotation && !change.sun && !change.clearSky && !change.turbidity)
        throw Error(
            "sky: give --environment, --environment-color, --sky clear or --off, and/or "
            "--environment-intensity, --environment-rotation, --sun, --turbidity");
    lastEdit = c.SetEnvironment(change, session);
    if (!quiet) std::printf("edit %llu: sky\n", (unsigned long long)lastEdit);
    return kExitOk;
}

int ServiceCommands::State::RunGet(client::Client& c) {
    client::Frame f = c.Get(ParseClientChannel(channel), client::Format::kFloat32, session);
    // The bake formats: a Scene carries each primitive's key (and, for glTF output, its
    // geometry, read from the local file).
    Scene scene;
    bool json =
        output == "-" || (output.size() >= 5 && output.compare(output.size() - 5, 5, ".json") == 0);
    if (!json) {
        if (gltf.empty())
            throw Error("glTF output needs the scene file: add --gltf FILE (or write .json)");
        scene = LoadGltf(gltf);
        if (scene.primitives.size() != f.primitives.size())
            throw Error(gltf + " has " + std::to_string(scene.primitives.size()) +
                        " primitives, the server's scene " + std::to_string(f.primitives.size()) +
                        ": not the same scene");
    } else {
        for (const auto& p : f.primitives) {
            Primitive prim;
            prim.node = p.node;
            prim.mesh = p.mesh;
            prim.primitive = p.primitive;
            scene.primitives.push_back(prim);
        }
    }
    IrradianceResult result;
    auto stats = nlohmann::json::parse(c.Stats(session));
    const nlohmann::json& sc = stats.contains("scenes") ? stats["scenes"].back() : stats;
    result.solver = sc["solver"].value("solver", "antiradiance");
    result.channel = ChannelName(f.channel);
    result.stats = sc["solver"];
    result.stats["frame"] = f.frame;
    result.stats["last_edit"] = f.lastEdit;
    for (size_t p = 0; p < f.primitives.size(); ++p) {
        const auto& rgb = f.primitives[p].rgb;
        if (!json && rgb.size() != scene.primitives[p].InputVertexCount() * 3)
            throw Error(gltf + ": primitive " + std::to_string(p) +
                        " has a different vertex count than the server's scene");
        std::vector<glm::vec3> v(rgb.size() / 3);
        for (size_t i = 0; i < v.size(); ++i)
            v[i] = glm::vec3(rgb[i * 3], rgb[i * 3 + 1], rgb[i * 3 + 2]);
        result.primitives.push_back(std::move(v));
    }
    if (json)
        WriteIrradianceJson(output, scene, result);
    else
        WriteIrradianceGltf(gltf, output, scene, result, ParseDisplayColor(color0));
    if (!quiet)  // on stderr when the data itself goes to standard output
        std::fprintf(
            output == "-" ? stderr : stdout, "wrote %s (frame %llu, edit %llu, channel %s)\n",
            output == "-" ? "standard output" : output.c_str(), (unsigned long long)f.frame,
            (unsigned long long)f.lastEdit, result.channel.c_str());
    return kExitOk;
}

int ServiceCommands::State::RunStep(client::Client& c) {
    uint64_t frame = c.Step(stepIterations, session);
    if (!quiet) std::printf("frame %llu\n", (unsigned long long)frame);
    return kExitOk;
}

int ServiceCommands::State::RunStats(client::Client& c) {
    std::printf("%s\n", nlohmann::json::parse(c.Stats(session)).dump(2).c_str());
    return kExitOk;
}

int ServiceCommands::State::RunUnload(client::Client& c) {
    c.UnloadScene(session);
    if (!quiet) std::printf("unloaded %s\n", session.empty() ? "the scene" : session.c_str());
    return kExitOk;
}

int ServiceCommands::State::RunSleep(client::Client&) {
    if (!(sleepSeconds >= 0.0) || sleepSeconds > 3600) throw Error("sleep: 0…3600 seconds");
    std::this_thread::sleep_for(std::chrono::duration<double>(sleepSeconds));
    return kExitOk;
}

}  // namespace penumbra::cli
