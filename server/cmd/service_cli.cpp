// Service commands of the CLI: their arguments, the embedded server, the dispatch to one
// function per command (service_commands.cpp) and scripts. The protocol work is the client
// library's.
#include "cmd/service_cli.h"

#include <unistd.h>

#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <glm/gtc/matrix_transform.hpp>
#include <mutex>
#include <nlohmann/json.hpp>
#include <sstream>
#include <thread>

#include "base/check.h"
#include "client/client.h"
#include "cmd/service_state.h"
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
}  // namespace

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

    AddLoad(app);
    AddWatch(app);
    AddObjectEdits(app);
    AddLightEdits(app);
    AddReads(app);
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
    for (CLI::App* c : {s.load, s.info, s.watch, s.move, s.deform, s.light, s.material, s.sky,
                        s.get, s.step, s.stats, s.wait, s.unload})
        c->add_flag("-q,--quiet", s.quiet, "print less");
}

// `load`: the scene, its solver and what the server does with it.
void ServiceCommands::AddLoad(CLI::App& app) {
    State& s = *s_;
    s.load = app.add_subcommand("load", "Load a scene on the server (or join its session)");
    s.load->add_option("path", s.loadPath, "glTF path under the server's --scene-root")->required();
    s.load->add_flag("--upload", s.upload, "send the local file as a .glb instead of a path");
    AddSolverOptions(s.load, s.loadOptions.solver, s.loadOptions.solverOptions);
    s.load
        ->add_option("--iterations-per-frame", s.loadOptions.iterationsPerFrame,
                     "solver iterations per streamed frame")
        ->capture_default_str();
    s.load->add_option("--element-size", s.loadOptions.elementSize,
                       "metres (0: scene diameter / 24 behind the final gather, / 40 without)");
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
    auto* sun = s.load
                    ->add_option("--sun", s.sun,
                                 "a sun on a node 'sun': azimuth (degrees from north, -Z, "
                                 "towards east, +X), elevation (degrees), lux, e.g. 135,30,80000")
                    ->delimiter(',')
                    ->expected(3);
    s.load->add_option("--sky", s.skyModel, "clear: Preetham's clear sky for the --sun position")
        ->check(CLI::IsMember({"clear"}))
        ->needs(sun);
    s.load->add_option("--turbidity", s.turbidity, "the clear sky's, 1.7 … 10 (default 3)");
    s.load
        ->add_option("--refine", s.loadOptions.refine,
                     "refined output: triangles subdivided until no edge is longer than this "
                     "many metres; frames carry values on the refined meshes (0: the file's "
                     "vertices)")
        ->check(CLI::Range(0.0f, 1e30f));
}

// `info` and `watch`.
void ServiceCommands::AddWatch(CLI::App& app) {
    State& s = *s_;
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
    s.watch
        ->add_option("--format", s.format,
                     "delta (only the vertices that drifted past --tolerance travel; "
                     "protocol/SPEC.md \"Delta frames\"), f32 or f16 (every frame whole)")
        ->capture_default_str();
    s.watch
        ->add_option("--tolerance", s.tolerance,
                     "a delta stream's relative tolerance (0: every change of a vertex's "
                     "fp16 value)")
        ->capture_default_str()
        ->check(CLI::Range(0.0f, 1.0f));
    s.watch->add_flag("--json", s.watchJson,
                      "one JSON object per frame and line (scene, frame, edit, iterations, ms, "
                      "device_ms, fps, converged, note, bytes, keyframe, latency_ms, passes)");
}

// `move` and `deform`.
void ServiceCommands::AddObjectEdits(CLI::App& app) {
    State& s = *s_;
    s.move = app.add_subcommand(
        "move", "Move a dynamic node: new local = translate × current × rotate-y (or --matrix)");
    s.move->add_option("node", s.node, "node name")->required();
    s.move->add_option("--translate", s.translate, "x,y,z metres, in the parent's space")
        ->delimiter(',');
    s.move->add_option("--rotate-y", s.rotateY,
                       "degrees about the node's own y axis (its local frame's: the world's up "
                       "only when neither it nor a parent is turned)");
    s.move->add_option("--matrix", s.matrix, "16 numbers, column-major: the new local transform")
        ->delimiter(',');

    s.deform = app.add_subcommand(
        "deform",
        "Deform a dynamic node's mesh: pose its morph targets (--weights) or give its vertices "
        "(--vertices)");
    s.deform->add_option("node", s.node, "node name")->required();
    auto* weights = s.deform
                        ->add_option("--weights", s.weights,
                                     "w1,w2,...: one weight a morph target (`info` lists them)")
                        ->delimiter(',');
    s.deform
        ->add_option("--vertices", s.verticesFile,
                     "JSON file {\"positions\": [x,y,z,...], \"normals\": [...] (optional)}: "
                     "the node's vertices in its own space, its primitives' one after another")
        ->excludes(weights);
}

