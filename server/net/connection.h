// One client of penumbra-server: its socket's reads and queued writes (connection.cpp), and
// its requests handled against the service (requests.cpp). Lives on the I/O thread; slow
// requests run on the server's blocking pool and answer back on the I/O thread.
#pragma once

#include <array>
#include <asio.hpp>
#include <cstdint>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "net/messages.h"
#include "net/server.h"
#include "protocol/frame.h"

namespace penumbra::net {

class Connection : public std::enable_shared_from_this<Connection> {
  public:
    Connection(Server& server, asio::generic::stream_protocol::socket socket, uint64_t id);

    // Starts reading, and the Hello deadline (Limits::helloTimeoutSeconds).
    void Start();
    // Closes the socket; pending writes are abandoned.
    void Close();
    // Queues `frame` of the subscription to scene `scene` (I/O thread), encoded as it asked:
    // whole, or a delta from what it holds (a keyframe if it holds nothing the stream's delta
    // builds on). Keeps at most maxQueuedFrames unsent frames: a slow client sees fewer
    // frames, never stale ones, and never holds up the others; a delta subscription that loses
    // a frame so gets a keyframe next.
    void PushFrame(const std::string& scene, const service::FramePtr& frame);

    // Scene `name` was unloaded: a subscription to it ends with a pushed Error NoScene
    // carrying `why` (nothing for a connection not subscribed to it).
    void SceneGone(const std::string& name, const std::string& why);
    // Scene `fresh->Name()` was reloaded as `fresh`: a subscription to it moves to the new
    // session (same channel and format), announced by a pushed SceneInfo of the new build.
    void SceneReplaced(const std::shared_ptr<service::Session>& fresh);

  private:
    struct Outgoing {
        std::shared_ptr<const std::vector<uint8_t>> bytes;
        bool frame = false;
        std::string scene;  // a frame's subscription
    };
    struct Subscription {
        std::weak_ptr<service::Session> session;
        int id = 0;
        service::Channel channel = service::Channel::kIndirect;
        protocol::fb::Format format = protocol::fb::Format::Float32;
        float tolerance = -1.0f;  // ≥ 0: a delta stream (Server::DeltaFrame)
        // A delta stream's frame the client holds once the queue is written (0: none).
        uint64_t baseSession = 0, baseFrame = 0;
    };

    // --- I/O (connection.cpp) ---
    void Read();
    // `scene`: a subscribed frame's scene (queued as a frame, which PushFrame may drop).
    void Enqueue(std::shared_ptr<const std::vector<uint8_t>> bytes,
                 const std::string* scene = nullptr);
    void WriteNext();
    void Send(protocol::MessageType type, uint32_t requestId,
              const flatbuffers::FlatBufferBuilder& b);
    // An Error reply; with `close`, the connection closes once it is written.
    void SendError(uint32_t requestId, protocol::fb::ErrorCode code, const std::string& message,
                   bool close = false);
    void SendOk(uint32_t requestId, uint64_t frame = 0);
    void SendAck(uint32_t requestId, uint64_t edit);
    // Closes once the queue is written.
    void CloseAfterWrites();
    // "client 7 'name'": this connection in the server's log.
    std::string Who() const;
    // After a read: with part of a frame buffered, the frame must be whole within the
    // frame timeout of its first byte (a new frame, `decoded` one before it, starts the
    // clock again); a client that stalls mid-frame gets Error Stalled and is closed.
    void WatchStall(bool decoded);
    // After Hello and after every request: the connection closes with Error Stalled when
    // nothing more comes within the idle timeout while it has no subscription and no request
    // in progress (either one puts the deadline off again).
    void ArmIdle();
    // Runs `work` on the blocking pool and `reply` with its result back on the I/O thread;
    // a ServiceError becomes an Error reply.
    template <typename Work, typename Reply>
    void Blocking(uint32_t requestId, Work work, Reply reply);

