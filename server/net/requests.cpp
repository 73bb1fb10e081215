// A client's requests handled against the service (protocol/SPEC.md, "Messages"): fields
// read and checked by messages.h, slow work on the blocking pool.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>

#include "net/connection.h"

namespace penumbra::net {

namespace fb = protocol::fb;
using protocol::MessageType;
using service::ErrorKind;
using service::ServiceError;

void Connection::Dispatch(const protocol::Message& m) {
    const uint32_t id = m.header.requestId;
    if (!helloDone_ && m.header.type != MessageType::kHello) {
        SendError(id, fb::ErrorCode::HelloRequired,
                  std::string("the first message must be Hello, got ") +
                      protocol::MessageName(m.header.type),
                  true);
        return;
    }
    if (id == 0) {  // 0 marks what the server pushes: a reply to it could not be told apart
        SendError(0, fb::ErrorCode::InvalidArgument,
                  std::string(protocol::MessageName(m.header.type)) +
                      " with request id 0: id 0 is reserved for frames the server pushes; "
                      "number requests from 1");
        return;
    }
    try {
        Handle(m);
    } catch (const ServiceError& e) {
        SendError(id, CodeOf(e.kind()), e.what());
    } catch (const std::exception& e) {
        SendError(id, fb::ErrorCode::Internal, e.what());
    }
}

void Connection::Handle(const protocol::Message& m) {
    const uint32_t id = m.header.requestId;
    switch (m.header.type) {
        case MessageType::kHello:
            return OnHello(id, *m.As<fb::Hello>());
        case MessageType::kBye: {
            flatbuffers::FlatBufferBuilder b;
            b.Finish(fb::CreateBye(b));
            Send(MessageType::kBye, id, b);
            return CloseAfterWrites();
        }
        case MessageType::kLoadScene:
            return OnLoadScene(id, *m.As<fb::LoadScene>());
        case MessageType::kUnloadScene:
            return OnUnloadScene(id, *m.As<fb::UnloadScene>());
        case MessageType::kGetSceneInfo: {
            auto session = SessionOf(m.As<fb::GetSceneInfo>()->scene());
            flatbuffers::FlatBufferBuilder b;
            BuildSceneInfo(b, *session, true);
            return Send(MessageType::kSceneInfo, id, b);
        }
        case MessageType::kSetTransform: {
            const auto* t = m.As<fb::SetTransform>();
            auto session = EditableSession(t->scene());
            return SendAck(id, session->Submit(ReadSetTransform(*t)));
        }
        case MessageType::kSetVertices: {
            const auto* v = m.As<fb::SetVertices>();
            auto session = EditableSession(v->scene());
            return SendAck(id, session->Submit(ReadSetVertices(*v)));
        }
        case MessageType::kSetLight: {
            const auto* l = m.As<fb::SetLight>();
            auto session = EditableSession(l->scene());
            return SendAck(id, session->Submit(ReadSetLight(*l)));
        }
        case MessageType::kSetMaterial: {
            const auto* s = m.As<fb::SetMaterial>();
            auto session = EditableSession(s->scene());
            return SendAck(id, session->Submit(ReadSetMaterial(*s)));
        }
        case MessageType::kSetEnvironment:
            return OnSetEnvironment(id, *m.As<fb::SetEnvironment>());
        case MessageType::kSubscribe:
            return OnSubscribe(id, *m.As<fb::Subscribe>());
        case MessageType::kUnsubscribe: {
            auto session = SessionOf(m.As<fb::Unsubscribe>()->scene());
            Unsubscribe(session->Name());
            return SendOk(id);
        }
        case MessageType::kGetIrradiance:
            return OnGetIrradiance(id, *m.As<fb::GetIrradiance>());
        case MessageType::kStep:
            return OnStep(id, *m.As<fb::Step>());
        case MessageType::kGetStats:
            return OnGetStats(id, *m.As<fb::GetStats>());
        default:
            SendError(id, fb::ErrorCode::UnknownType,
                      std::string(protocol::MessageName(m.header.type)) +
                          " is a reply type; a client may not send it");
    }
}

void Connection::OnHello(uint32_t id, const fb::Hello& h) {
    uint16_t lo = std::max<uint16_t>(h.min_version(), protocol::kMinProtocolVersion);
    uint16_t hi = std::min<uint16_t>(h.max_version(), protocol::kMaxProtocolVersion);
    if (helloDone_) {
        SendError(id, fb::ErrorCode::InvalidArgument, "Hello was already sent");
        return;
    }
    if (lo > hi) {
        SendError(id, fb::ErrorCode::VersionMismatch,
                  "client speaks versions " + std::to_string(h.min_version()) + "–" +
                      std::to_string(h.max_version()) + ", this server " +
                      std::to_string(protocol::kMinProtocolVersion) + "–" +
                      std::to_string(protocol::kMaxProtocolVersion),
                  true);
        return;
    }
    if (const auto& tokens = server_.Limits().tokens; !tokens.empty()) {
        auto token = tokens.find(Str(h.token()));
        if (token == tokens.end()) {
            SendError(id, fb::ErrorCode::Unauthorized,
                      h.token() ? "this server asks for a token in Hello (--token-file); the one "
                                  "given is not one of its tokens"
                                : "this server asks for a token in Hello (--token-file); none "
                                  "was given",
                      true);
            return;
        }
        role_ = token->second;
    }
    helloDone_ = true;
    hello_.cancel();
    client_ = Str(h.client());
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateWelcomeDirect(b, "penumbra-server", hi, server_.Limits().maxFrameBytes,
                                     service::RoleName(role_)));
    Send(MessageType::kWelcome, id, b);
}

