// Client: one blocking socket, a reader thread that routes replies by request id and
// pushed frames to the subscriber callback.
#include "client/client.h"

#include <asio.hpp>
#include <chrono>
#include <condition_variable>
#include <map>
#include <mutex>
#include <thread>

#include "protocol/delta.h"
#include "protocol/frame.h"

namespace penumbra::client {

namespace fb = protocol::fb;
using protocol::MessageType;

const NodeInfo* SceneInfo::Node(const std::string& name) const {
    for (const auto& n : nodes)
        if (n.name == name) return &n;
    return nullptr;
}

namespace {

std::string Str(const flatbuffers::String* s) { return s ? s->str() : std::string(); }

Frame ToFrame(const protocol::Message& m) {
    const auto* f = m.As<fb::Frame>();
    Frame out;
    out.scene = Str(f->scene());
    out.frame = f->frame();
    out.lastEdit = f->last_edit();
    out.iterations = f->iterations();
    out.frameMs = f->frame_ms();
    out.editLatencyMs = f->edit_latency_ms();
    out.converged = f->converged();
    out.channel = static_cast<Channel>(f->channel());
    out.note = Str(f->note());
    out.wireBytes = protocol::kHeaderBytes + m.payload.size();
    if (f->passes())
        for (const auto* p : *f->passes()) out.passes.emplace_back(Str(p->name()), p->ms());
    if (f->primitives())
        for (const auto* p : *f->primitives()) {
            Frame::Primitive prim;
            prim.node = Str(p->node());
            prim.mesh = p->mesh();
            prim.primitive = p->primitive();
            if (p->f32()) prim.rgb.assign(p->f32()->begin(), p->f32()->end());
            if (p->f16()) {
                prim.rgb.reserve(p->f16()->size());
                for (uint16_t h : *p->f16()) prim.rgb.push_back(protocol::HalfToFloat(h));
            }
            out.primitives.push_back(std::move(prim));
        }
    return out;
}

// What a delta subscription holds of its scene (SPEC.md "Delta frames"): the newest frame's
// values, fp16, and the keyframe's primitives.
struct DeltaCopy {
    uint64_t frame = 0;
    std::vector<uint16_t> values;  // 3 a vertex
    std::vector<Frame::Primitive> layout;
    std::vector<uint32_t> counts;
};

// A delta stream's frame applied to `copy`, whole in `out` (ToFrame's, with values).
// Throws protocol::DeltaError for a frame that does not fit what the copy holds.
void ApplyDeltaFrame(const fb::Frame& f, DeltaCopy& copy, Frame& out) {
    const fb::DeltaIrradiance& d = *f.delta();
    if (d.encoding() != protocol::kDeltaZstd)
        throw protocol::DeltaError("delta frame in encoding " + std::to_string(d.encoding()) +
                                   ", which this client does not know");
    if (!d.data()) throw protocol::DeltaError("delta frame without data");
    if (d.keyframe()) {
        if (!d.counts() || d.counts()->size() != out.primitives.size())
            throw protocol::DeltaError("keyframe whose counts do not match its primitives");
        uint64_t total = 0;
        for (uint32_t c : *d.counts()) total += c;
        if (total != d.vertices()) throw protocol::DeltaError("keyframe counts ≠ its vertices");
        DeltaCopy fresh;
        fresh.values.assign(size_t(d.vertices()) * 3, 0);
        protocol::ApplyDelta({d.data()->data(), d.data()->size()}, d.raw_bytes(), true,
                             fresh.values);
        fresh.layout = std::move(out.primitives);
        fresh.counts.assign(d.counts()->begin(), d.counts()->end());
        copy = std::move(fresh);
    } else {
        if (copy.frame == 0 || d.base_frame() != copy.frame ||
            d.vertices() * 3 != copy.values.size())
            throw protocol::DeltaError("delta frame " + std::to_string(f.frame()) +
                                       " changes frame " + std::to_string(d.base_frame()) +
                                       ", and this client holds frame " +
                                       std::to_string(copy.frame));
        protocol::ApplyDelta({d.data()->data(), d.data()->size()}, d.raw_bytes(), false,
                             copy.values);
    }
    copy.frame = f.frame();
    out.keyframe = d.keyframe();
    out.primitives = copy.layout;
    size_t at = 0;
    for (size_t p = 0; p < out.primitives.size(); ++p) {
        auto& rgb = out.primitives[p].rgb;
        rgb.resize(size_t(copy.counts[p]) * 3);
        for (float& v : rgb) v = protocol::HalfToFloat(copy.values[at++]);
    }
}

SceneInfo ToSceneInfo(const protocol::Message& m) {
    const auto* s = m.As<fb::SceneInfo>();
    SceneInfo out;
    out.scene = Str(s->scene());
    out.solver = Str(s->solver());
    out.device = Str(s->device());
    out.elements = s->elements();
    out.links = s->links();
    out.buildSeconds = s->build_seconds();
    out.reused = s->reused();
    if (s->environment()) out.environment = s->environment()->str();
    out.environmentIntensity = s->environment_intensity();
    out.divergence = Str(s->divergence());
    if (s->warnings())
        for (const auto* w : *s->warnings()) out.warnings.push_back(w->str());
    if (s->refined())
        for (const auto* r : *s->refined()) {
            RefinedPrimitive p;
            p.node = Str(r->node());
            p.mesh = r->mesh();
            p.primitive = r->primitive();
            if (r->positions()) p.positions.assign(r->positions()->begin(), r->positions()->end());
            if (r->normals()) p.normals.assign(r->normals()->begin(), r->normals()->end());
            if (r->indices()) p.indices.assign(r->indices()->begin(), r->indices()->end());
            if (r->parent_triangles())
                p.parentTriangles.assign(r->parent_triangles()->begin(),
                                         r->parent_triangles()->end());
            out.refined.push_back(std::move(p));
        }
    if (s->nodes())
        for (const auto* n : *s->nodes()) {
            NodeInfo node;
            node.name = Str(n->name());
            node.dynamic = n->dynamic();
            node.emissive = n->emissive();
            if (n->matrix() && n->matrix()->size() == 16)
                for (int i = 0; i < 16; ++i) node.matrix[i] = n->matrix()->Get(i);
            if (n->bounds_min() && n->bounds_max()) {
                const fb::Vec3 *lo = n->bounds_min(), *hi = n->bounds_max();
                node.boundsMin = std::array<float, 3>{lo->x(), lo->y(), lo->z()};
                node.boundsMax = std::array<float, 3>{hi->x(), hi->y(), hi->z()};
            }
            node.morphTargets = n->morph_targets();
            if (n->morph_weights())
                node.morphWeights.assign(n->morph_weights()->begin(), n->morph_weights()->end());
            if (n->primitives())
                for (const auto* p : *n->primitives())
                    node.primitives.push_back(
                        {p->mesh(), p->primitive(), p->vertices(), Str(p->material())});
            out.nodes.push_back(std::move(node));
        }
    auto vec = [](const fb::Vec3* v) {
        return v ? std::array<float, 3>{v->x(), v->y(), v->z()} : std::array<float, 3>{};
    };
    if (s->lights())
        for (const auto* l : *s->lights()) {
            LightInfo light;
            light.name = Str(l->name());
            light.node = Str(l->node());
            light.type = Str(l->type());
            light.color = vec(l->color());
            light.position = vec(l->position());
            light.direction = vec(l->direction());
            light.intensity = l->intensity();
            light.range = l->range();
            light.innerCone = l->inner_cone();
            light.outerCone = l->outer_cone();
            out.lights.push_back(light);
        }
    if (s->materials())
        for (const auto* m2 : *s->materials()) {
            MaterialInfo mat;
            mat.name = Str(m2->name());
            if (m2->albedo())
                mat.albedo = {m2->albedo()->x(), m2->albedo()->y(), m2->albedo()->z()};
            mat.roughness = m2->roughness();
            mat.metallic = m2->metallic();
            if (m2->emission())
                mat.emission = {m2->emission()->x(), m2->emission()->y(), m2->emission()->z()};
            out.materials.push_back(mat);
        }
    return out;
}

}  // namespace

struct Client::Impl {
    asio::io_context io;
    asio::generic::stream_protocol::socket socket{io};
    std::thread reader;
    std::mutex mutex;  // guards everything below and serialises writes
    std::condition_variable replied;
    std::map<uint32_t, std::optional<protocol::Message>> waiting;
    uint32_t nextId = 1;
    bool open = true;
    std::string lostReason = "connection closed";
    uint16_t lostCode = 0;  // the code of the Error the server sent as it closed, else 0
    FrameCallback callback;
    EndCallback ended;                                       // the subscription's end (Subscribe)
    std::map<uint32_t, ProgressCallback> progressCallbacks;  // by request id
    uint16_t version = 0;
    std::string role;

