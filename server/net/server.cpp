// Acceptors, connections, request dispatch and frame streaming (protocol/SPEC.md).
#include "net/server.h"

#include <cstdio>
#include <deque>
#include <filesystem>
#include <limits>

#include "base/check.h"
#include "gather/gather_stage.h"
#include "solver/registry.h"

namespace penumbra::net {

namespace fb = protocol::fb;
using protocol::MessageType;
using service::ErrorKind;
using service::ServiceError;

namespace {

fb::ErrorCode CodeOf(ErrorKind kind) {
    switch (kind) {
        case ErrorKind::kInvalidArgument:
            return fb::ErrorCode::InvalidArgument;
        case ErrorKind::kNotFound:
            return fb::ErrorCode::NotFound;
        case ErrorKind::kNoScene:
            return fb::ErrorCode::NoScene;
        case ErrorKind::kOutsideRoot:
            return fb::ErrorCode::OutsideRoot;
        case ErrorKind::kLoadFailed:
            return fb::ErrorCode::LoadFailed;
        case ErrorKind::kStaticNode:
            return fb::ErrorCode::StaticNode;
        case ErrorKind::kUnsupported:
            return fb::ErrorCode::Unsupported;
        case ErrorKind::kLimitReached:
            return fb::ErrorCode::LimitReached;
        case ErrorKind::kShuttingDown:
            return fb::ErrorCode::ShuttingDown;
    }
    return fb::ErrorCode::Internal;
}

service::Channel ChannelOf(fb::Channel c) {
    switch (c) {
        case fb::Channel::Direct:
            return service::Channel::kDirect;
        case fb::Channel::Total:
            return service::Channel::kTotal;
        default:
            return service::Channel::kIndirect;
    }
}

std::string Str(const flatbuffers::String* s) { return s ? s->str() : std::string(); }

// An optional float field of an edit: negative means unchanged; NaN counts as given so that
// the session refuses it.
bool Given(float v) { return v >= 0.0f || std::isnan(v); }

std::optional<glm::vec3> Vec(const fb::Vec3* v) {
    if (!v) return std::nullopt;
    return glm::vec3(v->x(), v->y(), v->z());
}

void BuildSceneInfo(flatbuffers::FlatBufferBuilder& b, const service::Session& session,
                    bool reused) {
    Scene scene = session.SceneSnapshot();
    SolverStats stats = session.SolverStatistics();
    std::vector<flatbuffers::Offset<fb::NodeInfo>> nodes;
    for (const auto& n : scene.nodes) {
        bool placesLight = false;
        for (const auto& l : scene.lights) placesLight = placesLight || &scene.nodes[l.node] == &n;
        if (n.primitives.empty() && n.children.empty() && !placesLight) continue;
        std::vector<flatbuffers::Offset<fb::PrimitiveInfo>> prims;
        bool emissive = false;
        for (uint32_t pi : n.primitives) {
            const Primitive& p = scene.primitives[pi];
            const Material& m = scene.materials[p.material];
            emissive = emissive || glm::any(glm::greaterThan(m.emission, glm::vec3(0.0f)));
            prims.push_back(fb::CreatePrimitiveInfoDirect(
                b, p.mesh, p.primitive, static_cast<uint32_t>(p.positions.size()), m.name.c_str()));
        }
        std::vector<float> matrix(16);
        for (int i = 0; i < 16; ++i) matrix[i] = n.local[i / 4][i % 4];
        nodes.push_back(
            fb::CreateNodeInfoDirect(b, n.name.c_str(), n.dynamic, &matrix, &prims, emissive));
    }
    std::vector<flatbuffers::Offset<fb::MaterialInfo>> materials;
    for (const auto& m : scene.materials) {
        fb::Vec3 albedo(m.baseColor.x, m.baseColor.y, m.baseColor.z);
        fb::Vec3 emission(m.emission.x, m.emission.y, m.emission.z);
        materials.push_back(fb::CreateMaterialInfoDirect(b, m.name.c_str(), &albedo, &emission,
                                                         m.roughness, m.metallic));
    }
    std::vector<flatbuffers::Offset<fb::LightInfo>> lights;
    for (const auto& l : scene.lights) {
        fb::Vec3 color(l.color.x, l.color.y, l.color.z);
        fb::Vec3 position(l.position.x, l.position.y, l.position.z);
        fb::Vec3 direction(l.direction.x, l.direction.y, l.direction.z);
        const char* type = l.type == LightType::kPoint  ? "point"
                           : l.type == LightType::kSpot ? "spot"
                                                        : "directional";
        lights.push_back(fb::CreateLightInfoDirect(
            b, l.name.c_str(), scene.nodes[l.node].name.c_str(), type, &color, l.intensity, l.range,
            l.innerCone, l.outerCone, &position, &direction));
    }
    b.Finish(fb::CreateSceneInfoDirect(
        b, session.Name().c_str(), stats.solver.c_str(), stats.device.c_str(), &nodes, &materials,
        static_cast<uint32_t>(stats.elements), stats.links, session.BuildSeconds(), reused, &lights,
        scene.environment.Active() ? scene.environment.source.c_str() : nullptr,
        scene.environment.intensity,
        stats.divergence.empty() ? nullptr : stats.divergence.c_str()));
}

}  // namespace

void BuildFramePayload(flatbuffers::FlatBufferBuilder& b, const service::FrameData& frame,
                       service::Channel channel, fb::Format format) {
    // Channels: `indirect` and `direct` as the session made them (`direct` is zero in a
    // scene without punctual lights), `total` their sum.
    const bool hasDirect = !frame.direct.empty();
    std::vector<flatbuffers::Offset<fb::PrimitiveIrradiance>> prims;
    prims.reserve(frame.irradiance.size());
    std::vector<float> sum;
    for (size_t p = 0; p < frame.irradiance.size(); ++p) {
        const size_t n = frame.irradiance[p].size() * 3;
        const float* values = nullptr;  // null: all zero
        if (channel == service::Channel::kIndirect || (!hasDirect && channel == Channel::kTotal)) {
            values = reinterpret_cast<const float*>(frame.irradiance[p].data());
        } else if (hasDirect && channel == service::Channel::kDirect) {
            values = reinterpret_cast<const float*>(frame.direct[p].data());
        } else if (hasDirect) {
            const float* a = reinterpret_cast<const float*>(frame.irradiance[p].data());
            const float* d = reinterpret_cast<const float*>(frame.direct[p].data());
            sum.resize(n);
            for (size_t i = 0; i < n; ++i) sum[i] = a[i] + d[i];
            values = sum.data();
        }
        flatbuffers::Offset<flatbuffers::Vector<float>> f32 = 0;
        flatbuffers::Offset<flatbuffers::Vector<uint16_t>> f16 = 0;
        if (format == fb::Format::Float16) {
            uint16_t* out = nullptr;
            f16 = b.CreateUninitializedVector(n, &out);
            for (size_t i = 0; i < n; ++i)
                out[i] = protocol::FloatToHalf(values ? values[i] : 0.0f);
        } else if (!values) {
            float* out = nullptr;
            f32 = b.CreateUninitializedVector(n, &out);
            std::fill(out, out + n, 0.0f);
        } else {
            f32 = b.CreateVector(values, n);
        }
        const service::PrimitiveKey& key = (*frame.layout)[p];
        prims.push_back(fb::CreatePrimitiveIrradiance(b, b.CreateSharedString(key.node), key.mesh,
                                                      key.primitive, f32, f16));
    }
    std::vector<flatbuffers::Offset<fb::PassTime>> passes;
    for (const auto& p : frame.passes)
        passes.push_back(fb::CreatePassTimeDirect(b, p.name.c_str(), p.msTotal));
    b.Finish(fb::CreateFrameDirect(b, frame.scene.c_str(), frame.frame, frame.lastEdit,
                                   frame.iterations, frame.frameMs, frame.editLatencyMs,
                                   frame.converged,
                                   channel == service::Channel::kDirect  ? fb::Channel::Direct
                                   : channel == service::Channel::kTotal ? fb::Channel::Total
                                                                         : fb::Channel::Indirect,
                                   &passes, &prims, frame.note.c_str()));
}

// --- Connection -----------------------------------------------------------------------------

class Connection : public std::enable_shared_from_this<Connection> {
  public:
    Connection(Server& server, asio::generic::stream_protocol::socket socket, uint64_t id)
        : server_(server),
          socket_(std::move(socket)),
          id_(id),
          decoder_(server.Limits().maxFrameBytes) {}

