// Protocol tables to service types and back (messages.h).
#include "net/messages.h"

#include <cmath>
#include <cstdio>
#include <limits>

#include "base/check.h"
#include "protocol/delta.h"
#include "solvers/registry.h"

namespace penumbra::net {

namespace fb = protocol::fb;
using service::ErrorKind;
using service::ServiceError;

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
        case ErrorKind::kForbidden:
            return fb::ErrorCode::Forbidden;
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

fb::Channel ChannelOf(service::Channel c) {
    switch (c) {
        case service::Channel::kDirect:
            return fb::Channel::Direct;
        case service::Channel::kTotal:
            return fb::Channel::Total;
        default:
            return fb::Channel::Indirect;
    }
}

std::string Str(const flatbuffers::String* s) { return s ? s->str() : std::string(); }

namespace {

// An optional float field of an edit: negative means unchanged; NaN counts as given so that
// the session refuses it.
bool Given(float v) { return v >= 0.0f || std::isnan(v); }

std::optional<glm::vec3> Vec(const fb::Vec3* v) {
    if (!v) return std::nullopt;
    return glm::vec3(v->x(), v->y(), v->z());
}

// A request's `sky`: "clear" (a clear sky for the scene's sun) or none; anything else refused.
bool ClearSkyAsked(const flatbuffers::String* sky, const char* request) {
    const std::string name = Str(sky);
    if (!name.empty() && name != "clear")
        throw ServiceError(ErrorKind::kInvalidArgument, std::string(request) + ": sky \"" + name +
                                                            "\" is not known (\"clear\" or none)");
    return name == "clear";
}

}  // namespace

service::LoadRequest ReadLoadScene(const fb::LoadScene& load, const service::Service& service) {
    const fb::LoadScene* l = &load;
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
    req.sun = Vec(l->sun());
    req.clearSky = ClearSkyAsked(l->sky(), "LoadScene");
    req.turbidity = l->turbidity();
    req.refine = l->refine();
    if (!(req.refine >= 0.0f) || !std::isfinite(req.refine))
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "LoadScene refine must be 0 (the file's vertices) or a positive number "
                           "of metres");
    // The solver and its options: each checked against the registry here, so a
    // bad one is refused before anything loads.
    const std::string solver = Str(l->solver());
    try {
        req.settings.solver = service.DefaultsFor(solver.empty() ? kDefaultSolver : solver);
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kUnsupported, e.what());
    }
    SolverOptions& options = req.settings.solver.options;
    if (l->options())
        for (const fb::SolverOption* o : *l->options()) options[Str(o->name())] = Str(o->value());
    // Protocol 1's shorthands for three antiradiance options, where given.
    if (l->bins() != 0) options.try_emplace("bins", std::to_string(l->bins()));
    if (l->oracle() != 1.0f) {
        char text[32];
        std::snprintf(text, sizeof text, "%.9g", l->oracle());
        options.try_emplace("oracle", text);
    }
    if (!Str(l->link_oracle()).empty()) options.try_emplace("link-oracle", Str(l->link_oracle()));
    req.settings.solver.elementSize = l->element_size();
    req.settings.iterationsPerFrame = l->iterations_per_frame();
    req.settings.convergedChange = l->converged_change();
    if (req.settings.convergedChange == 0.0)
        req.settings.maxFramesPerEdit = std::numeric_limits<int>::max();
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
        service::CheckSessionSettings(req.settings);
        CheckSolverSettings(req.settings.solver);
    } catch (const Error& e) {
        throw ServiceError(ErrorKind::kInvalidArgument, e.what());
    }
    return req;
}

service::TransformEdit ReadSetTransform(const fb::SetTransform& t) {
    if (!t.matrix() || t.matrix()->size() != 16)
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "matrix must have 16 numbers (column-major 4×4)");
    service::TransformEdit e;
    e.node = Str(t.node());
    for (int i = 0; i < 16; ++i) e.local[i / 4][i % 4] = t.matrix()->Get(i);
    return e;
}