void Connection::OnLoadScene(uint32_t id, const fb::LoadScene& l) {
    service::Service& service = server_.GetService();
    // Checked whole here, so a bad request is refused before anything loads.
    service::LoadRequest req = ReadLoadScene(l, service);
    req.by = id_;
    req.role = role_;
    if (l.progress()) req.progress = ProgressSender(id);
    Blocking(
        id, [&service, req] { return service.Load(req); },
        [this, id](service::LoadResult& r) {
            flatbuffers::FlatBufferBuilder b;
            BuildSceneInfo(b, *r.session, r.reused);
            lastScene_ = r.session->Name();
            server_.GetService().Hold(lastScene_, id_);
            if (!r.reused) server_.GetService().Own(lastScene_, id_);
            for (const std::string& gone : r.evicted)
                server_.Log(Who() + ": evicted " + gone +
                            " to make room (no client held it; --max-scenes)");
            const auto* info = flatbuffers::GetRoot<fb::SceneInfo>(b.GetBufferPointer());
            char built[32];
            std::snprintf(built, sizeof(built), "%.2f", info->build_seconds());
            server_.Log(Who() + (r.reused ? ": joined " : ": loaded ") + r.session->Name() +
                        " (solver " + Str(info->solver()) + " on " + Str(info->device()) + ", " +
                        std::to_string(info->elements()) + " elements, built in " + built + " s)");
            if (info->warnings() && !r.reused)
                for (const auto* w : *info->warnings())
                    server_.Log("warning: " + r.session->Name() + ": " + w->str());
            Send(MessageType::kSceneInfo, id, b);  // after the log: a client sees both
            // A reload: the old build's subscribers move to the new one.
            if (r.replaced) server_.SceneReplaced(r.session);
        });
}

void Connection::OnUnloadScene(uint32_t id, const fb::UnloadScene& u) {
    const std::string name = Str(u.scene()).empty() ? lastScene_ : Str(u.scene());
    std::shared_ptr<service::Session> session = server_.GetService().Unload(name, id_, role_);
    const std::string scene = session->Name();
    server_.Log(Who() + ": unloaded " + scene);
    if (lastScene_ == scene) lastScene_.clear();
    Unsubscribe(scene);
    server_.SceneGone(scene, "scene '" + scene + "' was unloaded by " + Who());
    // The session's worker stops as the last reference goes, which can wait out an
    // iteration: on the blocking pool, not the I/O thread.
    Blocking(
        id,
        [session = std::move(session)]() mutable {
            session.reset();
            return 0;
        },
        [this, id](int) { SendOk(id); });
}

void Connection::SceneGone(const std::string& name, const std::string& why) {
    if (!subscriptions_.count(name)) return;
    Unsubscribe(name);
    if (lastScene_ == name) lastScene_.clear();
    SendError(0, fb::ErrorCode::NoScene, why);
}

ProgressFn Connection::ProgressSender(uint32_t id) {
    // Called on the loading thread: at most five messages a second (and every change of
    // stage), each posted to the I/O thread; the time left is this stage's, from its pace.
    struct State {
        std::string stage;
        std::chrono::steady_clock::time_point stageStart, lastSent;
    };
    auto state = std::make_shared<State>();
    std::weak_ptr<Connection> weak = shared_from_this();
    Server* server = &server_;
    return [weak, server, id, state](const std::string& stage, double fraction) {
        const auto now = std::chrono::steady_clock::now();
        const bool newStage = stage != state->stage;
        if (newStage) state->stage = stage, state->stageStart = now;
        if (!newStage && fraction < 1.0 && now - state->lastSent < std::chrono::milliseconds(200))
            return;
        state->lastSent = now;
        const double spent = std::chrono::duration<double>(now - state->stageStart).count();
        const double left =
            fraction > 0.02 && spent > 0.1 ? spent * (1.0 - fraction) / fraction : -1.0;
        asio::post(server->Io(), [weak, id, stage, fraction, left] {
            auto c = weak.lock();
            if (!c) return;
            flatbuffers::FlatBufferBuilder b;
            b.Finish(fb::CreateProgressDirect(b, stage.c_str(), fraction, left));
            c->Send(MessageType::kProgress, id, b);
        });
    };
}

