// A client's socket: reads decoded into messages, writes queued with per-client backpressure.
#include "net/connection.h"

#include <chrono>
#include <cstdio>

namespace penumbra::net {

namespace fb = protocol::fb;
using protocol::MessageType;

namespace {

// A limit in seconds as a timer's duration, and as the text an Error quotes.
std::chrono::steady_clock::duration After(double seconds) {
    return std::chrono::duration_cast<std::chrono::steady_clock::duration>(
        std::chrono::duration<double>(seconds));
}
std::string SecondsText(double seconds) {
    char text[32];
    std::snprintf(text, sizeof(text), "%g", seconds);
    return text;
}

}  // namespace

Connection::Connection(Server& server, asio::generic::stream_protocol::socket socket, uint64_t id)
    : server_(server),
      socket_(std::move(socket)),
      id_(id),
      decoder_(server.Limits().maxFrameBytes),
      stall_(socket_.get_executor()),
      hello_(socket_.get_executor()),
      idle_(socket_.get_executor()) {}

void Connection::ArmIdle() {
    const double limit = server_.Limits().idleTimeoutSeconds;
    if (!(limit > 0.0) || closed_ || closing_) return;
    const uint64_t epoch = ++idleEpoch_;
    idle_.expires_after(After(limit));
    auto self = shared_from_this();
    idle_.async_wait([this, self, epoch, limit](std::error_code ec) {
        if (ec || closed_ || closing_ || epoch != idleEpoch_) return;
        if (!subscriptions_.empty() || busy_ > 0) {
            ArmIdle();
            return;
        }
        ++server_.idleTimeouts;
        SendError(0, fb::ErrorCode::Stalled,
                  "nothing sent for " + SecondsText(limit) +
                      " s, and no subscription (the server's --idle-timeout)",
                  true);
    });
}

void Connection::Start() {
    const double limit = server_.Limits().helloTimeoutSeconds;
    if (limit > 0.0) {
        hello_.expires_after(After(limit));
        auto self = shared_from_this();
        hello_.async_wait([this, self, limit](std::error_code ec) {
            if (ec || closed_ || closing_ || helloDone_) return;
            ++server_.helloTimeouts;
            SendError(0, fb::ErrorCode::HelloRequired,
                      "no Hello within " + SecondsText(limit) +
                          " s of connecting (the server's --hello-timeout)",
                      true);
        });
    }
    Read();
}

void Connection::Close() {
    if (closed_) return;
    closed_ = true;
    stallArmed_ = false;
    stall_.cancel();
    hello_.cancel();
    idle_.cancel();
    Unsubscribe("");
    std::error_code ec;
    socket_.shutdown(asio::socket_base::shutdown_both, ec);
    socket_.close(ec);
    server_.GetService().Release(id_);
    server_.Forget(this);
}

void Connection::CloseAfterWrites() {
    closing_ = true;
    if (!writing_) Close();
}

void Connection::PushFrame(const std::string& scene, const service::FramePtr& frame) {
    if (closed_) return;
    auto sub = subscriptions_.find(scene);
    if (sub == subscriptions_.end()) return;  // unsubscribed since the frame was posted
    const size_t first = writing_ ? 1 : 0;    // the one being written stays
    size_t queued = 0;
    for (size_t i = first; i < queue_.size(); ++i) queued += queue_[i].frame;
    if (queued >= server_.Limits().maxQueuedFrames) {
        for (size_t i = first; i < queue_.size(); ++i)
            if (queue_[i].frame) {
                const std::string dropped = queue_[i].scene;
                queue_.erase(queue_.begin() + static_cast<std::ptrdiff_t>(i));
                ++server_.framesDropped;
                // A delta stream's later frames build on the one dropped: they go too, and
                // its next frame is a keyframe.
                auto lost = subscriptions_.find(dropped);
                if (lost != subscriptions_.end() && lost->second.tolerance >= 0.0f) {
                    lost->second.baseFrame = 0;
                    for (size_t j = i; j < queue_.size();)
                        if (queue_[j].frame && queue_[j].scene == dropped) {
                            queue_.erase(queue_.begin() + static_cast<std::ptrdiff_t>(j));
                            ++server_.framesDropped;
                        } else {
                            ++j;
                        }
                }
                break;
            }
    }
    Subscription& s = sub->second;
    std::shared_ptr<const std::vector<uint8_t>> bytes;
    if (s.tolerance < 0.0f) {
        bytes = server_.EncodedFrame(frame, s.channel, s.format);
    } else {
        const uint64_t base = s.baseSession == frame->session ? s.baseFrame : 0;
        bytes = server_.DeltaFrame(frame, s.channel, s.tolerance, base);
        s.baseSession = frame->session;
        s.baseFrame = frame->frame;
    }
    Enqueue(std::move(bytes), &scene);
}

void Connection::Read() {
    auto self = shared_from_this();
    socket_.async_read_some(asio::buffer(readBuffer_), [this, self](std::error_code ec, size_t n) {
        if (closed_) return;
        if (ec) {  // peer closed or vanished: nothing to answer
            Close();
            return;
        }
        decoder_.Feed(readBuffer_.data(), n);
        protocol::Message message;
        bool decoded = false;
        while (!closed_ && !closing_) {
            auto r = decoder_.Next(message);
            if (r == protocol::Decoder::Result::kNeedMore) break;
            if (r == protocol::Decoder::Result::kError) {
                ++server_.protocolErrors;
                SendError(decoder_.errorRequestId(), decoder_.errorCode(), decoder_.error(), true);
                return;
            }
            Dispatch(message);
            decoded = true;
        }
        if (closed_ || closing_) return;
        if (decoded && helloDone_) ArmIdle();
        WatchStall(decoded);
        Read();
    });
}

void Connection::WatchStall(bool decoded) {
    const double limit = server_.Limits().frameTimeoutSeconds;
    if (!(limit > 0.0)) return;
    if (decoder_.buffered() == 0) {
        if (stallArmed_) stall_.cancel();
        stallArmed_ = false;
        return;
    }
    if (stallArmed_ && !decoded) return;  // the same frame, still arriving
    stallArmed_ = true;
    const uint64_t epoch = ++stallEpoch_;
    stall_.expires_after(After(limit));
    auto self = shared_from_this();
    stall_.async_wait([this, self, epoch, limit](std::error_code ec) {
        if (ec || closed_ || closing_ || !stallArmed_ || epoch != stallEpoch_) return;
        ++server_.protocolErrors;
        SendError(0, fb::ErrorCode::Stalled,
                  "a frame began " + SecondsText(limit) + " s ago and has not arrived whole (" +
                      std::to_string(decoder_.buffered()) +
                      " bytes of it so far; the limit is "
                      "the server's --frame-timeout)",
                  true);
    });
}

void Connection::Enqueue(std::shared_ptr<const std::vector<uint8_t>> bytes,
                         const std::string* scene) {
    if (closed_) return;
    queue_.push_back({std::move(bytes), scene != nullptr, scene ? *scene : std::string()});
    if (!writing_) WriteNext();
}

void Connection::WriteNext() {
    if (queue_.empty() || closed_) {
        writing_ = false;
        if (closing_ && !closed_) Close();
        return;
    }
    writing_ = true;
    auto self = shared_from_this();
    auto bytes = queue_.front().bytes;
    asio::async_write(socket_, asio::buffer(*bytes),
                      [this, self, bytes](std::error_code ec, size_t) {
                          if (closed_) return;
                          if (ec) {
                              Close();
                              return;
                          }
                          if (queue_.front().frame) ++server_.framesSent;
                          queue_.pop_front();
                          WriteNext();
                      });
}

void Connection::Send(MessageType type, uint32_t requestId,
                      const flatbuffers::FlatBufferBuilder& b) {
    Enqueue(
        std::make_shared<const std::vector<uint8_t>>(protocol::EncodeFrame(type, requestId, b)));
}

void Connection::SendError(uint32_t requestId, fb::ErrorCode code, const std::string& message,
                           bool close) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateErrorDirect(b, code, message.c_str()));
    server_.Log(Who() + ": " + fb::EnumNameErrorCode(code) + ": " + message +
                (close ? " (connection closed)" : ""));
    if (code == fb::ErrorCode::Unauthorized) ++server_.refusedUnauthorized;
    if (code == fb::ErrorCode::Forbidden) ++server_.forbiddenRequests;
    Send(MessageType::kError, requestId, b);
    if (close) CloseAfterWrites();
}

std::string Connection::Who() const {
    return "client " + std::to_string(id_) + (client_.empty() ? "" : " '" + client_ + "'");
}

void Connection::SendOk(uint32_t requestId, uint64_t frame) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateOk(b, frame));
    Send(MessageType::kOk, requestId, b);
}

void Connection::SendAck(uint32_t requestId, uint64_t edit) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateEditAck(b, edit));
    Send(MessageType::kEditAck, requestId, b);
}

}  // namespace penumbra::net
