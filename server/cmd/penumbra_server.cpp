// penumbra-server: keeps scenes resident on the device and streams per-vertex irradiance to
// clients over TCP and Unix sockets (protocol/SPEC.md). Only wiring lives here.
#include <CLI/CLI.hpp>
#ifdef __GLIBC__
#include <malloc.h>
#endif
#include <cctype>
#include <csignal>
#include <cstdio>
#include <fstream>
#include <iostream>

#include "base/check.h"
#include "net/server.h"
#include "service/service.h"

int main(int argc, char** argv) {
    using namespace penumbra;
#ifdef __GLIBC__
    // glibc's default thresholds grow with the largest block freed (up to 32 MiB mmapped, a
    // 64 MiB heap top kept), and each thread that builds or runs a scene gets an arena of its
    // own: a server whose scenes come and go would keep tens of MiB per arena that no
    // malloc_trim returns. Fixed ones put blocks of a MiB and more in their own mappings and
    // trim a heap's top past 2 MiB, so the server's memory falls back once a scene is dropped,
    // while a frame's smaller buffers are still reused from the heap.
    mallopt(M_MMAP_THRESHOLD, 1 << 20);
    mallopt(M_TRIM_THRESHOLD, 2 << 20);
#endif
    CLI::App app{"penumbra-server: a headless lighting service (protocol/SPEC.md)"};
    std::vector<std::string> listen;
    std::string sceneRoot = ".", device = "auto", readyFile;
    bool allowRemote = false, quiet = false;
    net::NetLimits netLimits;
    service::ServiceLimits serviceLimits;
    app.add_option("--listen", listen,
                   "tcp://HOST:PORT or unix:///PATH; repeat for several (default "
                   "tcp://127.0.0.1:7450)");
    app.add_option("--scene-root", sceneRoot, "folder that LoadScene paths are relative to")
        ->check(CLI::ExistingDirectory);
    app.add_flag("--allow-remote", allowRemote, "allow TCP addresses other than loopback");
    app.add_option("--device", device, "default solver device: auto|gpu|lavapipe|cpu");
    app.add_option("--max-clients", netLimits.maxClients, "connections at once")
        ->capture_default_str()
        ->check(CLI::Range(1, 100000));
    app.add_option("--max-clients-per-address", netLimits.maxClientsPerAddress,
                   "connections at once from one TCP peer address (Unix socket clients are "
                   "not counted)")
        ->capture_default_str()
        ->check(CLI::Range(1, 100000));
    app.add_option("--max-frame-bytes", netLimits.maxFrameBytes,
                   "largest request payload accepted (bytes)")
        ->capture_default_str()
        ->check(CLI::Range(uint32_t(1024), protocol::kMaxPayloadCeiling));
    app.add_option("--frame-timeout", netLimits.frameTimeoutSeconds,
                   "seconds a frame may take to arrive whole from its first byte (0: no limit)")
        ->capture_default_str()
        ->check(CLI::Range(0.0, 86400.0));
    app.add_option("--hello-timeout", netLimits.helloTimeoutSeconds,
                   "seconds a new connection has to complete its Hello (0: no limit)")
        ->capture_default_str()
        ->check(CLI::Range(0.0, 86400.0));
    app.add_option("--idle-timeout", netLimits.idleTimeoutSeconds,
                   "seconds a connection may send nothing while it has no subscription and no "
                   "request in progress (0: no limit)")
        ->capture_default_str()
        ->check(CLI::Range(0.0, 86400.0));
    app.add_option("--max-scenes", serviceLimits.maxScenes, "scenes loaded at once")
        ->capture_default_str()
        ->check(CLI::Range(1, 1000));
    app.add_option("--max-scenes-per-client", serviceLimits.maxScenesPerClient,
                   "scenes one connection may have built and hold at once (joins do not count)")
        ->capture_default_str()
        ->check(CLI::Range(1, 1000));
    app.add_option("--scene-idle-timeout", serviceLimits.sceneIdleSeconds,
                   "seconds a scene may stay loaded with no connected client that loaded or "
                   "joined it and no subscriber; then it is dropped (0: kept until "
                   "--max-scenes needs room)")
        ->capture_default_str()
        ->check(CLI::Range(0.0, 31536000.0));
    app.add_option("--max-scene-bytes", serviceLimits.maxSceneBytes,
                   "largest sum of buffers a scene file may declare (checked before reading)")
        ->capture_default_str();
    app.add_option("--max-scene-triangles", serviceLimits.maxSceneTriangles,
                   "largest scene accepted (input triangles)")
        ->capture_default_str();
    std::string metrics;
    app.add_option("--metrics", metrics,
                   "tcp://HOST:PORT: serve HTTP there for a supervisor: /metrics (Prometheus "
                   "text), /healthz, /readyz (docs/SERVICE.md)");
    app.add_option("--ready-file", readyFile,
                   "write the bound addresses here, one per line, once listening");
    std::string moves = "bounds";
    app.add_option("--moves", moves,
                   "how moves of dynamic nodes are taken: bounds (links built for the motion "
                   "bounds, updated in place; Sec. 3.3) or rebuild (every move rebuilds the links)")
        ->capture_default_str()
        ->check(CLI::IsMember({"bounds", "rebuild"}));
    std::string tokenFile;
    app.add_option("--token-file", tokenFile,
                   "every client must give one of this file's tokens in Hello, which gives it a "
                   "role: a line \"ROLE TOKEN\" (viewer, editor or admin) or the token alone "
                   "(editor); for servers reachable from other machines (--allow-remote)")
        ->check(CLI::ExistingFile);
    app.add_flag("-q,--quiet", quiet, "no log lines on stderr");
    CLI11_PARSE(app, argc, argv);
    if (listen.empty()) listen.push_back("tcp://127.0.0.1:7450");
    serviceLimits.maxUploadBytes = netLimits.maxFrameBytes;
    netLimits.log = !quiet;
    if (!tokenFile.empty()) {
        try {
            netLimits.tokens = net::ReadTokenFile(tokenFile);
        } catch (const std::exception& e) {
            std::fprintf(stderr, "penumbra-server: error: %s\n", e.what());
            return 2;
        }
    }

    try {
        SolverSettings defaults = service::ServiceDefaults();
        defaults.device = ParseDevice(device);
        defaults.prepareMoves = moves == "bounds";
        service::Service service(sceneRoot, serviceLimits, defaults);
        asio::io_context io;
        net::Server server(io, service, netLimits);
        std::vector<std::string> bound;
        for (const auto& url : listen)
            bound.push_back(server.Listen(net::ParseListenAddress(url), allowRemote));
        if (!metrics.empty())
            bound.push_back(server.ListenMetrics(net::ParseListenAddress(metrics), allowRemote));

        asio::signal_set signals(io, SIGINT, SIGTERM);
        signals.async_wait([&](std::error_code ec, int signal) {
            if (ec) return;
            if (!quiet)
                std::fprintf(stderr, "penumbra-server: %s, shutting down\n",
                             signal == SIGTERM ? "SIGTERM" : "SIGINT");
            server.Stop();
            io.stop();
        });
        std::signal(SIGPIPE, SIG_IGN);  // a vanished client is a write error, not a crash

        if (!quiet) {
            for (const auto& b : bound)
                std::fprintf(stderr, "penumbra-server: listening on %s\n", b.c_str());
            std::fprintf(stderr, "penumbra-server: scene root %s\n", sceneRoot.c_str());
        }
        if (!readyFile.empty()) {
            std::string tmp = readyFile + ".tmp";
            {
                std::ofstream out(tmp);
                for (const auto& b : bound) out << b << "\n";
            }
            std::rename(tmp.c_str(), readyFile.c_str());  // appears complete or not at all
        }
        io.run();
        if (!quiet) std::fprintf(stderr, "penumbra-server: stopped\n");
    } catch (const Error& e) {
        std::fprintf(stderr, "penumbra-server: %s\n", e.what());
        return 2;
    } catch (const std::exception& e) {
        std::fprintf(stderr, "penumbra-server: internal error: %s\n", e.what());
        return 3;
    }
    return 0;
}
