// Load and soak benchmark (issue 24): penumbra-server as a real process on loopback TCP with
// the office streaming continuously, for `--seconds` (10 minutes by default):
//   - 64 subscribers (client library, one connection each; channels and formats mixed);
//   - 4 editors, each its own kind of edit (a move, an emitter, a wall's colour, the sky)
//     every 0.5–1.5 s;
//   - `penumbra watch` as a child process, SIGKILLed every 30 s and started again;
//   - a subscriber that stops reading after its first frame;
//   - a client sending garbage: random bytes, or a frame header with a random payload, on a
//     new connection each time.
// Figures: frames delivered to each live subscriber, frames they lost (gaps in the frame
// numbers), p50/p99 frame interval, the server's RSS over the run (start, end, peak), its
// stats (frames sent, dropped, protocol errors) and whether it stayed up and exited cleanly on
// SIGTERM. Beside the frame rate, the relative RMSE of the final frame (every edit undone at
// the end) against `penumbra reference`. Prints a table and writes bench/results/soak.json.
#include <arpa/inet.h>
#include <netinet/in.h>
#include <signal.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <atomic>
#include <condition_variable>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <mutex>
#include <nlohmann/json.hpp>
#include <random>
#include <thread>

#include "bench_client.h"
#include "bench_util.h"
#include "output/compare.h"
#include "protocol/frame.h"
#include "scene/gltf_loader.h"