    void Connect(const std::string& url) {
        std::error_code ec;
        if (url.rfind("unix://", 0) == 0) {
            asio::local::stream_protocol::socket s(io);
            s.connect(asio::local::stream_protocol::endpoint(url.substr(7)), ec);
            if (ec) throw ClientError(0, "cannot connect to " + url + ": " + ec.message());
            socket = asio::generic::stream_protocol::socket(std::move(s));
        } else if (url.rfind("tcp://", 0) == 0) {
            std::string rest = url.substr(6);
            size_t colon = rest.rfind(':');
            if (colon == std::string::npos)
                throw ClientError(0, "'" + url + "': expected tcp://HOST:PORT");
            asio::ip::tcp::resolver resolver(io);
            auto endpoints = resolver.resolve(rest.substr(0, colon), rest.substr(colon + 1), ec);
            if (ec) throw ClientError(0, "cannot resolve " + url + ": " + ec.message());
            asio::ip::tcp::socket s(io);
            asio::connect(s, endpoints, ec);
            if (ec) throw ClientError(0, "cannot connect to " + url + ": " + ec.message());
            s.set_option(asio::ip::tcp::no_delay(true), ec);
            socket = asio::generic::stream_protocol::socket(std::move(s));
        } else {
            throw ClientError(0, "'" + url + "': expected tcp://HOST:PORT or unix:///PATH");
        }
        reader = std::thread([this] { Read(); });
    }