service::DeformEdit ReadSetVertices(const fb::SetVertices& v) {
    service::DeformEdit e;
    e.node = Str(v.node());
    const bool positions = v.positions() && v.positions()->size() > 0;
    const bool weights = v.weights() != nullptr;
    if (positions == weights)
        throw ServiceError(ErrorKind::kInvalidArgument,
                           "SetVertices takes either `positions` or `weights`");
    if (weights) {
        e.weights.emplace(v.weights()->begin(), v.weights()->end());
        if (v.normals() && v.normals()->size() > 0)
            throw ServiceError(ErrorKind::kInvalidArgument,
                               "SetVertices: `normals` go with `positions`, not `weights`");
        return e;
    }
    auto read = [](const flatbuffers::Vector<float>& f, const char* what) {
        if (f.size() % 3 != 0)
            throw ServiceError(ErrorKind::kInvalidArgument, std::string("SetVertices: `") + what +
                                                                "` must hold 3 numbers a vertex (" +
                                                                std::to_string(f.size()) +
                                                                " is not a multiple of 3)");
        std::vector<glm::vec3> out(f.size() / 3);
        for (size_t i = 0; i < out.size(); ++i)
            out[i] = glm::vec3(f.Get(3 * i), f.Get(3 * i + 1), f.Get(3 * i + 2));
        return out;
    };
    e.positions = read(*v.positions(), "positions");
    if (v.normals() && v.normals()->size() > 0) e.normals = read(*v.normals(), "normals");
    return e;
}

service::LightEdit ReadSetLight(const fb::SetLight& l) {
    service::LightEdit e;
    e.light = Str(l.light());
    e.color = Vec(l.color());
    if (Given(l.intensity())) e.intensity = l.intensity();
    e.position = Vec(l.position());
    e.direction = Vec(l.direction());
    if (Given(l.inner_cone())) e.innerCone = l.inner_cone();
    if (Given(l.outer_cone())) e.outerCone = l.outer_cone();
    if (Given(l.range())) e.range = l.range();
    return e;
}

service::MaterialEdit ReadSetMaterial(const fb::SetMaterial& s) {
    service::MaterialEdit e;
    e.material = Str(s.material());
    e.albedo = Vec(s.albedo());
    e.emission = Vec(s.emission());
    if (Given(s.roughness())) e.roughness = s.roughness();
    if (Given(s.metallic())) e.metallic = s.metallic();
    return e;
}

EnvironmentRequest ReadSetEnvironment(const fb::SetEnvironment& s) {
    EnvironmentRequest r;
    service::EnvironmentEdit& e = r.edit;
    r.path = Str(s.environment());
    r.color = Vec(s.environment_color());
    if (s.off() && (!r.path.empty() || r.color))
        throw service::ServiceError(service::ErrorKind::kInvalidArgument,
                                    "SetEnvironment: `off` and a new sky cannot both be given");
    if (s.off()) e.replace = Environment{};
    if (Given(s.intensity())) e.intensity = s.intensity();
    if (s.set_rotation()) e.rotation = s.rotation();
    if (const fb::Vec3* sun = s.sun()) {
        e.sun = glm::vec2(sun->x(), sun->y());
        if (Given(sun->z())) e.sunIlluminance = sun->z();
    }
    e.clearSky = ClearSkyAsked(s.sky(), "SetEnvironment");
    if (e.clearSky && (s.off() || !r.path.empty() || r.color))
        throw service::ServiceError(service::ErrorKind::kInvalidArgument,
                                    "SetEnvironment: a clear sky and another sky cannot both be "
                                    "given");
    if (Given(s.turbidity())) e.turbidity = s.turbidity();
    return r;
}