    void Start() { Read(); }

    // Closes the socket; pending writes are abandoned.
    void Close() {
        if (closed_) return;
        closed_ = true;
        Unsubscribe("");
        std::error_code ec;
        socket_.shutdown(asio::socket_base::shutdown_both, ec);
        socket_.close(ec);
        server_.Forget(this);
    }

    // Queues a subscribed frame (I/O thread). Keeps at most maxQueuedFrames unsent frames:
    // a slow client sees fewer frames, never stale ones, and never holds up the others.
    void PushFrame(std::shared_ptr<const std::vector<uint8_t>> bytes) {
        if (closed_) return;
        size_t queued = 0;
        for (size_t i = writing_ ? 1 : 0; i < queue_.size(); ++i) queued += queue_[i].frame;
        if (queued >= server_.Limits().maxQueuedFrames) {
            for (size_t i = writing_ ? 1 : 0; i < queue_.size(); ++i)
                if (queue_[i].frame) {
                    queue_.erase(queue_.begin() + static_cast<std::ptrdiff_t>(i));
                    ++server_.framesDropped;
                    break;
                }
        }
        Enqueue(std::move(bytes), true);
    }

  private:
    struct Outgoing {
        std::shared_ptr<const std::vector<uint8_t>> bytes;
        bool frame = false;
    };
    struct Subscription {
        std::weak_ptr<service::Session> session;
        int id = 0;
    };

