// Service commands of the CLI: argument handling, the embedded server and each command's
// output. The protocol work is the client library's.
#include "cmd/service_cli.h"

#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "base/check.h"
#include "client/client.h"
#include "cmd/solver_options.h"
#include "net/server.h"
#include "output/irradiance_writer.h"
#include "scene/gltf_loader.h"
#include "service/service.h"
#include "solver/solver.h"

namespace penumbra::cli {

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

// An in-process server on a private Unix socket: the CLI's embedded mode.
class EmbeddedServer {
  public:
    EmbeddedServer(const fs::path& sceneRoot, const std::string& device) {
        SolverSettings defaults = service::ServiceDefaults();
        defaults.device = ParseDevice(device);
        service_ =
            std::make_unique<service::Service>(sceneRoot, service::ServiceLimits{}, defaults);
        server_ = std::make_unique<net::Server>(io_, *service_, net::NetLimits{});
        char dir[] = "/tmp/penumbra-embedded-XXXXXX";
        if (!mkdtemp(dir)) throw Error("cannot create a private folder for the embedded server");
        dir_ = dir;
        net::ListenAddress a;
        a.kind = net::ListenAddress::Kind::kUnix;
        a.path = (dir_ / "socket").string();
        url_ = server_->Listen(a);
        thread_ = std::thread([this] { io_.run(); });
    }
    ~EmbeddedServer() {
        asio::post(io_, [this] {
            server_->Stop();
            io_.stop();
        });
        thread_.join();
        server_.reset();
        std::error_code ec;
        fs::remove_all(dir_, ec);
    }
    const std::string& Url() const { return url_; }

  private:
    asio::io_context io_;
    std::unique_ptr<service::Service> service_;
    std::unique_ptr<net::Server> server_;
    fs::path dir_;
    std::string url_;
    std::thread thread_;
};

std::array<float, 3> Triple(const std::vector<float>& v, const char* what) {
    if (v.size() != 3) throw Error(std::string(what) + " needs three numbers, e.g. 1,0.9,0.8");
    return {v[0], v[1], v[2]};
}

// The channels by the solver interface's names (solver.h), as the protocol numbers them.
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
    throw Error("format must be f32 or f16, not '" + s + "'");
}

// Splits a script line into words; "double quotes" group words with spaces.
std::vector<std::string> SplitWords(const std::string& line) {
    std::vector<std::string> words;
    std::string w;
    bool quoted = false, any = false;
    for (char c : line) {
        if (c == '"') {
            quoted = !quoted;
            any = true;
        } else if (!quoted && (c == ' ' || c == '\t')) {
            if (any) words.push_back(w);
            w.clear();
            any = false;
        } else {
            w += c;
            any = true;
        }
    }
    if (quoted) throw Error("unterminated quote");
    if (any) words.push_back(w);
    return words;
}

