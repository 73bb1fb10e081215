// Acceptors, the connections' bookkeeping and the shared frame encodings (protocol/SPEC.md).
#include "net/server.h"

#include <array>
#include <chrono>
#include <cstdio>
#include <deque>
#include <filesystem>
#include <fstream>
#include <limits>
#include <sstream>

#include "base/check.h"
#include "net/connection.h"
#include "net/delta_stream.h"
#include "net/messages.h"

namespace penumbra::net {

namespace fb = protocol::fb;
using protocol::MessageType;

ListenAddress ParseListenAddress(const std::string& url) {
    ListenAddress a;
    if (url.rfind("unix://", 0) == 0) {
        a.kind = ListenAddress::Kind::kUnix;
        a.path = url.substr(7);
        if (a.path.empty()) throw Error("'" + url + "': no socket path after unix://");
        if (a.path.size() >= sizeof(sockaddr_un::sun_path))
            throw Error("'" + url + "': socket path longer than " +
                        std::to_string(sizeof(sockaddr_un::sun_path) - 1) + " bytes");
        return a;
    }
    if (url.rfind("tcp://", 0) != 0)
        throw Error("'" + url + "': expected tcp://HOST:PORT or unix:///PATH");
    std::string rest = url.substr(6);
    size_t colon = rest.rfind(':');
    if (colon == std::string::npos || colon == 0 || colon + 1 == rest.size())
        throw Error("'" + url + "': expected tcp://HOST:PORT");
    a.host = rest.substr(0, colon);
    if (a.host.size() > 2 && a.host.front() == '[' && a.host.back() == ']')
        a.host = a.host.substr(1, a.host.size() - 2);
    std::string port = rest.substr(colon + 1);
    if (port.find_first_not_of("0123456789") != std::string::npos || port.size() > 5 ||
        std::stoul(port) > 65535)
        throw Error("'" + url + "': port must be a number 0…65535");
    a.port = static_cast<uint16_t>(std::stoul(port));
    return a;
}

std::map<std::string, service::Role> ReadTokenFile(const std::string& path) {
    std::ifstream in(path);
    if (!in) throw Error(path + ": cannot be read");
    std::map<std::string, service::Role> tokens;
    std::string line;
    for (int number = 1; std::getline(in, line); ++number) {
        line = line.substr(0, line.find('#'));
        std::istringstream words(line);
        std::vector<std::string> w;
        for (std::string word; words >> word;) w.push_back(word);
        if (w.empty()) continue;
        const std::string where = path + ":" + std::to_string(number) + ": ";
        if (w.size() > 2)
            throw Error(where + "expected ROLE TOKEN or TOKEN, got " + std::to_string(w.size()) +
                        " words (a token has no spaces)");
        std::optional<service::Role> role =
            w.size() == 2 ? service::RoleNamed(w[0]) : service::Role::kEditor;
        if (!role)
            throw Error(where + "unknown role '" + w[0] + "' (roles: viewer, editor, admin)");
        if (!tokens.emplace(w.back(), *role).second)
            throw Error(where + "this token is given twice");
    }
    if (tokens.empty()) throw Error(path + ": no token in it");
    return tokens;
}

Server::Server(asio::io_context& io, service::Service& service, NetLimits limits)
    : io_(io), service_(service), limits_(limits) {
    if (service_.Limits().sceneIdleSeconds > 0.0) SweepIdleScenes();
}

void Server::SweepIdleScenes() {
    std::vector<std::string> names;
    auto dropped = service_.DropIdle(std::chrono::steady_clock::now(), names);
    for (const std::string& name : names)
        Log("dropped " + name + ": no client held or watched it for " +
            std::to_string(int(service_.Limits().sceneIdleSeconds)) + " s (--scene-idle-timeout)");
    // A session's worker stops as its last reference goes, which can wait out an iteration.
    if (!dropped.empty())
        asio::post(blocking_, [dropped = std::move(dropped)]() mutable { dropped.clear(); });
    const double period = std::min(1.0, service_.Limits().sceneIdleSeconds / 4.0);
    sweep_.expires_after(std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(period)));
    sweep_.async_wait([this](std::error_code ec) {
        if (!ec && !stopping_) SweepIdleScenes();
    });
}

Server::~Server() {
    blocking_.join();
    for (const auto& p : unixPaths_) {
        std::error_code ec;
        std::filesystem::remove(p, ec);
    }
}

std::shared_ptr<asio::ip::tcp::acceptor> Server::OpenTcp(const ListenAddress& address,
                                                         bool allowRemote) {
    std::error_code ec;
    asio::ip::address ip =
        asio::ip::make_address(address.host == "localhost" ? "127.0.0.1" : address.host, ec);
    if (ec) throw Error("tcp://" + address.host + ": not an IP address (" + ec.message() + ")");
    if (!ip.is_loopback() && !allowRemote)
        throw Error("tcp://" + address.host + ":" + std::to_string(address.port) +
                    " is not a loopback address; pass --allow-remote to listen on it");
    auto acceptor = std::make_shared<asio::ip::tcp::acceptor>(io_);
    asio::ip::tcp::endpoint ep(ip, address.port);
    acceptor->open(ep.protocol(), ec);
    if (!ec) acceptor->set_option(asio::socket_base::reuse_address(true), ec);
    if (!ec) acceptor->bind(ep, ec);
    if (!ec) acceptor->listen(asio::socket_base::max_listen_connections, ec);
    if (ec)
        throw Error("cannot listen on tcp://" + address.host + ":" + std::to_string(address.port) +
                    ": " + ec.message());
    return acceptor;
}