    void Read() {
        // Frames from the server can be large (irradiance of big scenes): no payload limit
        // beyond the protocol's ceiling.
        protocol::Decoder decoder(protocol::kMaxPayloadCeiling);
        std::vector<uint8_t> buf(256 * 1024);
        std::string reason = "the server closed the connection";
        uint16_t code = 0;
        bool failed = false;
        // A delta subscription's copy of each scene (reader thread only).
        std::map<std::string, DeltaCopy> deltas;
        while (true) {
            std::error_code ec;
            size_t n = socket.read_some(asio::buffer(buf), ec);
            if (ec) {
                if (ec != asio::error::eof) reason = "connection lost: " + ec.message();
                break;
            }
            decoder.Feed(buf.data(), n);
            protocol::Message m;
            protocol::Decoder::Result r;
            while ((r = decoder.Next(m)) == protocol::Decoder::Result::kMessage) {
                if (m.header.type == MessageType::kFrame && m.header.requestId == 0) {
                    FrameCallback cb;
                    {
                        std::lock_guard lock(mutex);
                        cb = callback;
                    }
                    Frame frame = ToFrame(m);
                    if (const auto* f = m.As<fb::Frame>(); f->delta()) {
                        try {
                            ApplyDeltaFrame(*f, deltas[frame.scene], frame);
                        } catch (const protocol::DeltaError& e) {
                            reason = std::string("bad frame from the server: ") + e.what();
                            failed = true;
                            break;
                        }
                    }
                    if (cb) cb(frame);
                    continue;
                }
                if (m.header.type == MessageType::kProgress) {
                    ProgressCallback cb;
                    {
                        std::lock_guard lock(mutex);
                        auto p = progressCallbacks.find(m.header.requestId);
                        if (p != progressCallbacks.end()) cb = p->second;
                    }
                    const auto* pr = m.As<fb::Progress>();
                    if (cb) cb(Str(pr->stage()), pr->fraction(), pr->seconds_left());
                    continue;
                }
                if (m.header.type == MessageType::kError && m.header.requestId == 0 &&
                    m.As<fb::Error>()->code() == fb::ErrorCode::NoScene) {
                    // The subscription's scene went (UnloadScene): the connection stays.
                    EndCallback cb;
                    {
                        std::lock_guard lock(mutex);
                        cb = ended;
                    }
                    if (cb) cb(Str(m.As<fb::Error>()->message()));
                    continue;
                }
                std::lock_guard lock(mutex);
                auto it = waiting.find(m.header.requestId);
                if (it != waiting.end()) {
                    it->second = std::move(m);
                    replied.notify_all();
                } else if (m.header.type == MessageType::kError) {
                    // An unsolicited error (the server is full, or closing us): keep it as
                    // the reason the connection ends, with its code.
                    reason = Str(m.As<fb::Error>()->message());
                    code = static_cast<uint16_t>(m.As<fb::Error>()->code());
                }
            }
            if (failed) break;
            if (r == protocol::Decoder::Result::kError) {
                reason = "bad data from the server: " + decoder.error();
                break;
            }
        }
        std::lock_guard lock(mutex);
        open = false;
        lostReason = reason;
        lostCode = code;
        replied.notify_all();
    }