namespace penumbra {
namespace {

using bench::Clock;
using bench::Ms;
using bench::Percentile;
namespace fs = std::filesystem;

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

// VmRSS of a process in MiB (0 when it is gone).
double RssMiB(pid_t pid) {
    std::ifstream in("/proc/" + std::to_string(pid) + "/status");
    std::string line;
    while (std::getline(in, line))
        if (line.rfind("VmRSS:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
    return 0.0;
}

// Runs `argv` as a child process (stdout and stderr to `log`); its pid.
pid_t Spawn(const std::vector<std::string>& argv, const std::string& log) {
    std::fflush(stdout);  // else the child's freopen writes what is buffered a second time
    pid_t pid = fork();
    if (pid == 0) {
        std::vector<char*> args;
        for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
        args.push_back(nullptr);
        FILE* out = std::freopen(log.c_str(), "a", stdout);
        if (out) dup2(fileno(stdout), 2);
        execv(args[0], args.data());
        _exit(127);
    }
    if (pid < 0) throw std::runtime_error("fork failed");
    return pid;
}

// The server process: started on an ephemeral loopback port, its address read back.
struct ServerProcess {
    pid_t pid = -1;
    std::string url;
    uint16_t port = 0;
    fs::path dir;

    ServerProcess(const std::string& binary, const std::string& sceneRoot, int maxClients) {
        char tmpl[] = "/tmp/penumbra-soak-XXXXXX";
        dir = mkdtemp(tmpl);
        const std::string ready = (dir / "ready").string();
        pid = Spawn({binary, "--listen", "tcp://127.0.0.1:0", "--scene-root", sceneRoot, "--device",
                     "cpu", "--max-clients", std::to_string(maxClients), "--ready-file", ready},
                    (dir / "server.log").string());
        for (int i = 0; i < 500 && !fs::exists(ready); ++i)
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        std::ifstream in(ready);
        std::getline(in, url);
        if (url.rfind("tcp://", 0) != 0) throw std::runtime_error("the server did not start");
        port = static_cast<uint16_t>(std::stoi(url.substr(url.rfind(':') + 1)));
    }
    // Whether it is still running (false once it exited or died; `status` says how).
    bool Alive(int* status = nullptr) {
        if (pid < 0) return false;
        int s = 0;
        if (waitpid(pid, &s, WNOHANG) == pid) {
            pid = -1;
            if (status) *status = s;
            return false;
        }
        return true;
    }
    // SIGTERM, then its exit code (-1: no exit within 30 s, then SIGKILL).
    int Terminate() {
        if (pid < 0) return -1;
        kill(pid, SIGTERM);
        for (int i = 0; i < 1500; ++i) {
            int s = 0;
            if (waitpid(pid, &s, WNOHANG) == pid) {
                pid = -1;
                return WIFEXITED(s) ? WEXITSTATUS(s) : 128 + WTERMSIG(s);
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
        kill(pid, SIGKILL);
        waitpid(pid, nullptr, 0);
        pid = -1;
        return -1;
    }
    ~ServerProcess() {
        if (pid > 0) {
            kill(pid, SIGKILL);
            waitpid(pid, nullptr, 0);
        }
    }
};

// What one well-behaved subscriber saw.
struct Subscriber {
    std::mutex m;
    uint64_t frames = 0, lost = 0, repeated = 0, lastFrame = 0;
    std::vector<double> intervalsMs;
    Clock::time_point lastArrival;
    void operator()(const client::Frame& f) {
        const auto now = Clock::now();
        std::lock_guard lock(m);
        if (frames > 0) {
            intervalsMs.push_back(Ms(now - lastArrival));
            if (f.frame > lastFrame + 1) lost += f.frame - lastFrame - 1;
            if (f.frame <= lastFrame) ++repeated;
        }
        ++frames;
        lastFrame = std::max(lastFrame, f.frame);
        lastArrival = now;
    }
};

// A client that takes its first frame and then never returns from the callback: the
// client's reader stops, so the server's writes to it back up.
struct StuckReader {
    std::mutex m;
    std::condition_variable cv;
    bool release = false;
    uint64_t frames = 0;
    void operator()(const client::Frame&) {
        std::unique_lock lock(m);
        ++frames;
        cv.wait(lock, [&] { return release; });
    }
    void Release() {
        std::lock_guard lock(m);
        release = true;
        cv.notify_all();
    }
};

// Sends garbage on new connections until `stop`: random bytes, a well-formed header before a
// payload of noise, or half of such a frame and then nothing. Counts connections and how
// they ended after a second: closed by the server, or left open (waiting for the rest of a
// frame, which --frame-timeout bounds; the sender gives up first).
struct GarbageSender {
    uint64_t connections = 0, closedByServer = 0, leftOpen = 0, bytes = 0;
    void Run(uint16_t port, const std::atomic<bool>& stop) {
        std::mt19937 rng(24);
        while (!stop) {
            int fd = socket(AF_INET, SOCK_STREAM, 0);
            sockaddr_in a{};
            a.sin_family = AF_INET;
            a.sin_port = htons(port);
            a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
            timeval tv{1, 0};
            setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof(tv));
            if (connect(fd, reinterpret_cast<sockaddr*>(&a), sizeof(a)) == 0) {
                ++connections;
                std::vector<uint8_t> junk(1 + rng() % 4096);
                for (auto& b : junk) b = static_cast<uint8_t>(rng());
                const int kind = static_cast<int>(rng() % 3);
                if (kind > 0) {  // a real header (any type) before a payload that is noise
                    std::vector<uint8_t> frame;
                    const uint16_t type = static_cast<uint16_t>(1 + rng() % 41);
                    protocol::AppendFrame(frame, static_cast<protocol::MessageType>(type),
                                          static_cast<uint32_t>(rng()), junk);
                    if (kind == 2) frame.resize(frame.size() / 2);  // half a frame, then quiet
                    junk = std::move(frame);
                }
                bytes += junk.size();
                (void)!send(fd, junk.data(), junk.size(), MSG_NOSIGNAL);
                char buf[4096];
                ssize_t n;
                while ((n = recv(fd, buf, sizeof(buf), 0)) > 0) {
                }
                if (n == 0)
                    ++closedByServer;
                else
                    ++leftOpen;
            }
            close(fd);
            std::this_thread::sleep_for(std::chrono::milliseconds(50));
        }
    }
};

struct Options {
    double seconds = 600.0;
    int subscribers = 64, killEvery = 30, samples = 1024;
    std::string scene = "office.gltf", outDir = "bench/results", name = "soak";
    std::string server = std::string(PENUMBRA_BINARY_DIR) + "/penumbra-server";
    std::string cli = std::string(PENUMBRA_BINARY_DIR) + "/penumbra";
};

int Run(const Options& o) {
    const fs::path scenes = fs::path(PENUMBRA_SOURCE_DIR) / "scenes";
    ServerProcess server(o.server, scenes.string(), o.subscribers + 16);
    std::printf("penumbra-bench-soak: server %s (pid %d), %s, %.0f s, %d subscribers\n",
                server.url.c_str(), server.pid, o.scene.c_str(), o.seconds, o.subscribers);
    nlohmann::json out;
    out["device"] = "cpu (" + bench::CpuModel() + ", " +
                    std::to_string(std::thread::hardware_concurrency()) + " threads)";
    out["scene"] = o.scene;
    out["seconds"] = o.seconds;
    out["subscribers"] = o.subscribers;
    out["rss_mib_before_load"] = RssMiB(server.pid);

    // Load: the service's defaults, streaming continuously (every frame is one to deliver).
    client::Client loader(server.url, "soak-loader");
    client::LoadOptions load;
    load.path = o.scene;
    load.device = "cpu";
    load.convergedChange = 0.0f;
    const auto t0 = Clock::now();
    const client::SceneInfo info = loader.Load(load);
    out["load_s"] = Seconds(Clock::now() - t0);
    std::printf("  loaded in %.1f s; server RSS %.0f MiB\n", out["load_s"].get<double>(),
                RssMiB(server.pid));

    // What the editors change, and the values they put back at the end.
    const client::NodeInfo* mover = nullptr;
    for (const auto& n : info.nodes)
        if (n.dynamic && !mover) mover = &n;
    const client::MaterialInfo *emitter = nullptr, *wall = nullptr;
    for (const auto& m : info.materials) {
        const bool emits = m.emission[0] + m.emission[1] + m.emission[2] > 0.0f;
        if (emits && !emitter) emitter = &m;
        if (!emits && !wall) wall = &m;
    }
    if (!mover || !emitter || !wall)
        throw std::runtime_error(o.scene +
                                 ": needs a dynamic node, an emissive material and "
                                 "a material that does not emit");

    std::vector<std::unique_ptr<client::Client>> subClients;
    std::vector<std::unique_ptr<Subscriber>> subs;
    for (int i = 0; i < o.subscribers; ++i) {
        subClients.push_back(std::make_unique<client::Client>(server.url, "soak-sub"));
        subs.push_back(std::make_unique<Subscriber>());
        Subscriber* s = subs.back().get();
        const auto channel = i % 3 == 0 ? client::Channel::kTotal : client::Channel::kIndirect;
        const auto format = i % 2 ? client::Format::kFloat16 : client::Format::kFloat32;
        subClients.back()->Subscribe([s](const client::Frame& f) { (*s)(f); }, channel, format);
    }
    StuckReader stuck;
    client::Client stuckClient(server.url, "soak-stuck");
    stuckClient.Subscribe([&](const client::Frame& f) { stuck(f); });

    std::atomic<bool> stop{false};
    std::atomic<uint64_t> edits{0}, editErrors{0};
    std::vector<std::thread> threads;
    for (int e = 0; e < 4; ++e)
        threads.emplace_back([&, e] {
            client::Client c(server.url, "soak-editor");
            std::mt19937 rng(100 + e);
            for (int i = 0; !stop; ++i) {
                try {
                    const float s = i % 2 ? 1.0f : 0.7f;
                    if (e == 0) {
                        std::array<float, 16> m = mover->matrix;
                        m[12] += i % 2 ? 0.05f : -0.05f;
                        c.SetTransform(mover->name, m);
                    } else if (e == 1) {
                        c.SetMaterial(
                            emitter->name, std::nullopt,
                            std::array<float, 3>{emitter->emission[0] * s, emitter->emission[1] * s,
                                                 emitter->emission[2] * s});
                    } else if (e == 2) {
                        c.SetMaterial(wall->name,
                                      std::array<float, 3>{wall->albedo[0] * s, wall->albedo[1],
                                                           wall->albedo[2] * s},
                                      std::nullopt);
                    } else {
                        client::Client::EnvironmentChange sky;
                        sky.color = std::array<float, 3>{0.2f * s, 0.3f * s, 0.5f * s};
                        c.SetEnvironment(sky);
                    }
                    ++edits;
                } catch (const std::exception& ex) {
                    ++editErrors;
                    std::fprintf(stderr, "  editor %d: %s\n", e, ex.what());
                }
                std::this_thread::sleep_for(std::chrono::milliseconds(500 + rng() % 1000));
            }
            // Undo: the scene as loaded, for the accuracy check at the end.
            if (e == 0) c.SetTransform(mover->name, mover->matrix);
            if (e == 1) c.SetMaterial(emitter->name, std::nullopt, emitter->emission);
            if (e == 2) c.SetMaterial(wall->name, wall->albedo, std::nullopt);
            if (e == 3) {
                client::Client::EnvironmentChange sky;
                sky.off = true;
                c.SetEnvironment(sky);
            }
            c.Close();
        });
    GarbageSender garbage;
    threads.emplace_back([&] { garbage.Run(server.port, stop); });

    // The killed subscriber: `penumbra watch`, SIGKILLed every killEvery seconds.
    const std::string watchLog = (server.dir / "watch.log").string();
    auto startWatch = [&] {
        return Spawn({o.cli, "watch", "--connect", server.url, "--json"}, watchLog);
    };
    pid_t watcher = startWatch();
    int kills = 0;

    // The soak: RSS sampled every 2 s; the server must stay up.
    nlohmann::json rss = nlohmann::json::array();
    const auto start = Clock::now();
    auto nextKill = start + std::chrono::seconds(o.killEvery);
    bool crashed = false;
    int lastPrint = -1;
    while (Clock::now() - start < std::chrono::duration<double>(o.seconds)) {
        std::this_thread::sleep_for(std::chrono::seconds(2));
        int status = 0;
        if (!server.Alive(&status)) {
            crashed = true;
            std::printf("  the server died (status %d) at %.0f s\n", status,
                        Seconds(Clock::now() - start));
            break;
        }
        const double t = Seconds(Clock::now() - start);
        rss.push_back({{"s", t}, {"mib", RssMiB(server.pid)}});
        if (Clock::now() >= nextKill) {
            kill(watcher, SIGKILL);
            waitpid(watcher, nullptr, 0);
            ++kills;
            watcher = startWatch();
            nextKill += std::chrono::seconds(o.killEvery);
        }
        if (int(t) / 60 != lastPrint) {
            lastPrint = int(t) / 60;
            std::printf("  %4.0f s: RSS %.0f MiB, %llu edits, subscriber 0 has %llu frames\n", t,
                        rss.back()["mib"].get<double>(), (unsigned long long)edits.load(),
                        (unsigned long long)subs[0]->frames);
            std::fflush(stdout);
        }
    }
    const double soakSeconds = Seconds(Clock::now() - start);
    stop = true;
    for (auto& t : threads) t.join();
    kill(watcher, SIGKILL);
    waitpid(watcher, nullptr, 0);
    stuck.Release();

    nlohmann::json figures;
    if (!crashed) {
        // The final frame, every edit undone, against the reference at the same settings.
        nlohmann::json stats = nlohmann::json::parse(loader.Stats());
        figures["server_stats"] = stats["server"];
        std::this_thread::sleep_for(std::chrono::seconds(5));  // bounces after the undo
        const client::Frame last = loader.Get(client::Channel::kIndirect);
        std::vector<uint64_t> frames, lost;
        std::vector<double> intervals;
        uint64_t repeated = 0, disconnected = 0;
        for (size_t i = 0; i < subs.size(); ++i) {
            std::lock_guard lock(subs[i]->m);
            frames.push_back(subs[i]->frames);
            lost.push_back(subs[i]->lost);
            repeated += subs[i]->repeated;
            disconnected += subClients[i]->Connected() ? 0 : 1;
            intervals.insert(intervals.end(), subs[i]->intervalsMs.begin(),
                             subs[i]->intervalsMs.end());
        }
        for (auto& c : subClients) c->Close();
        stuckClient.Close();
        loader.Close();
        const int exitCode = server.Terminate();
        const double rssStart = rss.empty() ? 0.0 : rss.front()["mib"].get<double>();
        const double rssEnd = rss.empty() ? 0.0 : rss.back()["mib"].get<double>();
        double rssPeak = 0.0, rssHalf = 0.0;
        for (const auto& r : rss) {
            rssPeak = std::max(rssPeak, r["mib"].get<double>());
            if (r["s"].get<double>() <= soakSeconds / 2) rssHalf = r["mib"].get<double>();
        }
        auto sum = [](const std::vector<uint64_t>& v) {
            uint64_t s = 0;
            for (auto x : v) s += x;
            return s;
        };
        std::vector<double> perSub(frames.begin(), frames.end());
        figures["soak_s"] = soakSeconds;
        figures["frames_per_subscriber"] = {
            {"min", *std::min_element(frames.begin(), frames.end())},
            {"median", bench::Median(perSub)},
            {"max", *std::max_element(frames.begin(), frames.end())}};
        figures["frames_lost_by_subscribers"] = sum(lost);
        figures["frames_repeated"] = repeated;
        figures["subscribers_disconnected"] = disconnected;
        figures["frame_interval_ms"] = {{"p50", Percentile(intervals, 0.5)},
                                        {"p99", Percentile(intervals, 0.99)},
                                        {"max", Percentile(intervals, 1.0)}};
        figures["fps_per_subscriber_median"] = bench::Median(perSub) / soakSeconds;
        figures["edits"] = edits.load();
        figures["edit_errors"] = editErrors.load();
        figures["watch_kills"] = kills;
        figures["stuck_reader_frames"] = stuck.frames;
        figures["garbage"] = {{"connections", garbage.connections},
                              {"closed_by_server", garbage.closedByServer},
                              {"left_open_after_1s", garbage.leftOpen},
                              {"bytes", garbage.bytes}};
        figures["rss_mib"] = {{"start", rssStart},
                              {"half_time", rssHalf},
                              {"end", rssEnd},
                              {"peak", rssPeak},
                              {"second_half_growth", rssEnd - rssHalf}};
        figures["server_exit_code_on_sigterm"] = exitCode;
        figures["crashes"] = 0;

        std::printf("\n  %-34s %s\n", "figure", "value");
        std::printf("  %-34s %.0f s\n", "soak", soakSeconds);
        std::printf("  %-34s %llu / %.0f / %llu\n", "frames per subscriber min/med/max",
                    (unsigned long long)*std::min_element(frames.begin(), frames.end()),
                    bench::Median(perSub),
                    (unsigned long long)*std::max_element(frames.begin(), frames.end()));
        std::printf("  %-34s %.2f\n", "fps per subscriber (median)",
                    figures["fps_per_subscriber_median"].get<double>());
        std::printf("  %-34s %.1f / %.1f ms\n", "frame interval p50 / p99",
                    Percentile(intervals, 0.5), Percentile(intervals, 0.99));
        std::printf("  %-34s %llu (%llu disconnected)\n", "frames lost by subscribers",
                    (unsigned long long)sum(lost), (unsigned long long)disconnected);
        std::printf("  %-34s %llu (%llu failed)\n", "edits", (unsigned long long)edits.load(),
                    (unsigned long long)editErrors.load());
        std::printf("  %-34s %d\n", "watch processes SIGKILLed", kills);
        std::printf("  %-34s %llu (%llu closed by the server)\n", "garbage connections",
                    (unsigned long long)garbage.connections,
                    (unsigned long long)garbage.closedByServer);
        std::printf("  %-34s %llu sent, %llu dropped\n", "server frames",
                    (unsigned long long)stats["server"].value("frames_sent", uint64_t(0)),
                    (unsigned long long)stats["server"].value("frames_dropped", uint64_t(0)));
        std::printf("  %-34s %.0f → %.0f MiB (peak %.0f; second half %+.1f)\n", "server RSS",
                    rssStart, rssEnd, rssPeak, rssEnd - rssHalf);
        std::printf("  %-34s %d\n", "exit code on SIGTERM", exitCode);
        if (o.samples > 0) {
            const IrradianceFile truth =
                bench::Reference(LoadGltf((scenes / o.scene).string()), o.samples);
            const double rmse = Compare(bench::FrameToFile(last), truth).overall.relRmse;
            figures["rel_rmse"] = rmse;
            figures["rmse_frame_iterations"] = last.iterations;
            figures["reference_samples"] = o.samples;
            std::printf("  %-34s %.1f%% (frame %llu, %d reference paths)\n",
                        "rel. RMSE of the final frame", 100.0 * rmse,
                        (unsigned long long)last.frame, o.samples);
        }
    } else {
        figures["crashes"] = 1;
    }
    figures["rss_samples"] = rss;
    out["figures"] = figures;
    bench::WriteReport(out, o.outDir, o.name + ".json");
    return crashed ? 1 : 0;
}

}  // namespace
}  // namespace penumbra

int main(int argc, char** argv) {
    penumbra::Options o;
    CLI::App app{"penumbra-bench-soak: a live server under many clients, edits and abuse"};
    app.add_option("--seconds", o.seconds, "length of the soak")->capture_default_str();
    app.add_option("--subscribers", o.subscribers, "well-behaved subscribers")
        ->capture_default_str();
    app.add_option("--kill-every", o.killEvery, "seconds between SIGKILLs of `penumbra watch`")
        ->capture_default_str();
    app.add_option("--scene", o.scene, "glTF under scenes/")->capture_default_str();
    app.add_option("--samples", o.samples, "reference paths per vertex for the RMSE (0: none)")
        ->capture_default_str();
    app.add_option("--out", o.outDir, "results folder (empty: print only)")->capture_default_str();
    app.add_option("--name", o.name, "results go to OUT/NAME.json")->capture_default_str();
    app.add_option("--server", o.server, "penumbra-server program")->capture_default_str();
    app.add_option("--cli", o.cli, "penumbra program")->capture_default_str();
    CLI11_PARSE(app, argc, argv);
    std::signal(SIGPIPE, SIG_IGN);
    try {
        return penumbra::Run(o);
    } catch (const std::exception& e) {
        std::fprintf(stderr, "penumbra-bench-soak: %s\n", e.what());
        return 1;
    }
}