std::string Server::BoundHostPort(const asio::ip::tcp::acceptor& acceptor) {
    auto bound = acceptor.local_endpoint();
    std::string host = bound.address().to_string();
    if (bound.address().is_v6()) host.insert(0, 1, '[').push_back(']');
    return host + ":" + std::to_string(bound.port());
}

std::string Server::Listen(const ListenAddress& address, bool allowRemote) {
    std::error_code ec;
    if (address.kind == ListenAddress::Kind::kTcp) {
        auto acceptor = OpenTcp(address, allowRemote);
        tcp_.push_back(acceptor);
        Accept(acceptor);
        return "tcp://" + BoundHostPort(*acceptor);
    }
    // A socket file left by a server that died is removed; a live one is not taken over.
    if (std::filesystem::exists(address.path)) {
        asio::local::stream_protocol::socket probe(io_);
        probe.connect(asio::local::stream_protocol::endpoint(address.path), ec);
        if (!ec) throw Error("unix://" + address.path + ": another server is listening there");
        if (!std::filesystem::is_socket(address.path))
            throw Error("unix://" + address.path + ": a file that is not a socket is in the way");
        std::filesystem::remove(address.path, ec);
    }
    auto acceptor = std::make_shared<asio::local::stream_protocol::acceptor>(io_);
    asio::local::stream_protocol::endpoint ep(address.path);
    acceptor->open(ep.protocol(), ec);
    if (!ec) acceptor->bind(ep, ec);
    if (!ec) acceptor->listen(asio::socket_base::max_listen_connections, ec);
    if (ec) throw Error("cannot listen on unix://" + address.path + ": " + ec.message());
    unix_.push_back(acceptor);
    unixPaths_.push_back(address.path);
    Accept(acceptor);
    return "unix://" + address.path;
}

void Server::Accept(std::shared_ptr<asio::ip::tcp::acceptor> acceptor) {
    acceptor->async_accept([this, acceptor](std::error_code ec, asio::ip::tcp::socket socket) {
        if (stopping_ || !acceptor->is_open()) return;
        if (!ec) {
            socket.set_option(asio::ip::tcp::no_delay(true), ec);
            const auto peer = socket.remote_endpoint(ec);
            Adopt(asio::generic::stream_protocol::socket(std::move(socket)),
                  ec ? std::string("?") : peer.address().to_string());
        }
        Accept(acceptor);
    });
}

void Server::Accept(std::shared_ptr<asio::local::stream_protocol::acceptor> acceptor) {
    acceptor->async_accept(
        [this, acceptor](std::error_code ec, asio::local::stream_protocol::socket socket) {
            if (stopping_ || !acceptor->is_open()) return;
            if (!ec) Adopt(asio::generic::stream_protocol::socket(std::move(socket)), "");
            Accept(acceptor);
        });
}

namespace {

// A refused socket after its Error: the sending side shut, what the client sends (its Hello)
// read and dropped until it closes or 2 s pass, then closed. Closing at once with the Hello
// unread would reset the connection, and the reset can discard the Error before the client
// reads it.
struct Lingering : std::enable_shared_from_this<Lingering> {
    Lingering(asio::generic::stream_protocol::socket s)
        : socket(std::move(s)), timer(socket.get_executor()) {}
    void Start() {
        std::error_code ec;
        socket.shutdown(asio::socket_base::shutdown_send, ec);
        timer.expires_after(std::chrono::seconds(2));
        timer.async_wait([self = shared_from_this()](std::error_code) {
            std::error_code ignored;
            self->socket.close(ignored);
        });
        Drain();
    }
    void Drain() {
        socket.async_read_some(asio::buffer(sink),
                               [self = shared_from_this()](std::error_code ec, size_t) {
                                   if (ec) {
                                       self->timer.cancel();
                                       std::error_code ignored;
                                       self->socket.close(ignored);
                                       return;
                                   }
                                   self->Drain();
                               });
    }
    asio::generic::stream_protocol::socket socket;
    asio::steady_timer timer;
    std::array<char, 4096> sink{};
};

}  // namespace

void Server::Refuse(asio::generic::stream_protocol::socket& socket, const std::string& why) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateErrorDirect(b, fb::ErrorCode::LimitReached, why.c_str()));
    auto bytes = protocol::EncodeFrame(MessageType::kError, 0, b);
    std::error_code ec;
    asio::write(socket, asio::buffer(bytes), ec);  // one small frame: synchronous
    std::make_shared<Lingering>(std::move(socket))->Start();
    Log("refused a connection: LimitReached: " + why);
}