    // Sends one request and waits for its reply; Error replies throw.
    // With `progress`, the Progress messages sent under the request's id go to it (on the
    // reader thread) until the reply comes.
    protocol::Message Call(MessageType type, flatbuffers::FlatBufferBuilder& b, MessageType expect,
                           const ProgressCallback* progress = nullptr) {
        std::unique_lock lock(mutex);
        if (!open) throw ClientError(lostCode, lostReason);
        uint32_t id = nextId++;
        waiting[id];
        if (progress) progressCallbacks[id] = *progress;
        struct Forget {
            Impl* impl;
            uint32_t id;
            ~Forget() { impl->progressCallbacks.erase(id); }  // under the lock
        } forget{this, id};
        auto bytes = protocol::EncodeFrame(type, id, b);
        std::error_code ec;
        asio::write(socket, asio::buffer(bytes), ec);
        if (ec) {
            waiting.erase(id);
            // The server may have said why it closed (a full server, a missed deadline): the
            // reader takes that in as the connection ends.
            replied.wait_for(lock, std::chrono::seconds(2), [&] { return !open; });
            if (!open && lostCode) throw ClientError(lostCode, lostReason);
            throw ClientError(
                0, "cannot send " + std::string(protocol::MessageName(type)) + ": " + ec.message());
        }
        replied.wait(lock, [&] { return waiting[id].has_value() || !open; });
        std::optional<protocol::Message> reply = std::move(waiting[id]);
        waiting.erase(id);
        if (!reply) throw ClientError(lostCode, lostReason);
        if (reply->header.type == MessageType::kError) {
            const auto* e = reply->As<fb::Error>();
            throw ClientError(static_cast<uint16_t>(e->code()), Str(e->message()));
        }
        if (reply->header.type != expect)
            throw ClientError(0, std::string("expected ") + protocol::MessageName(expect) +
                                     ", got " + protocol::MessageName(reply->header.type));
        return std::move(*reply);
    }
};

Client::Client(const std::string& url, const std::string& clientName, const std::string& token)
    : impl_(std::make_unique<Impl>()) {
    impl_->Connect(url);
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateHelloDirect(b, clientName.c_str(), protocol::kMinProtocolVersion,
                                   protocol::kMaxProtocolVersion,
                                   token.empty() ? nullptr : token.c_str()));
    try {
        auto m = impl_->Call(MessageType::kHello, b, MessageType::kWelcome);
        const auto* welcome = m.As<fb::Welcome>();
        impl_->version = welcome->version();
        impl_->role = welcome->role() ? welcome->role()->str() : "user";
    } catch (...) {
        // Refused at Hello (a version mismatch, a wrong token): stop the reader before the
        // exception leaves, so that nothing is left running.
        std::error_code ec;
        impl_->socket.shutdown(asio::socket_base::shutdown_both, ec);
        if (impl_->reader.joinable()) impl_->reader.join();
        impl_->socket.close(ec);
        throw;
    }
}

Client::~Client() {
    try {
        Close();
    } catch (...) {
    }
}

void Client::Close() {
    if (!impl_->reader.joinable()) return;
    if (Connected()) {
        flatbuffers::FlatBufferBuilder b;
        b.Finish(fb::CreateBye(b));
        try {
            impl_->Call(MessageType::kBye, b, MessageType::kBye);
        } catch (const ClientError&) {
        }
    }
    std::error_code ec;
    impl_->socket.shutdown(asio::socket_base::shutdown_both, ec);
    impl_->reader.join();
    impl_->socket.close(ec);
}

void Client::Wait() {
    std::unique_lock lock(impl_->mutex);
    impl_->replied.wait(lock, [&] { return !impl_->open; });
}

bool Client::Connected() const {
    std::lock_guard lock(impl_->mutex);
    return impl_->open;
}

uint16_t Client::ProtocolVersion() const { return impl_->version; }
const std::string& Client::Role() const { return impl_->role; }