    // --- Requests (requests.cpp) ---
    // Hello first, then Handle; a ServiceError or any exception becomes an Error reply.
    void Dispatch(const protocol::Message& m);
    void Handle(const protocol::Message& m);
    void OnHello(uint32_t id, const protocol::fb::Hello& h);
    void OnLoadScene(uint32_t id, const protocol::fb::LoadScene& l);
    void OnUnloadScene(uint32_t id, const protocol::fb::UnloadScene& u);
    void OnSetEnvironment(uint32_t id, const protocol::fb::SetEnvironment& s);
    void OnSubscribe(uint32_t id, const protocol::fb::Subscribe& s);
    void OnGetIrradiance(uint32_t id, const protocol::fb::GetIrradiance& g);
    void OnStep(uint32_t id, const protocol::fb::Step& s);
    void OnGetStats(uint32_t id, const protocol::fb::GetStats& g);
    // "" unsubscribes from every scene.
    void Unsubscribe(const std::string& scene);
    // Subscribes this connection to `session`'s frames in `channel` and `format`, or as a
    // delta stream at `tolerance` ≥ 0 (any earlier subscription to a scene of that name ends).
    void SubscribeTo(const std::shared_ptr<service::Session>& session, service::Channel channel,
                     protocol::fb::Format format, float tolerance);
    // LoadScene's progress callback when the client asked for Progress messages.
    ProgressFn ProgressSender(uint32_t id);
    // The session a request's `scene` names; "" is the one this connection loaded or joined
    // last, or the server's newest when it has not loaded any. Throws ServiceError.
    std::shared_ptr<service::Session> SessionOf(const flatbuffers::String* scene);
    // SessionOf's session, if this connection may edit it (Service::CheckMay); else throws
    // ServiceError kForbidden.
    std::shared_ptr<service::Session> EditableSession(const flatbuffers::String* scene);

    Server& server_;
    asio::generic::stream_protocol::socket socket_;
    uint64_t id_;
    protocol::Decoder decoder_;
    std::array<uint8_t, 64 * 1024> readBuffer_;
    std::deque<Outgoing> queue_;
    bool writing_ = false;
    bool closing_ = false;  // close once the queue is written
    bool closed_ = false;
    bool helloDone_ = false;
    asio::steady_timer stall_;  // WatchStall
    asio::steady_timer hello_;  // the Hello deadline; cancelled by Hello or Close
    asio::steady_timer idle_;   // ArmIdle
    uint64_t idleEpoch_ = 0;    // which arming a firing belongs to
    size_t busy_ = 0;           // requests on the blocking pool, not yet answered
    uint64_t stallEpoch_ = 0;   // which arming a firing belongs to
    bool stallArmed_ = false;
    std::string client_;
    service::Role role_ = service::Role::kUser;  // from Hello's token (NetLimits::tokens)
    std::string lastScene_;                      // the scene this connection loaded or joined last
    std::map<std::string, Subscription> subscriptions_;
};

template <typename Work, typename Reply>
void Connection::Blocking(uint32_t requestId, Work work, Reply reply) {
    auto self = shared_from_this();
    ++busy_;
    asio::post(server_.Blocking(), [this, self, requestId, work, reply]() mutable {
        std::function<void()> done;
        try {
            auto result = std::make_shared<decltype(work())>(work());
            done = [result, reply]() mutable { reply(*result); };
        } catch (const service::ServiceError& e) {
            std::string what = e.what();
            protocol::fb::ErrorCode code = CodeOf(e.kind());
            done = [this, requestId, code, what] { SendError(requestId, code, what); };
        } catch (const std::exception& e) {
            std::string what = e.what();
            done = [this, requestId, what] {
                SendError(requestId, protocol::fb::ErrorCode::Internal, what);
            };
        }
        asio::post(server_.Io(), [this, self, done] {
            --busy_;
            done();
        });
    });
}

}  // namespace penumbra::net