void BuildSceneInfo(flatbuffers::FlatBufferBuilder& b, const service::Session& session,
                    bool reused) {
    Scene scene = session.SceneSnapshot();
    SolverStats stats = session.SolverStatistics();
    std::vector<flatbuffers::Offset<fb::NodeInfo>> nodes;
    for (size_t ni = 0; ni < scene.nodes.size(); ++ni) {
        const SceneNode& n = scene.nodes[ni];
        bool placesLight = false;
        for (const auto& l : scene.lights) placesLight = placesLight || l.node == int(ni);
        if (n.primitives.empty() && n.children.empty() && !placesLight) continue;
        std::vector<flatbuffers::Offset<fb::PrimitiveInfo>> prims;
        bool emissive = false;
        for (uint32_t pi : n.primitives) {
            const Primitive& p = scene.primitives[pi];
            const Material& m = scene.materials[p.material];
            emissive = emissive || glm::any(glm::greaterThan(m.emission, glm::vec3(0.0f)));
            prims.push_back(fb::CreatePrimitiveInfoDirect(
                b, p.mesh, p.primitive, static_cast<uint32_t>(p.InputVertexCount()),
                m.name.c_str()));
        }
        std::vector<float> matrix(16);
        for (int i = 0; i < 16; ++i) matrix[i] = n.local[i / 4][i % 4];
        const fb::Vec3 lo(n.boundsMin.x, n.boundsMin.y, n.boundsMin.z),
            hi(n.boundsMax.x, n.boundsMax.y, n.boundsMax.z);
        const uint32_t targets = static_cast<uint32_t>(NodeMorphTargets(scene, int(ni)));
        nodes.push_back(fb::CreateNodeInfoDirect(b, n.name.c_str(), n.dynamic, &matrix, &prims,
                                                 emissive, n.hasMotionBounds ? &lo : nullptr,
                                                 n.hasMotionBounds ? &hi : nullptr, targets,
                                                 targets ? &n.morphWeights : nullptr));
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
    std::vector<flatbuffers::Offset<flatbuffers::String>> warnings;
    for (const std::string& w : SceneWarnings(scene)) warnings.push_back(b.CreateString(w));
    std::vector<flatbuffers::Offset<fb::RefinedPrimitive>> refined;
    for (const Primitive& p : scene.primitives) {
        if (!p.refined) continue;
        const float* positions = &p.objectPositions[0].x;
        const float* normals = &p.objectNormals[0].x;
        refined.push_back(fb::CreateRefinedPrimitive(
            b, b.CreateString(p.node), p.mesh, p.primitive,
            b.CreateVector(positions, 3 * p.objectPositions.size()),
            b.CreateVector(normals, 3 * p.objectNormals.size()), b.CreateVector(p.indices),
            b.CreateVector(p.parentTriangles)));
    }
    b.Finish(fb::CreateSceneInfoDirect(
        b, session.Name().c_str(), stats.solver.c_str(), stats.device.c_str(), &nodes, &materials,
        static_cast<uint32_t>(stats.elements), stats.links, session.BuildSeconds(), reused, &lights,
        scene.environment.Active() ? scene.environment.source.c_str() : nullptr,
        scene.environment.intensity, stats.divergence.empty() ? nullptr : stats.divergence.c_str(),
        &warnings, refined.empty() ? nullptr : &refined));
}

void BuildFramePayload(flatbuffers::FlatBufferBuilder& b, const service::FrameData& frame,
                       service::Channel channel, fb::Format format, const DeltaPayload* delta) {
    std::vector<flatbuffers::Offset<fb::PrimitiveIrradiance>> prims;
    prims.reserve(frame.irradiance.size());
    std::vector<glm::vec3> scratch;
    flatbuffers::Offset<fb::DeltaIrradiance> deltaTable = 0;
    if (delta) {
        std::vector<uint32_t> counts;
        if (delta->keyframe)
            for (size_t p = 0; p < frame.irradiance.size(); ++p) {
                const service::PrimitiveKey& key = (*frame.layout)[p];
                prims.push_back(fb::CreatePrimitiveIrradiance(b, b.CreateSharedString(key.node),
                                                              key.mesh, key.primitive));
                counts.push_back(static_cast<uint32_t>(frame.irradiance[p].size()));
            }
        deltaTable = fb::CreateDeltaIrradianceDirect(
            b, delta->keyframe, delta->baseFrame, delta->vertices,
            delta->keyframe ? &counts : nullptr, protocol::kDeltaZstd,
            static_cast<uint32_t>(delta->rawBytes), &delta->data, delta->tolerance);
    }
    for (size_t p = 0; !delta && p < frame.irradiance.size(); ++p) {
        const size_t n = frame.irradiance[p].size() * 3;
        // Null: all zero.
        const float* values = reinterpret_cast<const float*>(frame.Values(p, channel, scratch));
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
                                   frame.converged, ChannelOf(channel), &passes, &prims,
                                   frame.note.c_str(), deltaTable));
}

}  // namespace penumbra::net