SceneInfo Client::Load(const LoadOptions& o) {
    flatbuffers::FlatBufferBuilder b(1024 + o.glb.size());
    std::optional<fb::Vec3> sky;
    if (o.environmentColor)
        sky =
            fb::Vec3((*o.environmentColor)[0], (*o.environmentColor)[1], (*o.environmentColor)[2]);
    std::optional<fb::Vec3> sun;
    if (o.sun) sun = fb::Vec3((*o.sun)[0], (*o.sun)[1], (*o.sun)[2]);
    std::vector<flatbuffers::Offset<fb::SolverOption>> options;
    for (const auto& [name, value] : o.solverOptions)
        options.push_back(fb::CreateSolverOptionDirect(b, name.c_str(), value.c_str()));
    // bins, link_oracle and oracle: protocol 1's shorthands, left unset (solverOptions).
    b.Finish(fb::CreateLoadSceneDirect(
        b, o.path.empty() ? nullptr : o.path.c_str(), o.glb.empty() ? nullptr : &o.glb,
        o.name.empty() ? nullptr : o.name.c_str(), o.solver.c_str(), 0, o.iterationsPerFrame,
        o.elementSize, o.device.empty() ? nullptr : o.device.c_str(), o.reload, nullptr, 1.0f,
        o.convergedChange, o.environment.empty() ? nullptr : o.environment.c_str(),
        sky ? &*sky : nullptr, o.environmentIntensity, o.environmentRotation, o.emitterRays,
        o.gatherRays, options.empty() ? nullptr : &options, bool(o.progress), sun ? &*sun : nullptr,
        o.clearSky ? "clear" : nullptr, o.turbidity, o.refine));
    return ToSceneInfo(impl_->Call(MessageType::kLoadScene, b, MessageType::kSceneInfo,
                                   o.progress ? &o.progress : nullptr));
}

SceneInfo Client::Info(const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateGetSceneInfoDirect(b, scene.c_str()));
    return ToSceneInfo(impl_->Call(MessageType::kGetSceneInfo, b, MessageType::kSceneInfo));
}

uint64_t Client::SetTransform(const std::string& node, const std::array<float, 16>& matrix,
                              const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    std::vector<float> m(matrix.begin(), matrix.end());
    b.Finish(fb::CreateSetTransformDirect(b, scene.c_str(), node.c_str(), &m));
    return impl_->Call(MessageType::kSetTransform, b, MessageType::kEditAck)
        .As<fb::EditAck>()
        ->edit_id();
}

uint64_t Client::SetVertices(const std::string& node, const std::vector<float>& positions,
                             const std::vector<float>& normals, const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateSetVerticesDirect(b, scene.c_str(), node.c_str(), &positions,
                                         normals.empty() ? nullptr : &normals));
    return impl_->Call(MessageType::kSetVertices, b, MessageType::kEditAck)
        .As<fb::EditAck>()
        ->edit_id();
}

uint64_t Client::SetMorphWeights(const std::string& node, const std::vector<float>& weights,
                                 const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(
        fb::CreateSetVerticesDirect(b, scene.c_str(), node.c_str(), nullptr, nullptr, &weights));
    return impl_->Call(MessageType::kSetVertices, b, MessageType::kEditAck)
        .As<fb::EditAck>()
        ->edit_id();
}

uint64_t Client::SetLight(const std::string& light, std::optional<std::array<float, 3>> color,
                          std::optional<float> intensity, const std::string& scene) {
    LightChange change;
    change.color = color;
    change.intensity = intensity;
    return SetLight(light, change, scene);
}

uint64_t Client::SetLight(const std::string& light, const LightChange& change,
                          const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    auto vec = [](const std::optional<std::array<float, 3>>& v) {
        return v ? fb::Vec3((*v)[0], (*v)[1], (*v)[2]) : fb::Vec3();
    };
    fb::Vec3 c = vec(change.color), p = vec(change.position), d = vec(change.direction);
    b.Finish(
        fb::CreateSetLightDirect(b, scene.c_str(), light.c_str(), change.color ? &c : nullptr,
                                 change.intensity.value_or(-1.0f), change.position ? &p : nullptr,
                                 change.direction ? &d : nullptr, change.innerCone.value_or(-1.0f),
                                 change.outerCone.value_or(-1.0f), change.range.value_or(-1.0f)));
    return impl_->Call(MessageType::kSetLight, b, MessageType::kEditAck)
        .As<fb::EditAck>()
        ->edit_id();
}