void Server::Adopt(asio::generic::stream_protocol::socket socket, const std::string& peer) {
    // Tell the client why before closing (one small frame).
    if (connections_.size() >= limits_.maxClients) {
        ++refusedFull;
        Refuse(socket, "the server has its maximum of " + std::to_string(limits_.maxClients) +
                           " clients (--max-clients)");
        return;
    }
    if (!peer.empty() && perAddress_[peer] >= limits_.maxClientsPerAddress) {
        ++refusedAddress;
        Refuse(socket, "the server has its maximum of " +
                           std::to_string(limits_.maxClientsPerAddress) + " clients from " + peer +
                           " (--max-clients-per-address)");
        return;
    }
    auto c = std::make_shared<Connection>(*this, std::move(socket), nextConnection_++);
    connections_[c.get()] = c;
    if (!peer.empty()) ++perAddress_[peer], peers_[c.get()] = peer;
    c->Start();
}

void Server::Forget(Connection* connection) {
    connections_.erase(connection);
    if (auto it = peers_.find(connection); it != peers_.end()) {
        if (--perAddress_[it->second] == 0) perAddress_.erase(it->second);
        peers_.erase(it);
    }
}

std::vector<std::shared_ptr<Connection>> Server::OpenConnections() const {
    std::vector<std::shared_ptr<Connection>> open;
    for (auto& [p, weak] : connections_)
        if (auto c = weak.lock()) open.push_back(c);
    return open;
}

void Server::SceneGone(const std::string& name, const std::string& why) {
    for (auto& c : OpenConnections()) c->SceneGone(name, why);
}

void Server::SceneReplaced(const std::shared_ptr<service::Session>& fresh) {
    for (auto& c : OpenConnections()) c->SceneReplaced(fresh);
}

void Server::Stop() {
    if (stopping_) return;
    stopping_ = true;
    std::error_code ec;
    for (auto& a : tcp_) a->close(ec);
    for (auto& a : unix_) a->close(ec);
    for (auto& a : metrics_) a->close(ec);
    sweep_.cancel();
    for (auto& c : OpenConnections()) c->Close();
    service_.Shutdown();
}

void Server::Log(const std::string& line) const {
    if (limits_.log) std::fprintf(stderr, "penumbra-server: %s\n", line.c_str());
}

nlohmann::json Server::StatsJson() const {
    nlohmann::json j;
    j["clients"] = connections_.size();
    j["frames_sent"] = framesSent.load();
    j["frames_dropped"] = framesDropped.load();
    j["protocol_errors"] = protocolErrors.load();
    j["refused_full"] = refusedFull.load();
    j["refused_address"] = refusedAddress.load();
    j["hello_timeouts"] = helloTimeouts.load();
    j["idle_timeouts"] = idleTimeouts.load();
    j["refused_unauthorized"] = refusedUnauthorized.load();
    j["forbidden_requests"] = forbiddenRequests.load();
    j["max_clients"] = limits_.maxClients;
    j["max_frame_bytes"] = limits_.maxFrameBytes;
    return j;
}

std::shared_ptr<const std::vector<uint8_t>> Server::EncodedFrame(const service::FramePtr& frame,
                                                                 service::Channel channel,
                                                                 fb::Format format) {
    EncodedKey key{frame->session, frame->frame, frame->converged, static_cast<int>(channel),
                   static_cast<int>(format)};
    {
        std::lock_guard lock(encodedMutex_);
        auto it = encoded_.find(key);
        if (it != encoded_.end()) return it->second;
    }
    flatbuffers::FlatBufferBuilder b(1024 + frame->irradiance.size() * 64);
    BuildFramePayload(b, *frame, channel, format);
    auto bytes = std::make_shared<const std::vector<uint8_t>>(
        protocol::EncodeFrame(MessageType::kFrame, 0, b));
    std::lock_guard lock(encodedMutex_);
    // Keep only the newest few encodings, whichever sessions made them.
    if (encoded_.emplace(key, bytes).second) encodedOrder_.push_back(key);
    while (encoded_.size() > 16) {
        encoded_.erase(encodedOrder_.front());
        encodedOrder_.pop_front();
    }
    return bytes;
}

std::shared_ptr<const std::vector<uint8_t>> Server::DeltaFrame(const service::FramePtr& frame,
                                                               service::Channel channel,
                                                               float tolerance, uint64_t base) {
    std::lock_guard lock(deltaMutex_);
    const DeltaKey key{frame->session, static_cast<int>(channel), tolerance};
    DeltaEntry& entry = deltas_[key];
    if (!entry.stream) entry.stream = std::make_shared<DeltaStream>(channel, tolerance);
    entry.used = ++deltaClock_;
    std::shared_ptr<DeltaStream> stream = entry.stream;
    if (deltas_.size() > 16)
        deltas_.erase(std::min_element(
            deltas_.begin(), deltas_.end(),
            [](const auto& a, const auto& b) { return a.second.used < b.second.used; }));
    return stream->For(frame, base);
}

}  // namespace penumbra::net