    void Read() {
        auto self = shared_from_this();
        socket_.async_read_some(asio::buffer(readBuffer_),
                                [this, self](std::error_code ec, size_t n) {
                                    if (closed_) return;
                                    if (ec) {  // peer closed or vanished: nothing to answer
                                        Close();
                                        return;
                                    }
                                    decoder_.Feed(readBuffer_.data(), n);
                                    protocol::Message message;
                                    while (!closed_ && !closing_) {
                                        auto r = decoder_.Next(message);
                                        if (r == protocol::Decoder::Result::kNeedMore) break;
                                        if (r == protocol::Decoder::Result::kError) {
                                            ++server_.protocolErrors;
                                            SendError(decoder_.errorRequestId(),
                                                      decoder_.errorCode(), decoder_.error(), true);
                                            return;
                                        }
                                        Dispatch(message);
                                    }
                                    if (!closed_ && !closing_) Read();
                                });
    }

    void Enqueue(std::shared_ptr<const std::vector<uint8_t>> bytes, bool frame = false) {
        if (closed_) return;
        queue_.push_back({std::move(bytes), frame});
        if (!writing_) WriteNext();
    }

    void WriteNext() {
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

    void Send(MessageType type, uint32_t requestId, const flatbuffers::FlatBufferBuilder& b) {
        Enqueue(std::make_shared<const std::vector<uint8_t>>(
            protocol::EncodeFrame(type, requestId, b)));
    }

    // An Error reply; with `close`, the connection closes once it is written.
    void SendError(uint32_t requestId, fb::ErrorCode code, const std::string& message,
                   bool close = false) {
        flatbuffers::FlatBufferBuilder b;
        b.Finish(fb::CreateErrorDirect(b, code, message.c_str()));
        Send(MessageType::kError, requestId, b);
        if (close) {
            closing_ = true;
            if (!writing_) Close();
        }
    }

    void SendOk(uint32_t requestId, uint64_t frame = 0) {
        flatbuffers::FlatBufferBuilder b;
        b.Finish(fb::CreateOk(b, frame));
        Send(MessageType::kOk, requestId, b);
    }

    // Runs `work` on the blocking pool and `reply` with its result back on the I/O thread;
    // a ServiceError becomes an Error reply.
    template <typename Work, typename Reply>
    void Blocking(uint32_t requestId, Work work, Reply reply) {
        auto self = shared_from_this();
        asio::post(server_.Blocking(), [this, self, requestId, work, reply]() mutable {
            std::function<void()> done;
            try {
                auto result = std::make_shared<decltype(work())>(work());
                done = [this, result, reply]() mutable { reply(*result); };
            } catch (const ServiceError& e) {
                std::string what = e.what();
                fb::ErrorCode code = CodeOf(e.kind());
                done = [this, requestId, code, what] { SendError(requestId, code, what); };
            } catch (const std::exception& e) {
                std::string what = e.what();
                done = [this, requestId, what] {
                    SendError(requestId, fb::ErrorCode::Internal, what);
                };
            }
            asio::post(server_.Io(), [self, done] { done(); });
        });
    }

    void Dispatch(const protocol::Message& m) {
        const uint32_t id = m.header.requestId;
        if (!helloDone_ && m.header.type != MessageType::kHello) {
            SendError(id, fb::ErrorCode::HelloRequired,
                      std::string("the first message must be Hello, got ") +
                          protocol::MessageName(m.header.type),
                      true);
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

    void Handle(const protocol::Message& m) {
        const uint32_t id = m.header.requestId;
        service::Service& service = server_.GetService();
        switch (m.header.type) {
            case MessageType::kHello: {
                const auto* h = m.As<fb::Hello>();
                uint16_t lo = std::max<uint16_t>(h->min_version(), protocol::kMinProtocolVersion);
                uint16_t hi = std::min<uint16_t>(h->max_version(), protocol::kMaxProtocolVersion);
                if (helloDone_) {
                    SendError(id, fb::ErrorCode::InvalidArgument, "Hello was already sent");
                    return;
                }
                if (lo > hi) {
                    SendError(id, fb::ErrorCode::VersionMismatch,
                              "client speaks versions " + std::to_string(h->min_version()) + "–" +
                                  std::to_string(h->max_version()) + ", this server " +
                                  std::to_string(protocol::kMinProtocolVersion) + "–" +
                                  std::to_string(protocol::kMaxProtocolVersion),
                              true);
                    return;
                }
                helloDone_ = true;
                client_ = Str(h->client());
                flatbuffers::FlatBufferBuilder b;
                b.Finish(fb::CreateWelcomeDirect(b, "penumbra-server", hi,
                                                 server_.Limits().maxFrameBytes));
                Send(MessageType::kWelcome, id, b);
                return;
            }
            case MessageType::kBye: {
                flatbuffers::FlatBufferBuilder b;
                b.Finish(fb::CreateBye(b));
                Send(MessageType::kBye, id, b);
                closing_ = true;
                if (!writing_) Close();
                return;
            }
            case MessageType::kLoadScene: {
                const auto* l = m.As<fb::LoadScene>();
                service::LoadRequest req;
                req.path = Str(l->path());
                if (l->glb()) req.glb.assign(l->glb()->begin(), l->glb()->end());
                req.name = Str(l->name());
                req.reload = l->reload();
                req.environmentPath = Str(l->environment());
                if (const fb::Vec3* c = l->environment_color()) {
                    req.hasEnvironmentColor = true;
                    req.environmentColor = glm::vec3(c->x(), c->y(), c->z());
                }
                req.environmentIntensity = l->environment_intensity();
                req.environmentRotation = l->environment_rotation();
                // The solver and its options: each checked against the registry here, so a
                // bad one is refused before anything loads.
                const std::string solver = Str(l->solver());
                try {
                    req.settings.solver =
                        service.DefaultsFor(solver.empty() ? "antiradiance" : solver);
                } catch (const Error& e) {
                    throw ServiceError(ErrorKind::kUnsupported, e.what());
                }
                SolverOptions& options = req.settings.solver.options;
                if (l->options())
                    for (const fb::SolverOption* o : *l->options())
                        options[Str(o->name())] = Str(o->value());
                // Protocol 1's shorthands for three antiradiance options, where given.
                if (l->bins() != 0) options.try_emplace("bins", std::to_string(l->bins()));
                if (l->oracle() != 1.0f) {
                    char text[32];
                    std::snprintf(text, sizeof text, "%.9g", l->oracle());
                    options.try_emplace("oracle", text);
                }
                if (!Str(l->link_oracle()).empty())
                    options.try_emplace("link-oracle", Str(l->link_oracle()));
                if (!(l->element_size() >= 0.0f) || !std::isfinite(l->element_size()))
                    throw ServiceError(ErrorKind::kInvalidArgument,
                                       "element size must be ≥ 0 metres (0: automatic)");
                req.settings.solver.elementSize = l->element_size();
                if (l->iterations_per_frame() < 1 || l->iterations_per_frame() > 64)
                    throw ServiceError(ErrorKind::kInvalidArgument,
                                       "iterations per frame must be 1…64");
                req.settings.iterationsPerFrame = l->iterations_per_frame();
                if (!(l->converged_change() >= 0.0f))
                    throw ServiceError(ErrorKind::kInvalidArgument,
                                       "converged_change must be ≥ 0 (0: never idle)");
                req.settings.convergedChange = l->converged_change();
                if (req.settings.convergedChange == 0.0)
                    req.settings.maxFramesPerEdit = std::numeric_limits<int>::max();
                for (auto [value, field] : {std::pair(l->emitter_rays(), "emitter_rays"),
                                            std::pair(l->gather_rays(), "gather_rays")})
                    if (value < 0 || value > kMaxGatherRays)
                        throw ServiceError(ErrorKind::kInvalidArgument,
                                           std::string(field) + " must be 0 (off) … " +
                                               std::to_string(kMaxGatherRays));
                req.settings.emitterRays = l->emitter_rays();
                req.settings.gatherRays = l->gather_rays();
                if (!Str(l->device()).empty()) {
                    try {
                        req.settings.solver.device = ParseDevice(Str(l->device()));
                    } catch (const Error& e) {
                        throw ServiceError(ErrorKind::kInvalidArgument, e.what());
                    }
                }
                try {
                    CheckSolverSettings(req.settings.solver);
                } catch (const Error& e) {
                    throw ServiceError(ErrorKind::kInvalidArgument, e.what());
                }
                Blocking(
                    id, [&service, req] { return service.Load(req); },
                    [this, id](service::LoadResult& r) {
                        flatbuffers::FlatBufferBuilder b;
                        BuildSceneInfo(b, *r.session, r.reused);
                        Send(MessageType::kSceneInfo, id, b);
                    });
                return;
            }
            case MessageType::kGetSceneInfo: {
                auto session = service.Find(Str(m.As<fb::GetSceneInfo>()->scene()));
                flatbuffers::FlatBufferBuilder b;
                BuildSceneInfo(b, *session, true);
                Send(MessageType::kSceneInfo, id, b);
                return;
            }
            case MessageType::kSetTransform: {
                const auto* t = m.As<fb::SetTransform>();
                auto session = service.Find(Str(t->scene()));
                if (!t->matrix() || t->matrix()->size() != 16)
                    throw ServiceError(ErrorKind::kInvalidArgument,
                                       "matrix must have 16 numbers (column-major 4×4)");
                service::TransformEdit e;
                e.node = Str(t->node());
                for (int i = 0; i < 16; ++i) e.local[i / 4][i % 4] = t->matrix()->Get(i);
                SendAck(id, session->Submit(e));
                return;
            }
            case MessageType::kSetLight: {
                const auto* l = m.As<fb::SetLight>();
                auto session = service.Find(Str(l->scene()));
                service::LightEdit e;
                e.light = Str(l->light());
                e.color = Vec(l->color());
                if (Given(l->intensity())) e.intensity = l->intensity();
                e.position = Vec(l->position());
                e.direction = Vec(l->direction());
                if (Given(l->inner_cone())) e.innerCone = l->inner_cone();
                if (Given(l->outer_cone())) e.outerCone = l->outer_cone();
                if (Given(l->range())) e.range = l->range();
                SendAck(id, session->Submit(e));
                return;
            }
            case MessageType::kSetMaterial: {
                const auto* s = m.As<fb::SetMaterial>();
                auto session = service.Find(Str(s->scene()));
                service::MaterialEdit e;
                e.material = Str(s->material());
                e.albedo = Vec(s->albedo());
                e.emission = Vec(s->emission());
                if (Given(s->roughness())) e.roughness = s->roughness();
                if (Given(s->metallic())) e.metallic = s->metallic();
                SendAck(id, session->Submit(e));
                return;
            }
            case MessageType::kSetEnvironment: {
                const auto* s = m.As<fb::SetEnvironment>();
                auto session = service.Find(Str(s->scene()));
                service::EnvironmentEdit e;
                std::string path = Str(s->environment());
                std::optional<glm::vec3> color = Vec(s->environment_color());
                if (s->off() && (!path.empty() || color))
                    throw service::ServiceError(
                        service::ErrorKind::kInvalidArgument,
                        "SetEnvironment: `off` and a new sky cannot both be given");
                if (s->off()) e.replace = Environment{};
                if (Given(s->intensity())) e.intensity = s->intensity();
                if (s->set_rotation()) e.rotation = s->rotation();
                // Reading a sky map takes a while: on the blocking pool.
                Blocking(
                    id,
                    [&service = service, session, e, path, color]() mutable {
                        if (!path.empty() || color)
                            e.replace = service.MakeEnvironment(path, color);
                        return session->Submit(e);
                    },
                    [this, id](uint64_t edit) { SendAck(id, edit); });
                return;
            }
            case MessageType::kSubscribe: {
                const auto* s = m.As<fb::Subscribe>();
                auto session = service.Find(Str(s->scene()));
                auto channel = ChannelOf(s->channel());
                Unsubscribe(session->Name());
                std::weak_ptr<Connection> weak = shared_from_this();
                Server* server = &server_;
                fb::Format format = s->format();
                int sub = session->AddSubscriber(
                    [weak, server, channel, format](const service::FramePtr& frame) {
                        asio::post(server->Io(), [weak, server, channel, format, frame] {
                            if (auto c = weak.lock())
                                c->PushFrame(server->EncodedFrame(frame, channel, format));
                        });
                    });
                subscriptions_[session->Name()] = {session, sub};
                SendOk(id);
                return;
            }
            case MessageType::kUnsubscribe: {
                auto session = service.Find(Str(m.As<fb::Unsubscribe>()->scene()));
                Unsubscribe(session->Name());
                SendOk(id);
                return;
            }
            case MessageType::kGetIrradiance: {
                const auto* g = m.As<fb::GetIrradiance>();
                auto session = service.Find(Str(g->scene()));
                auto channel = ChannelOf(g->channel());
                fb::Format format = g->format();
                Blocking(
                    id, [session] { return session->Latest(); },
                    [this, id, channel, format](service::FramePtr& frame) {
                        flatbuffers::FlatBufferBuilder b;
                        BuildFramePayload(b, *frame, channel, format);
                        Send(MessageType::kFrame, id, b);
                    });
                return;
            }
            case MessageType::kStep: {
                const auto* s = m.As<fb::Step>();
                auto session = service.Find(Str(s->scene()));
                int n = s->iterations();
                Blocking(
                    id, [session, n] { return session->Step(n); },
                    [this, id](uint64_t& frame) { SendOk(id, frame); });
                return;
            }
            case MessageType::kGetStats: {
                std::string scene = Str(m.As<fb::GetStats>()->scene());
                nlohmann::json j;
                if (!scene.empty()) {
                    j = service.Find(scene)->StatsJson();
                } else {
                    j = service.StatsJson();
                }
                j["server"] = server_.StatsJson();
                flatbuffers::FlatBufferBuilder b;
                b.Finish(fb::CreateStatsDirect(b, j.dump().c_str()));
                Send(MessageType::kStats, id, b);
                return;
            }
            default:
                SendError(id, fb::ErrorCode::UnknownType,
                          std::string(protocol::MessageName(m.header.type)) +
                              " is a reply type; a client may not send it");
        }
    }

    void SendAck(uint32_t id, uint64_t edit) {
        flatbuffers::FlatBufferBuilder b;
        b.Finish(fb::CreateEditAck(b, edit));
        Send(MessageType::kEditAck, id, b);
    }

    // "" unsubscribes from every scene.
    void Unsubscribe(const std::string& scene) {
        for (auto it = subscriptions_.begin(); it != subscriptions_.end();) {
            if (scene.empty() || it->first == scene) {
                if (auto s = it->second.session.lock()) s->RemoveSubscriber(it->second.id);
                it = subscriptions_.erase(it);
            } else {
                ++it;
            }
        }
    }

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
    std::string client_;
    std::map<std::string, Subscription> subscriptions_;
};

// --- Server ---------------------------------------------------------------------------------

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

Server::Server(asio::io_context& io, service::Service& service, NetLimits limits)
    : io_(io), service_(service), limits_(limits) {}

Server::~Server() {
    blocking_.join();
    for (const auto& p : unixPaths_) {
        std::error_code ec;
        std::filesystem::remove(p, ec);
    }
}

std::string Server::Listen(const ListenAddress& address, bool allowRemote) {
    std::error_code ec;
    if (address.kind == ListenAddress::Kind::kTcp) {
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
            throw Error("cannot listen on tcp://" + address.host + ":" +
                        std::to_string(address.port) + ": " + ec.message());
        tcp_.push_back(acceptor);
        Accept(acceptor);
        auto bound = acceptor->local_endpoint();
        std::string host = bound.address().is_v6() ? "[" + bound.address().to_string() + "]"
                                                   : bound.address().to_string();
        return "tcp://" + host + ":" + std::to_string(bound.port());
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
            Adopt(asio::generic::stream_protocol::socket(std::move(socket)));
        }
        Accept(acceptor);
    });
}

void Server::Accept(std::shared_ptr<asio::local::stream_protocol::acceptor> acceptor) {
    acceptor->async_accept(
        [this, acceptor](std::error_code ec, asio::local::stream_protocol::socket socket) {
            if (stopping_ || !acceptor->is_open()) return;
            if (!ec) Adopt(asio::generic::stream_protocol::socket(std::move(socket)));
            Accept(acceptor);
        });
}

void Server::Adopt(asio::generic::stream_protocol::socket socket) {
    if (connections_.size() >= limits_.maxClients) {
        // Tell the client why before closing (best effort, synchronous: one small frame).
        flatbuffers::FlatBufferBuilder b;
        std::string why = "the server has its maximum of " + std::to_string(limits_.maxClients) +
                          " clients (--max-clients)";
        b.Finish(fb::CreateErrorDirect(b, fb::ErrorCode::LimitReached, why.c_str()));
        auto bytes = protocol::EncodeFrame(MessageType::kError, 0, b);
        std::error_code ec;
        asio::write(socket, asio::buffer(bytes), ec);
        socket.close(ec);
        return;
    }
    auto c = std::make_shared<Connection>(*this, std::move(socket), nextConnection_++);
    connections_[c.get()] = c;
    c->Start();
}

void Server::Forget(Connection* connection) { connections_.erase(connection); }

void Server::Stop() {
    if (stopping_) return;
    stopping_ = true;
    std::error_code ec;
    for (auto& a : tcp_) a->close(ec);
    for (auto& a : unix_) a->close(ec);
    std::vector<std::shared_ptr<Connection>> open;
    for (auto& [p, weak] : connections_)
        if (auto c = weak.lock()) open.push_back(c);
    for (auto& c : open) c->Close();
    service_.Shutdown();
}

nlohmann::json Server::StatsJson() const {
    nlohmann::json j;
    j["clients"] = connections_.size();
    j["frames_sent"] = framesSent.load();
    j["frames_dropped"] = framesDropped.load();
    j["protocol_errors"] = protocolErrors.load();
    j["max_clients"] = limits_.maxClients;
    j["max_frame_bytes"] = limits_.maxFrameBytes;
    return j;
}

std::shared_ptr<const std::vector<uint8_t>> Server::EncodedFrame(const service::FramePtr& frame,
                                                                 service::Channel channel,
                                                                 fb::Format format) {
    EncodedKey key{frame->scene, frame->frame, frame->converged, static_cast<int>(channel),
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
    // Keep only the newest few frames' encodings.
    while (encoded_.size() > 16) encoded_.erase(encoded_.begin());
    encoded_[key] = bytes;
    return bytes;
}

}  // namespace penumbra::net
