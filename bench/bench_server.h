// Shared by the benchmarks that run penumbra's server in their own process (bench_service,
// bench_stream): the service and its socket server on a private Unix socket, with its I/O
// thread.
#pragma once

#include <stdlib.h>

#include <asio.hpp>
#include <filesystem>
#include <string>
#include <thread>

#include "net/server.h"
#include "service/service.h"

namespace penumbra::bench {

// A server with its I/O thread, on a private Unix socket.
struct InProcessServer {
    asio::io_context io;
    service::Service service;
    net::Server server;
    std::string url;
    std::thread thread;
    std::filesystem::path dir;

    explicit InProcessServer(const std::filesystem::path& root)
        : service(root, service::ServiceLimits{}), server(io, service, Limits()) {
        char tmpl[] = "/tmp/penumbra-bench-XXXXXX";
        dir = mkdtemp(tmpl);
        net::ListenAddress a;
        a.kind = net::ListenAddress::Kind::kUnix;
        a.path = (dir / "s.sock").string();
        url = server.Listen(a);
        thread = std::thread([this] { io.run(); });
    }
    // Room for a benchmark's many subscribers beside its editors.
    static net::NetLimits Limits() {
        net::NetLimits limits;
        limits.maxClients = 256;
        return limits;
    }
    ~InProcessServer() {
        asio::post(io, [this] {
            server.Stop();
            io.stop();
        });
        thread.join();
        std::filesystem::remove_all(dir);
    }
};

}  // namespace penumbra::bench
