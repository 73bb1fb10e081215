// The socket side of penumbra-server: Asio acceptors on TCP and Unix sockets, one
// Connection per client that decodes frames (protocol/), dispatches them to the Service and
// streams subscribed frames back. One I/O thread; slow work runs on a small pool.
#pragma once

#include <asio.hpp>
#include <atomic>
#include <cstdint>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "protocol/frame.h"
#include "service/service.h"

namespace penumbra::net {

struct NetLimits {
    size_t maxClients = 64;
    // Connections at once from one TCP peer address (a Unix socket's clients are local and
    // not counted), so that one host cannot take every slot; --max-clients-per-address.
    size_t maxClientsPerAddress = 16;
    uint32_t maxFrameBytes = protocol::kDefaultMaxPayloadBytes;
    size_t maxQueuedFrames = 2;  // per subscriber; older unsent frames are dropped
    // A frame begun must arrive whole within this many seconds of its first byte, else the
    // connection gets Error Stalled and closes (0: no limit); --frame-timeout.
    double frameTimeoutSeconds = 60.0;
    // A connection must complete its Hello within this many seconds of being accepted, else
    // it gets Error HelloRequired and closes (0: no limit); --hello-timeout. A client that
    // never speaks, or speaks a byte a second, holds a slot no longer than this.
    double helloTimeoutSeconds = 5.0;
    // A connection past its Hello that sends nothing for this many seconds, with no
    // subscription and no request in progress, gets Error Stalled and closes (0: no limit);
    // --idle-timeout.
    double idleTimeoutSeconds = 300.0;
    // Every Hello must carry one of these tokens, which gives the connection its role
    // (empty: none asked for, every client a service::Role::kUser); --token-file.
    std::map<std::string, service::Role> tokens;
    // One line on stderr for each load, refusal and protocol error (penumbra-server sets it
    // unless -q; off for servers inside other programs).
    bool log = false;
};

// The tokens of a --token-file: one a line, "ROLE TOKEN" (ROLE viewer, editor or admin) or
// the token alone (an editor's); blank lines and lines from '#' on are skipped. Throws
// penumbra::Error naming the file and line of anything else, a token given twice, or none.
std::map<std::string, service::Role> ReadTokenFile(const std::string& path);

// "tcp://HOST:PORT" or "unix:///PATH".
struct ListenAddress {
    enum class Kind { kTcp, kUnix } kind = Kind::kTcp;
    std::string host;  // tcp
    uint16_t port = 0;
    std::string path;  // unix
};
// Throws penumbra::Error with what is wrong with `url`.
ListenAddress ParseListenAddress(const std::string& url);

class Connection;
class DeltaStream;

class Server {
  public:
    Server(asio::io_context& io, service::Service& service, NetLimits limits);
    ~Server();

    // Binds and starts accepting. A TCP address other than loopback needs `allowRemote`.
    // Returns the bound address as a URL (port 0 becomes the chosen port). Throws
    // penumbra::Error naming the address and the reason.
    std::string Listen(const ListenAddress& address, bool allowRemote = false);
    // Serves HTTP on a TCP address for a supervisor (metrics.cpp): GET /metrics (Prometheus
    // text: clients, scenes, frames sent and dropped, refusals and timeouts by reason, scenes
    // evicted, unloaded and expired, each scene's frames, subscribers, frame time and edits),
    // /healthz (200 while the I/O loop answers) and /readyz (200 while accepting, 503 once
    // stopping). Returns "http://HOST:PORT".
    std::string ListenMetrics(const ListenAddress& address, bool allowRemote = false);
    // The Prometheus text /metrics answers.
    std::string MetricsText() const;
    // Stops accepting, closes every connection, shuts the service down. I/O thread only
    // (post it there from elsewhere).
    void Stop();

    asio::io_context& Io() { return io_; }
    service::Service& GetService() { return service_; }
    const NetLimits& Limits() const { return limits_; }
    asio::thread_pool& Blocking() { return blocking_; }
    bool Stopping() const { return stopping_; }
    nlohmann::json StatsJson() const;
    // "penumbra-server: " + `line` on stderr, unless NetLimits::log is off.
    void Log(const std::string& line) const;

    // Encoded Frame messages (request id 0), shared by all subscribers asking for the same
    // channel and format of the same frame.
    std::shared_ptr<const std::vector<uint8_t>> EncodedFrame(const service::FramePtr& frame,
                                                             service::Channel channel,
                                                             protocol::fb::Format format);

