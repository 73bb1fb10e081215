// The server's HTTP endpoints for a supervisor (server.h, ListenMetrics): Prometheus text at
// /metrics, liveness at /healthz, readiness at /readyz. One request a connection, read within
// a few seconds and at most a few kilobytes, answered and closed: a client that never speaks
// or sends more costs one socket for those seconds, not the service.
#include <asio.hpp>
#include <memory>
#include <sstream>
#include <string>

#include "net/server.h"

namespace penumbra::net {
namespace {

constexpr size_t kMostRequestBytes = 8192;
constexpr auto kRequestTime = std::chrono::seconds(5);

// One metric's HELP and TYPE lines, then its samples.
void Family(std::ostringstream& out, const std::string& name, const char* type, const char* help) {
    out << "# HELP " << name << " " << help << "\n# TYPE " << name << " " << type << "\n";
}

// A label value escaped as the text format asks (backslash, quote, newline).
std::string Label(const std::string& value) {
    std::string out;
    for (char c : value) {
        if (c == '\\' || c == '"') out += '\\';
        out += c == '\n' ? 'n' : c;
        if (c == '\n') out.insert(out.size() - 1, 1, '\\');
    }
    return out;
}

struct Exchange : std::enable_shared_from_this<Exchange> {
    Exchange(Server& server, asio::ip::tcp::socket socket)
        : server(server), socket(std::move(socket)), timer(this->socket.get_executor()) {}

    void Start() {
        auto self = shared_from_this();
        timer.expires_after(kRequestTime);
        timer.async_wait([self](std::error_code ec) {
            if (!ec) self->socket.close(ec);  // no whole request in time
        });
        asio::async_read_until(socket, asio::dynamic_buffer(request, kMostRequestBytes), "\r\n\r\n",
                               [self](std::error_code ec, size_t) {
                                   if (ec) {
                                       self->Answer(400, "a request line and headers within " +
                                                             std::to_string(kMostRequestBytes) +
                                                             " bytes\n");
                                       return;
                                   }
                                   self->Route();
                               });
    }

    void Route() {
        std::istringstream line(request.substr(0, request.find("\r\n")));
        std::string method, target;
        line >> method >> target;
        if (method != "GET") return Answer(405, "only GET\n");
        if (target == "/metrics") return Answer(200, server.MetricsText(), true);
        if (target == "/healthz") return Answer(200, "ok\n");
        if (target == "/readyz")
            return server.Stopping() ? Answer(503, "shutting down\n") : Answer(200, "ready\n");
        Answer(404, "endpoints: /metrics, /healthz, /readyz\n");
    }

    void Answer(int status, const std::string& body, bool prometheus = false) {
        const char* reason = status == 200   ? "OK"
                             : status == 404 ? "Not Found"
                             : status == 405 ? "Method Not Allowed"
                             : status == 503 ? "Service Unavailable"
                                             : "Bad Request";
        response =
            "HTTP/1.1 " + std::to_string(status) + " " + reason +
            "\r\nContent-Type: " + (prometheus ? "text/plain; version=0.0.4" : "text/plain") +
            "\r\nContent-Length: " + std::to_string(body.size()) + "\r\nConnection: close\r\n\r\n" +
            body;
        auto self = shared_from_this();
        asio::async_write(socket, asio::buffer(response), [self](std::error_code ec, size_t) {
            self->timer.cancel();
            self->socket.shutdown(asio::ip::tcp::socket::shutdown_both, ec);
            self->socket.close(ec);
        });
    }