std::shared_ptr<service::Session> Connection::SessionOf(const flatbuffers::String* scene) {
    const std::string name = Str(scene);
    // "": the scene this connection loaded or joined last; the newest for one that did not.
    return server_.GetService().Find(name.empty() ? lastScene_ : name);
}

std::shared_ptr<service::Session> Connection::EditableSession(const flatbuffers::String* scene) {
    auto session = SessionOf(scene);
    server_.GetService().CheckMay(session->Name(), id_, role_, service::Change::kEdit);
    return session;
}

void Connection::OnSetEnvironment(uint32_t id, const fb::SetEnvironment& s) {
    service::Service& service = server_.GetService();
    auto session = EditableSession(s.scene());
    EnvironmentRequest r = ReadSetEnvironment(s);
    // Reading a sky map takes a while: on the blocking pool.
    Blocking(
        id,
        [&service, session, r]() mutable {
            if (!r.path.empty() || r.color)
                r.edit.replace = service.MakeEnvironment(r.path, r.color);
            return session->Submit(r.edit);
        },
        [this, id](uint64_t edit) { SendAck(id, edit); });
}

void Connection::OnSubscribe(uint32_t id, const fb::Subscribe& s) {
    const float tolerance = s.tolerance();
    if (!std::isfinite(tolerance) || tolerance > 1.0f)
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "Subscribe tolerance " + std::to_string(tolerance) +
                               ": give a relative tolerance in [0, 1] for a delta stream (0.005 "
                               "is a half percent; 0 sends every change of a vertex's fp16 "
                               "value), or a negative one for whole frames");
    SubscribeTo(SessionOf(s.scene()), ChannelOf(s.channel()), s.format(),
                tolerance < 0.0f ? -1.0f : tolerance);
    SendOk(id);
}

void Connection::SubscribeTo(const std::shared_ptr<service::Session>& session,
                             service::Channel channel, fb::Format format, float tolerance) {
    Unsubscribe(session->Name());
    std::weak_ptr<Connection> weak = shared_from_this();
    Server* server = &server_;
    const std::string name = session->Name();
    int sub = session->AddSubscriber([weak, server, name](const service::FramePtr& frame) {
        asio::post(server->Io(), [weak, name, frame] {
            if (auto c = weak.lock()) c->PushFrame(name, frame);
        });
    });
    Subscription& s = subscriptions_[name];
    s = Subscription{};
    s.session = session;
    s.id = sub;
    s.channel = channel;
    s.format = format;
    s.tolerance = tolerance;
}

void Connection::SceneReplaced(const std::shared_ptr<service::Session>& fresh) {
    auto it = subscriptions_.find(fresh->Name());
    if (it == subscriptions_.end() || it->second.session.lock() == fresh) return;
    const Subscription was = it->second;
    flatbuffers::FlatBufferBuilder b;
    BuildSceneInfo(b, *fresh, false);
    Send(MessageType::kSceneInfo, 0, b);  // before the new build's frames
    SubscribeTo(fresh, was.channel, was.format, was.tolerance);
}

void Connection::OnGetIrradiance(uint32_t id, const fb::GetIrradiance& g) {
    auto session = SessionOf(g.scene());
    const service::Channel channel = ChannelOf(g.channel());
    const fb::Format format = g.format();
    Blocking(
        id, [session] { return session->Latest(); },
        [this, id, channel, format](service::FramePtr& frame) {
            flatbuffers::FlatBufferBuilder b;
            BuildFramePayload(b, *frame, channel, format);
            Send(MessageType::kFrame, id, b);
        });
}

void Connection::OnStep(uint32_t id, const fb::Step& s) {
    auto session = EditableSession(s.scene());  // its iterations are the scene's, everyone's
    const int n = s.iterations();
    Blocking(
        id, [session, n] { return session->Step(n); },
        [this, id](uint64_t& frame) { SendOk(id, frame); });
}

void Connection::OnGetStats(uint32_t id, const fb::GetStats& g) {
    const std::string scene = Str(g.scene());
    service::Service& service = server_.GetService();
    nlohmann::json j = scene.empty() ? service.StatsJson() : service.Find(scene)->StatsJson();
    j["server"] = server_.StatsJson();
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateStatsDirect(b, j.dump().c_str()));
    Send(MessageType::kStats, id, b);
}

void Connection::Unsubscribe(const std::string& scene) {
    for (auto it = subscriptions_.begin(); it != subscriptions_.end();) {
        if (scene.empty() || it->first == scene) {
            if (auto s = it->second.session.lock()) s->RemoveSubscriber(it->second.id);
            it = subscriptions_.erase(it);
        } else {
            ++it;
        }
    }
}

}  // namespace penumbra::net