// `light`, `material` and `sky`.
void ServiceCommands::AddLightEdits(CLI::App& app) {
    State& s = *s_;
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
    s.sky
        ->add_option("--sun", s.sun,
                     "moves the scene's sun: azimuth,elevation (degrees)[,lux]; a clear sky "
                     "follows it")
        ->delimiter(',')
        ->expected(2, 3);
    s.sky->add_option("--sky", s.skyModel, "clear: a new clear sky for the sun")
        ->check(CLI::IsMember({"clear"}));
    s.sky->add_option("--turbidity", s.turbidity, "the clear sky's, 1.7 … 10");
}

// `get`, `step`, `stats` and `wait`.
void ServiceCommands::AddReads(CLI::App& app) {
    State& s = *s_;
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

    s.unload = app.add_subcommand(
        "unload",
        "Drop the scene (--session, else this client's or the newest) from the server: its "
        "owner's while that client is connected, anyone's once it has gone");
}

ServiceCommands::~ServiceCommands() = default;

bool ServiceCommands::Parsed() const {
    for (CLI::App* c :
         {s_->load, s_->info, s_->watch, s_->move, s_->deform, s_->light, s_->material, s_->sky,
          s_->get, s_->step, s_->stats, s_->script, s_->wait, s_->sleep, s_->unload})
        if (c && c->parsed()) return true;
    return false;
}

namespace {

// The token on the first line of the file PENUMBRA_TOKEN_FILE names (a server started with
// --token-file asks for it in Hello): the line's last word, so that a line of the server's
// file ("editor TOKEN") serves as it is; empty when the variable is not set.
std::string TokenFromEnvironment() {
    const char* path = std::getenv("PENUMBRA_TOKEN_FILE");
    if (!path || !*path) return {};
    std::ifstream in(path);
    if (!in) throw Error(std::string(path) + " (PENUMBRA_TOKEN_FILE): cannot read");
    std::string line, token;
    std::getline(in, line);
    std::istringstream words(line);
    for (std::string word; words >> word;) token = word;
    return token;
}

}  // namespace

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
        client::Client c(url, "penumbra-cli", TokenFromEnvironment());
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
    using Command = int (State::*)(client::Client&);
    const std::pair<CLI::App*, Command> commands[] = {
        {load, &State::RunLoad},         {info, &State::RunInfo},     {watch, &State::RunWatch},
        {move, &State::RunMove},         {deform, &State::RunDeform}, {light, &State::RunLight},
        {material, &State::RunMaterial}, {sky, &State::RunSky},       {get, &State::RunGet},
        {step, &State::RunStep},         {stats, &State::RunStats},   {sleep, &State::RunSleep},
        {script, &State::RunScript},     {wait, &State::RunWait},     {unload, &State::RunUnload},
    };
    for (const auto& [command, run] : commands)
        if (command && command->parsed()) return (this->*run)(c);
    return kExitOk;
}

int ServiceCommands::State::RunWait(client::Client& c) {
    return Wait(c, lastEdit, timeout > 0.0 ? timeout : 60.0);
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
        CLI::App lineApp{"script line"};
        ServiceCommands commands(lineApp, /*forScript=*/true);
        State& ls = *commands.s_;
        if (!ParseScriptLine(line, scriptFile + ":" + std::to_string(number), lineApp)) continue;
        const size_t hash = line.find('#');
        if (hash != std::string::npos) line.resize(hash);
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

bool ParseScriptLine(const std::string& text, const std::string& where, CLI::App& app) {
    std::string line = text;
    const size_t hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    std::vector<std::string> words;
    try {
        words = SplitWords(line);
    } catch (const Error& e) {
        throw Error(where + ": " + e.what());
    }
    if (words.empty()) return false;
    app.require_subcommand(1);
    std::vector<std::string> reversed(words.rbegin(), words.rend());
    try {
        app.parse(reversed);
    } catch (const CLI::ParseError& e) {
        throw Error(where + ": '" + line + "': " + e.what());
    }
    return true;
}

}  // namespace penumbra::cli