// One line per frame: for people, or (`json`) a JSON object per line (JSON Lines).
void PrintFrame(const client::Frame& f, double fps, bool json) {
    double device = 0.0;
    for (const auto& p : f.passes) device += p.second;
    if (json) {
        nlohmann::json j = {{"scene", f.scene},   {"frame", f.frame},
                            {"edit", f.lastEdit}, {"iterations", f.iterations},
                            {"ms", f.frameMs},    {"device_ms", device},
                            {"fps", fps},         {"converged", f.converged},
                            {"note", f.note}};
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

struct ServiceCommands::State {
    bool forScript = false;
    std::string connect, session, embeddedScene, device = "auto";
    bool quiet = false;

    CLI::App *load = nullptr, *info = nullptr, *watch = nullptr, *move = nullptr, *light = nullptr,
             *material = nullptr, *sky = nullptr, *get = nullptr, *step = nullptr, *stats = nullptr,
             *script = nullptr, *wait = nullptr, *sleep = nullptr;

    client::LoadOptions loadOptions;
    std::string loadPath;
    bool upload = false;
    std::vector<float> skyColor;
    float skyRotationDegrees = 0.0f;

    int watchFrames = 0;
    uint64_t minEdit = 0;
    double timeout = 0.0;
    bool untilConverged = false;
    bool watchJson = false;
    std::string channel = "indirect", format = "f32";

    std::string node;
    std::vector<float> translate, matrix, color, albedo, emission, position, direction, cone;
    float rotateY = 0.0f;
    // Optional, so that a negative value reaches the server and is refused there with why.
    std::optional<float> intensity, range;
    std::optional<float> roughness, metallic;
    std::string skyPath;
    bool skyOff = false;
    std::optional<float> skyIntensity, skyTurnDegrees;

    std::string output, gltf, color0 = "tonemapped";
    int stepIterations = 1;
    std::string scriptFile;
    double sleepSeconds = 0.0;

    uint64_t lastEdit = 0;  // newest edit this run sent (for `wait`)

    int Execute(client::Client& c);
    int RunScript(client::Client& c);
    int Wait(client::Client& c, uint64_t edit, double timeoutSeconds);
};

ServiceCommands::ServiceCommands(CLI::App& app, bool forScript) : s_(std::make_unique<State>()) {
    State& s = *s_;
    s.forScript = forScript;
    if (!forScript) {
        app.add_option("--connect", s.connect,
                       "server address for the service commands: tcp://HOST:PORT or "
                       "unix:///PATH")
            ->envname("PENUMBRA_CONNECT");
        app.add_option("--session", s.session,
                       "scene session on the server (default: the newest loaded)");
    }

    s.load = app.add_subcommand("load", "Load a scene on the server (or join its session)");
    s.load->add_option("path", s.loadPath, "glTF path under the server's --scene-root")->required();
    s.load->add_flag("--upload", s.upload, "send the local file as a .glb instead of a path");
    AddSolverOptions(s.load, s.loadOptions.solver, s.loadOptions.solverOptions);
    s.load
        ->add_option("--iterations-per-frame", s.loadOptions.iterationsPerFrame,
                     "solver iterations per streamed frame")
        ->capture_default_str();
    s.load->add_option("--element-size", s.loadOptions.elementSize,
                       "metres (0: scene diameter / 40)");
    s.load->add_option("--device", s.loadOptions.device, "auto|gpu|lavapipe|cpu");
    s.load->add_flag("--reload", s.loadOptions.reload, "rebuild even if already loaded");
    s.load
        ->add_option("--converged-change", s.loadOptions.convergedChange,
                     "idle once a frame changes irradiance by less (0: stream forever)")
        ->capture_default_str();
    s.load
        ->add_option("--emitter-direct", s.loadOptions.emitterRays,
                     "shadow rays per surfel for the emitters' direct light, the solver's first "
                     "shot (as bake's --direct-rays); 0: off")
        ->capture_default_str();
    s.load
        ->add_option("--gather-rays", s.loadOptions.gatherRays,
                     "final gather rays per input vertex (as bake's --gather-rays: cached hits, "
                     "re-read after edits, traced again near what moved); 0: off")
        ->capture_default_str();
    s.load->add_option("--environment", s.loadOptions.environment,
                       "equirectangular OpenEXR sky under the server's scene root");
    s.load->add_option("--environment-color", s.skyColor, "a constant sky: r,g,b nits")
        ->delimiter(',')
        ->expected(3);
    s.load
        ->add_option("--environment-intensity", s.loadOptions.environmentIntensity,
                     "scales the sky")
        ->capture_default_str();
    s.load
        ->add_option("--environment-rotation", s.skyRotationDegrees,
                     "turns the sky about +Y, degrees")
        ->capture_default_str();

    s.info = app.add_subcommand("info", "Print the scene's nodes, lights and materials");

    s.watch = app.add_subcommand(
        "watch", "Subscribe and print each frame: number, edit id, ms, fps, edit latency");
    s.watch->add_option("--frames", s.watchFrames, "stop after this many frames (0: no limit)");
    s.watch->add_option("--timeout", s.timeout, "stop after this many seconds (0: no limit)");
    s.watch->add_flag("--until-converged", s.untilConverged,
                      "stop at the first converged frame (that includes --min-edit)");
    s.watch->add_option("--min-edit", s.minEdit,
                        "with --until-converged: the frame must include this edit id");
    s.watch->add_option("--channel", s.channel, "indirect|direct|total")->capture_default_str();
    s.watch->add_option("--format", s.format, "f32|f16")->capture_default_str();
    s.watch->add_flag("--json", s.watchJson,
                      "one JSON object per frame and line (scene, frame, edit, iterations, ms, "
                      "device_ms, fps, converged, note, latency_ms, passes)");

    s.move = app.add_subcommand(
        "move", "Move a dynamic node: new local = translate × current × rotate-y (or --matrix)");
    s.move->add_option("node", s.node, "node name")->required();
    s.move->add_option("--translate", s.translate, "x,y,z metres, in the parent's space")
        ->delimiter(',');
    s.move->add_option("--rotate-y", s.rotateY, "degrees about the node's own y axis");
    s.move->add_option("--matrix", s.matrix, "16 numbers, column-major: the new local transform")
        ->delimiter(',');

    s.light = app.add_subcommand(
        "light",
        "Change a light: a punctual light's colour, intensity, placement, cone and range, or an "
        "emissive node's colour × intensity");
    s.light->add_option("name", s.node, "punctual light (or its node) or emissive node")
        ->required();
    s.light->add_option("--intensity", s.intensity,
                        "cd (point, spot), lux (directional), or peak radiance in nits (emissive)");
    s.light->add_option("--color", s.color, "r,g,b (emissive: scaled so its peak is 1)")
        ->delimiter(',');
    s.light->add_option("--position", s.position, "x,y,z world position, metres (punctual)")
        ->delimiter(',');
    s.light->add_option("--direction", s.direction, "x,y,z where the light shines (punctual)")
        ->delimiter(',');
    s.light->add_option("--cone", s.cone, "inner,outer spot cone angles in degrees (≤ 90)")
        ->delimiter(',');
    s.light->add_option("--range", s.range, "metres, 0 = infinite (point, spot)");

    s.material = app.add_subcommand(
        "material", "Change a material's albedo (base colour), emission, roughness or metallic");
    s.material->add_option("name", s.node, "material name")->required();
    s.material->add_option("--albedo", s.albedo, "base colour r,g,b in [0, 1]")->delimiter(',');
    s.material->add_option("--roughness", s.roughness, "glTF roughness in [0, 1]");
    s.material->add_option("--metallic", s.metallic, "glTF metallic in [0, 1]");
    s.material->add_option("--emission", s.emission, "r,g,b nits")->delimiter(',');

    s.sky = app.add_subcommand("sky", "Change the loaded scene's sky (environment light)");
    s.sky->add_option("--environment", s.skyPath,
                      "a new equirectangular OpenEXR sky under the server's scene root");
    s.sky->add_option("--environment-color", s.skyColor, "a new constant sky: r,g,b nits")
        ->delimiter(',')
        ->expected(3);
    s.sky->add_flag("--off", s.skyOff, "no sky");
    s.sky->add_option("--environment-intensity", s.skyIntensity, "scales the sky (≥ 0)");
    s.sky->add_option("--environment-rotation", s.skyTurnDegrees,
                      "turns the sky about +Y, degrees");

    s.get = app.add_subcommand("get", "Write the current irradiance (.json, or .glb/.gltf)");
    s.get
        ->add_option("-o,--output", s.output,
                     "output: .json, .glb or .gltf; - for JSON on standard output")
        ->required();
    s.get->add_option("--gltf", s.gltf,
                      "the scene's glTF file, needed for .glb/.gltf output (_IRRADIANCE is added)");
    s.get
        ->add_option("--color0", s.color0,
                     "glTF out: COLOR_0 for viewers, none or tonemapped (the irradiance scaled so "
                     "the 99th percentile is 1, clamped to [0, 1])")
        ->capture_default_str();
    s.get->add_option("--channel", s.channel, "indirect|direct|total")->capture_default_str();

    s.step = app.add_subcommand("step", "Run N solver iterations now, as one frame");
    s.step->add_option("iterations", s.stepIterations, "iterations")->capture_default_str();

    s.stats = app.add_subcommand("stats", "Print server and scene statistics (JSON)");

    s.wait = app.add_subcommand(
        "wait", "Wait until a frame includes every edit sent so far and has converged");
    s.wait->add_option("--timeout", s.timeout, "seconds (default 60)");

    if (forScript) {
        s.sleep = app.add_subcommand("sleep", "Pause the script");
        s.sleep->add_option("seconds", s.sleepSeconds)->required();
    } else {
        s.script = app.add_subcommand(
            "script",
            "Run service commands from a file, one per line (docs/CLI.md); without --connect, "
            "on an embedded server that loads --scene");
        s.script->add_option("file", s.scriptFile, "script file ('-' for stdin)")->required();
        s.script->add_option("--scene", s.embeddedScene,
                             "glTF to load in an embedded in-process server (no --connect)");
        s.script->add_option("--device", s.device, "embedded server's device")
            ->capture_default_str();
        s.script->add_flag("-q,--quiet", s.quiet, "do not echo the script's lines");
    }
    for (CLI::App* c : {s.load, s.info, s.watch, s.move, s.light, s.material, s.sky, s.get, s.step,
                        s.stats, s.wait})
        c->add_flag("-q,--quiet", s.quiet, "print less");
}

ServiceCommands::~ServiceCommands() = default;

bool ServiceCommands::Parsed() const {
    for (CLI::App* c : {s_->load, s_->info, s_->watch, s_->move, s_->light, s_->material, s_->sky,
                        s_->get, s_->step, s_->stats, s_->script, s_->wait, s_->sleep})
        if (c && c->parsed()) return true;
    return false;
}

int ServiceCommands::Run() {
    State& s = *s_;
    try {
        std::unique_ptr<EmbeddedServer> embedded;
        std::string url = s.connect;
        if (url.empty()) {
            if (!(s.script && s.script->parsed() && !s.embeddedScene.empty()))
                throw Error(
                    "this command talks to a server: give --connect tcp://HOST:PORT (or "
                    "unix:///PATH), or run a script with --scene FILE on an embedded server");
            fs::path scene = fs::absolute(s.embeddedScene);
            if (!fs::is_regular_file(scene)) throw Error(s.embeddedScene + ": no such file");
            embedded = std::make_unique<EmbeddedServer>(scene.parent_path(), s.device);
            url = embedded->Url();
            client::Client c(url, "penumbra-cli");
            client::LoadOptions o;
            o.path = scene.filename().string();
            auto info = c.Load(o);
            if (!s.quiet)
                std::printf("embedded server: loaded %s (%u elements, %llu links, %.2f s, %s)\n",
                            info.scene.c_str(), info.elements, (unsigned long long)info.links,
                            info.buildSeconds, info.device.c_str());
            s.gltf = scene.string();
            return s.Execute(c);
        }
        client::Client c(url, "penumbra-cli");
        return s.Execute(c);
    } catch (const client::ClientError& e) {
        std::fprintf(stderr, "penumbra: %s%s\n", e.code() ? "refused: " : "", e.what());
        return e.code() ? kExitRefused : kExitConnection;
    } catch (const Error& e) {
        std::fprintf(stderr, "penumbra: error: %s\n", e.what());
        return kExitRefused;
    }
}

int ServiceCommands::State::Wait(client::Client& c, uint64_t edit, double timeoutSeconds) {
    auto deadline = Clock::now() + std::chrono::duration<double>(timeoutSeconds);
    while (true) {
        auto j = nlohmann::json::parse(c.Stats(session));
        // Stats of one scene ("" = the newest): {"scenes": [...]} or the scene itself.
        const nlohmann::json& sc = j.contains("scenes") ? j["scenes"].back() : j;
        if (sc["last_applied_edit"].get<uint64_t>() >= edit && sc["pending_edits"] == 0 &&
            !sc["rebuilding"].get<bool>() && sc["converged"].get<bool>())
            return kExitOk;
        if (Clock::now() > deadline) {
            std::fprintf(stderr, "penumbra: wait: timed out after %.1f s (edit %llu)\n",
                         timeoutSeconds, (unsigned long long)edit);
            return kExitTimeout;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
}

int ServiceCommands::State::Execute(client::Client& c) {
    if (load && load->parsed()) {
        client::LoadOptions o = loadOptions;
        if (skyColor.size() == 3) o.environmentColor = {skyColor[0], skyColor[1], skyColor[2]};
        o.environmentRotation = skyRotationDegrees * 0.017453292519943295f;
        if (upload) {
            std::ifstream in(loadPath, std::ios::binary);
            if (!in) throw Error(loadPath + ": cannot read");
            if (!IsGlbPath(loadPath)) throw Error("--upload sends binary glTF: give a .glb file");
            o.glb.assign(std::istreambuf_iterator<char>(in), {});
            o.name = fs::path(loadPath).filename().string();
        } else {
            o.path = loadPath;
        }
        auto info = c.Load(o);
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
            std::printf("  movable: %s\n  lights: %s\n",
                        dynamic.empty() ? "(none)" : dynamic.c_str(),
                        lights.empty() ? "(none)" : lights.c_str());
        return kExitOk;
    }
    if (info && info->parsed()) {
        auto i = c.Info(session);
        std::printf("scene %s: solver %s on %s, %u elements, %llu links\n", i.scene.c_str(),
                    i.solver.c_str(), i.device.c_str(), i.elements, (unsigned long long)i.links);
        for (const auto& n : i.nodes) {
            uint32_t vertices = 0;
            for (const auto& p : n.primitives) vertices += p.vertices;
            std::printf("  node %-20s %zu primitives, %u vertices%s%s\n", n.name.c_str(),
                        n.primitives.size(), vertices, n.dynamic ? ", dynamic" : "",
                        n.emissive ? ", light" : "");
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
    if (watch && watch->parsed()) {
        std::mutex m;
        std::condition_variable cv;
        int seen = 0;
        bool done = false;
        std::deque<Clock::time_point> arrivals;
        c.Subscribe(
            [&](const client::Frame& f) {
                std::lock_guard lock(m);
                if (done) return;
                auto now = Clock::now();
                arrivals.push_back(now);
                while (arrivals.size() > 10) arrivals.pop_front();
                double fps = 0.0;
                if (arrivals.size() > 1)
                    fps = (arrivals.size() - 1) /
                          std::chrono::duration<double>(arrivals.back() - arrivals.front()).count();
                PrintFrame(f, fps, watchJson);
                ++seen;
                if ((watchFrames > 0 && seen >= watchFrames) ||
                    (untilConverged && f.converged && f.lastEdit >= minEdit))
                    done = true;
                cv.notify_all();
            },
            ParseClientChannel(channel), ParseFormat(format), session);
        std::unique_lock lock(m);
        auto stop = [&] { return done || !c.Connected(); };
        if (timeout > 0.0) {
            if (!cv.wait_for(lock, std::chrono::duration<double>(timeout), stop)) {
                done = true;
                if (!quiet)  // on stderr when stdout is JSON Lines
                    std::fprintf(watchJson ? stderr : stdout, "watch: %.1f s passed, %d frames\n",
                                 timeout, seen);
                return kExitOk;
            }
        } else {
            while (!stop()) cv.wait_for(lock, std::chrono::milliseconds(200));
        }
        done = true;
        if (!c.Connected()) {
            std::fprintf(stderr, "penumbra: watch: the server closed the connection\n");
            return kExitConnection;
        }
        return kExitOk;
    }
    if (move && move->parsed()) {
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
    if (light && light->parsed()) {
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
        if (!quiet)
            std::printf("edit %llu: light %s\n", (unsigned long long)lastEdit, node.c_str());
        return kExitOk;
    }
    if (material && material->parsed()) {
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
        if (!quiet)
            std::printf("edit %llu: material %s\n", (unsigned long long)lastEdit, node.c_str());
        return kExitOk;
    }
    if (sky && sky->parsed()) {
        client::Client::EnvironmentChange change;
        change.path = skyPath;
        if (skyColor.size() == 3) change.color = {skyColor[0], skyColor[1], skyColor[2]};
        change.off = skyOff;
        change.intensity = skyIntensity;
        if (skyTurnDegrees) change.rotation = *skyTurnDegrees * 0.017453292519943295f;
        if (change.path.empty() && !change.color && !change.off && !change.intensity &&
            !change.rotation)
            throw Error(
                "sky: give --environment, --environment-color or --off, and/or "
                "--environment-intensity, --environment-rotation");
        lastEdit = c.SetEnvironment(change, session);
        if (!quiet) std::printf("edit %llu: sky\n", (unsigned long long)lastEdit);
        return kExitOk;
    }
    if (get && get->parsed()) {
        client::Frame f = c.Get(ParseClientChannel(channel), client::Format::kFloat32, session);
        // The bake formats: a Scene carries each primitive's key (and, for glTF output, its
        // geometry, read from the local file).
        Scene scene;
        bool json = output == "-" ||
                    (output.size() >= 5 && output.compare(output.size() - 5, 5, ".json") == 0);
        if (!json) {
            if (gltf.empty())
                throw Error("glTF output needs the scene file: add --gltf FILE (or write .json)");
            scene = LoadGltf(gltf);
            if (scene.primitives.size() != f.primitives.size())
                throw Error(gltf + " has " + std::to_string(scene.primitives.size()) +
                            " primitives, the server's scene " +
                            std::to_string(f.primitives.size()) + ": not the same scene");
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
            if (!json && rgb.size() != scene.primitives[p].positions.size() * 3)
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
    if (step && step->parsed()) {
        uint64_t frame = c.Step(stepIterations, session);
        if (!quiet) std::printf("frame %llu\n", (unsigned long long)frame);
        return kExitOk;
    }
    if (stats && stats->parsed()) {
        std::printf("%s\n", nlohmann::json::parse(c.Stats(session)).dump(2).c_str());
        return kExitOk;
    }
    if (wait && wait->parsed()) return Wait(c, lastEdit, timeout > 0.0 ? timeout : 60.0);
    if (sleep && sleep->parsed()) {
        if (!(sleepSeconds >= 0.0) || sleepSeconds > 3600) throw Error("sleep: 0…3600 seconds");
        std::this_thread::sleep_for(std::chrono::duration<double>(sleepSeconds));
        return kExitOk;
    }
    if (script && script->parsed()) return RunScript(c);
    return kExitOk;
}

int ServiceCommands::State::RunScript(client::Client& c) {
    std::ifstream file;
    std::istream* in = &std::cin;
    if (scriptFile != "-") {
        file.open(scriptFile);
        if (!file) throw Error(scriptFile + ": cannot read");
        in = &file;
    }
    std::string line;
    int number = 0;
    uint64_t lastSent = 0;
    while (std::getline(*in, line)) {
        ++number;
        size_t hash = line.find('#');
        if (hash != std::string::npos) line.resize(hash);
        std::vector<std::string> words;
        try {
            words = SplitWords(line);
        } catch (const Error& e) {
            throw Error(scriptFile + ":" + std::to_string(number) + ": " + e.what());
        }
        if (words.empty()) continue;
        CLI::App lineApp{"script line"};
        lineApp.require_subcommand(1);
        ServiceCommands commands(lineApp, /*forScript=*/true);
        State& ls = *commands.s_;
        std::vector<std::string> reversed(words.rbegin(), words.rend());
        try {
            lineApp.parse(reversed);
        } catch (const CLI::ParseError& e) {
            throw Error(scriptFile + ":" + std::to_string(number) + ": '" + line +
                        "': " + e.what());
        }
        ls.session = session;
        ls.gltf = ls.gltf.empty() ? gltf : ls.gltf;
        ls.lastEdit = lastSent;
        if (!quiet) std::printf("> %s\n", line.c_str());
        int rc;
        try {
            rc = ls.Execute(c);
        } catch (const client::ClientError& e) {
            if (e.code() == 0) throw;
            throw Error(scriptFile + ":" + std::to_string(number) + ": " + e.what());
        } catch (const Error& e) {
            throw Error(scriptFile + ":" + std::to_string(number) + ": " + e.what());
        }
        std::fflush(stdout);
        if (rc != kExitOk) return rc;
        lastSent = std::max(lastSent, ls.lastEdit);
    }
    return kExitOk;
}

}  // namespace penumbra::cli