uint64_t Client::SetMaterial(const std::string& material,
                             std::optional<std::array<float, 3>> albedo,
                             std::optional<std::array<float, 3>> emission,
                             const std::string& scene) {
    return SetMaterial(material, MaterialChange{albedo, emission, {}, {}}, scene);
}

uint64_t Client::SetEnvironment(const EnvironmentChange& change, const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    fb::Vec3 c = change.color ? fb::Vec3((*change.color)[0], (*change.color)[1], (*change.color)[2])
                              : fb::Vec3();
    const fb::Vec3 sun = change.sun ? fb::Vec3((*change.sun)[0], (*change.sun)[1],
                                               change.sunIlluminance.value_or(-1.0f))
                                    : fb::Vec3();
    b.Finish(fb::CreateSetEnvironmentDirect(
        b, scene.c_str(), change.path.empty() ? nullptr : change.path.c_str(),
        change.color ? &c : nullptr, change.off, change.intensity.value_or(-1.0f),
        change.rotation.value_or(0.0f), change.rotation.has_value(), change.sun ? &sun : nullptr,
        change.clearSky ? "clear" : nullptr, change.turbidity.value_or(-1.0f)));
    return impl_->Call(MessageType::kSetEnvironment, b, MessageType::kEditAck)
        .As<fb::EditAck>()
        ->edit_id();
}

uint64_t Client::SetMaterial(const std::string& material, const MaterialChange& change,
                             const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    const auto& albedo = change.albedo;
    const auto& emission = change.emission;
    fb::Vec3 a = albedo ? fb::Vec3((*albedo)[0], (*albedo)[1], (*albedo)[2]) : fb::Vec3();
    fb::Vec3 e = emission ? fb::Vec3((*emission)[0], (*emission)[1], (*emission)[2]) : fb::Vec3();
    b.Finish(fb::CreateSetMaterialDirect(b, scene.c_str(), material.c_str(), albedo ? &a : nullptr,
                                         emission ? &e : nullptr, change.roughness.value_or(-1.0f),
                                         change.metallic.value_or(-1.0f)));
    return impl_->Call(MessageType::kSetMaterial, b, MessageType::kEditAck)
        .As<fb::EditAck>()
        ->edit_id();
}

void Client::Subscribe(FrameCallback callback, Channel channel, Format format,
                       const std::string& scene, EndCallback ended, float tolerance) {
    if (format == Format::kDelta && !(tolerance >= 0.0f && tolerance <= 1.0f))
        throw ClientError(20,
                          "a delta stream's tolerance is in [0, 1] (0.005: half a percent; "
                          "0: every change of a vertex's fp16 value)");
    {
        std::lock_guard lock(impl_->mutex);
        impl_->callback = std::move(callback);
        impl_->ended = std::move(ended);
    }
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateSubscribeDirect(
        b, scene.c_str(), static_cast<fb::Channel>(channel),
        format == Format::kDelta ? fb::Format::Float16 : static_cast<fb::Format>(format),
        format == Format::kDelta ? tolerance : -1.0f));
    impl_->Call(MessageType::kSubscribe, b, MessageType::kOk);
}

void Client::Unsubscribe(const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateUnsubscribeDirect(b, scene.c_str()));
    impl_->Call(MessageType::kUnsubscribe, b, MessageType::kOk);
}

void Client::UnloadScene(const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateUnloadSceneDirect(b, scene.c_str()));
    impl_->Call(MessageType::kUnloadScene, b, MessageType::kOk);
}

Frame Client::Get(Channel channel, Format format, const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    // One frame, whole: a delta stream's format asks for its values' fp16.
    b.Finish(fb::CreateGetIrradianceDirect(
        b, scene.c_str(), static_cast<fb::Channel>(channel),
        format == Format::kDelta ? fb::Format::Float16 : static_cast<fb::Format>(format)));
    return ToFrame(impl_->Call(MessageType::kGetIrradiance, b, MessageType::kFrame));
}

uint64_t Client::Step(int iterations, const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateStepDirect(b, scene.c_str(), iterations));
    return impl_->Call(MessageType::kStep, b, MessageType::kOk).As<fb::Ok>()->frame();
}

std::string Client::Stats(const std::string& scene) {
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateGetStatsDirect(b, scene.c_str()));
    return Str(impl_->Call(MessageType::kGetStats, b, MessageType::kStats).As<fb::Stats>()->json());
}

}  // namespace penumbra::client