    // A delta subscriber's Frame message (DeltaStream::For): the stream of `frame`'s session
    // in `channel` at `tolerance`, shared by every subscriber asking for the same; `base` is
    // the frame of that session the subscriber holds (0: none). The 16 streams used last are
    // kept.
    std::shared_ptr<const std::vector<uint8_t>> DeltaFrame(const service::FramePtr& frame,
                                                           service::Channel channel,
                                                           float tolerance, uint64_t base);

    // Connection bookkeeping (I/O thread).
    void Forget(Connection* connection);
    // Scene `name` is gone (unloaded): every connection subscribed to it gets `why` as a
    // pushed Error NoScene and its subscription ends (I/O thread).
    void SceneGone(const std::string& name, const std::string& why);
    // Scene `fresh->Name()` was reloaded: every connection subscribed to it moves to the new
    // session (Connection::SceneReplaced; I/O thread).
    void SceneReplaced(const std::shared_ptr<service::Session>& fresh);
    std::atomic<uint64_t> framesSent{0}, framesDropped{0}, protocolErrors{0};
    // Connections refused at the door (--max-clients, --max-clients-per-address) and closed
    // for no Hello in time or idleness.
    std::atomic<uint64_t> refusedFull{0}, refusedAddress{0}, helloTimeouts{0}, idleTimeouts{0};
    // Hellos refused for their token (--token-file), and requests refused for the
    // connection's role (Error Forbidden: protocol/SPEC.md "Roles").
    std::atomic<uint64_t> refusedUnauthorized{0}, forbiddenRequests{0};

  private:
    // Every second or so, the scenes idle past --scene-idle-timeout are dropped
    // (Service::DropIdle; logged, their sessions let go of on the blocking pool).
    void SweepIdleScenes();
    void Accept(std::shared_ptr<asio::ip::tcp::acceptor> acceptor);
    void AcceptMetrics(std::shared_ptr<asio::ip::tcp::acceptor> acceptor);
    // The connections still open, held while the caller calls each (I/O thread).
    std::vector<std::shared_ptr<Connection>> OpenConnections() const;
    // A TCP acceptor bound and listening at `address` (loopback unless `allowRemote`).
    std::shared_ptr<asio::ip::tcp::acceptor> OpenTcp(const ListenAddress& address,
                                                     bool allowRemote);
    static std::string BoundHostPort(const asio::ip::tcp::acceptor& acceptor);
    void Accept(std::shared_ptr<asio::local::stream_protocol::acceptor> acceptor);
    // `peer`: the TCP peer's address ("" for a Unix socket's client).
    void Adopt(asio::generic::stream_protocol::socket socket, const std::string& peer);
    // Sends Error LimitReached with `why` and closes `socket` (best effort, synchronous).
    void Refuse(asio::generic::stream_protocol::socket& socket, const std::string& why);

    asio::io_context& io_;
    service::Service& service_;
    NetLimits limits_;
    asio::thread_pool blocking_{2};
    asio::steady_timer sweep_{io_};  // SweepIdleScenes
    std::vector<std::shared_ptr<asio::ip::tcp::acceptor>> tcp_;
    std::vector<std::shared_ptr<asio::local::stream_protocol::acceptor>> unix_;
    std::vector<std::shared_ptr<asio::ip::tcp::acceptor>> metrics_;
    std::vector<std::string> unixPaths_;
    std::map<Connection*, std::weak_ptr<Connection>> connections_;
    std::map<Connection*, std::string> peers_;  // a TCP connection's peer address
    std::map<std::string, size_t> perAddress_;  // connections from each peer address
    bool stopping_ = false;
    uint64_t nextConnection_ = 1;

    std::mutex encodedMutex_;
    struct EncodedKey {
        uint64_t session;  // not the scene's name: a reload numbers its frames from 1 again
        uint64_t frame;
        bool converged;  // a replayed frame may differ from the original in this flag
        int channel, format;
        auto operator<=>(const EncodedKey&) const = default;
    };
    std::map<EncodedKey, std::shared_ptr<const std::vector<uint8_t>>> encoded_;
    std::deque<EncodedKey> encodedOrder_;  // oldest first

    std::mutex deltaMutex_;
    struct DeltaKey {
        uint64_t session;
        int channel;
        float tolerance;
        auto operator<=>(const DeltaKey&) const = default;
    };
    struct DeltaEntry {
        std::shared_ptr<DeltaStream> stream;
        uint64_t used = 0;  // deltaClock_ when last asked for
    };
    std::map<DeltaKey, DeltaEntry> deltas_;
    uint64_t deltaClock_ = 0;
};

}  // namespace penumbra::net