    Server& server;
    asio::ip::tcp::socket socket;
    asio::steady_timer timer;
    std::string request, response;
};

}  // namespace

std::string Server::ListenMetrics(const ListenAddress& address, bool allowRemote) {
    if (address.kind != ListenAddress::Kind::kTcp)
        throw Error("--metrics takes a tcp://HOST:PORT address (it serves HTTP)");
    auto acceptor = OpenTcp(address, allowRemote);
    metrics_.push_back(acceptor);
    AcceptMetrics(acceptor);
    return "http://" + BoundHostPort(*acceptor);
}

void Server::AcceptMetrics(std::shared_ptr<asio::ip::tcp::acceptor> acceptor) {
    acceptor->async_accept([this, acceptor](std::error_code ec, asio::ip::tcp::socket socket) {
        if (stopping_ || !acceptor->is_open()) return;
        if (!ec) std::make_shared<Exchange>(*this, std::move(socket))->Start();
        AcceptMetrics(acceptor);
    });
}

std::string Server::MetricsText() const {
    const nlohmann::json net = StatsJson();
    const nlohmann::json service = service_.StatsJson();
    std::ostringstream out;
    auto number = [](const nlohmann::json& j, const char* key) {
        return j.contains(key) && j[key].is_number() ? j[key].get<double>() : 0.0;
    };
    Family(out, "penumbra_clients", "gauge", "Connected clients.");
    out << "penumbra_clients " << number(net, "clients") << "\n";
    const nlohmann::json scenes =
        service.contains("scenes") ? service["scenes"] : nlohmann::json::array();
    Family(out, "penumbra_scenes", "gauge", "Scenes loaded.");
    out << "penumbra_scenes " << scenes.size() << "\n";
    for (const auto& [name, key, help] :
         {std::tuple{"penumbra_frames_sent_total", "frames_sent", "Frames written to clients."},
          {"penumbra_frames_dropped_total", "frames_dropped",
           "Frames not sent to a client that was behind (it got a newer one)."},
          {"penumbra_protocol_errors_total", "protocol_errors",
           "Connections closed for a framing error."},
          {"penumbra_forbidden_requests_total", "forbidden_requests",
           "Requests refused for the connection's role (Error Forbidden)."}}) {
        Family(out, name, "counter", help);
        out << name << " " << number(net, key) << "\n";
    }
    Family(out, "penumbra_refused_connections_total", "counter",
           "Connections refused or closed, by reason.");
    for (const auto& [reason, key] : {std::pair{"full", "refused_full"},
                                      {"address", "refused_address"},
                                      {"hello_timeout", "hello_timeouts"},
                                      {"idle_timeout", "idle_timeouts"},
                                      {"unauthorized", "refused_unauthorized"}})
        out << "penumbra_refused_connections_total{reason=\"" << reason << "\"} "
            << number(net, key) << "\n";
    Family(out, "penumbra_scenes_dropped_total", "counter", "Scenes dropped, by why.");
    for (const auto& [why, key] : {std::pair{"evicted", "evicted_scenes"},
                                   {"unloaded", "unloaded_scenes"},
                                   {"expired", "expired_scenes"}})
        out << "penumbra_scenes_dropped_total{why=\"" << why << "\"} " << number(service, key)
            << "\n";
    for (const auto& [name, key, type, help] :
         {std::tuple{"penumbra_scene_frames_total", "frames", "counter", "Frames a scene made."},
          {"penumbra_scene_edits_total", "edits", "counter", "Edits a scene acknowledged."},
          {"penumbra_scene_pending_edits", "pending_edits", "gauge",
           "Edits acknowledged and not yet in a frame."},
          {"penumbra_scene_subscribers", "subscribers", "gauge", "A scene's subscribers."},
          {"penumbra_scene_last_frame_ms", "last_frame_ms", "gauge",
           "The time a scene's last frame took, milliseconds."}}) {
        Family(out, name, type, help);
        for (const auto& scene : scenes)
            out << name << "{scene=\"" << Label(scene.value("scene", "")) << "\"} "
                << number(scene, key) << "\n";
    }
    // Each scene's histograms (service::LatencyHistogram), as Prometheus histograms.
    for (const auto& [name, key, help] :
         {std::tuple{"penumbra_edit_to_frame_seconds", "edit_to_frame_seconds",
                     "Time from an edit's acknowledgement to the first frame that includes it."},
          {"penumbra_frame_seconds", "frame_seconds", "Time a frame took to make."}}) {
        Family(out, name, "histogram", help);
        for (const auto& scene : scenes) {
            if (!scene.contains(key)) continue;
            const nlohmann::json& h = scene[key];
            const std::string label = "scene=\"" + Label(scene.value("scene", "")) + "\"";
            for (size_t i = 0; i < h["le"].size(); ++i)
                out << name << "_bucket{" << label << ",le=\"" << h["le"][i].get<double>() << "\"} "
                    << h["cumulative"][i].get<uint64_t>() << "\n";
            out << name << "_bucket{" << label << ",le=\"+Inf\"} " << h["count"].get<uint64_t>()
                << "\n";
            out << name << "_sum{" << label << "} " << h["sum"].get<double>() << "\n";
            out << name << "_count{" << label << "} " << h["count"].get<uint64_t>() << "\n";
        }
    }
    return out.str();
}

}  // namespace penumbra::net
