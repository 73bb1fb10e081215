// Between the protocol's tables (protocol/penumbra.fbs) and the service's types: error
// codes and channels, requests read into loads and edits (their fields checked here, so a
// bad request is refused before anything runs), and the SceneInfo and Frame payloads.
#pragma once

#include <optional>
#include <string>
#include <vector>

#include "protocol/frame.h"
#include "service/service.h"

namespace penumbra::net {

protocol::fb::ErrorCode CodeOf(service::ErrorKind kind);
service::Channel ChannelOf(protocol::fb::Channel channel);
protocol::fb::Channel ChannelOf(service::Channel channel);
std::string Str(const flatbuffers::String* s);  // "" for an absent string

// Requests read into the service's types; service::ServiceError (InvalidArgument, or
// Unsupported for an unknown solver) names a bad field. A load is checked whole: the session
// settings (CheckSessionSettings) and the solver's options (CheckSolverSettings).
service::LoadRequest ReadLoadScene(const protocol::fb::LoadScene& l,
                                   const service::Service& service);
service::TransformEdit ReadSetTransform(const protocol::fb::SetTransform& t);
service::DeformEdit ReadSetVertices(const protocol::fb::SetVertices& v);
service::LightEdit ReadSetLight(const protocol::fb::SetLight& l);
service::MaterialEdit ReadSetMaterial(const protocol::fb::SetMaterial& s);
// A sky edit; a new sky (`path` or `color`) is made later, on the blocking pool
// (Service::MakeEnvironment reads a map).
struct EnvironmentRequest {
    service::EnvironmentEdit edit;
    std::string path;
    std::optional<glm::vec3> color;
};
EnvironmentRequest ReadSetEnvironment(const protocol::fb::SetEnvironment& s);

// The SceneInfo reply for `session` (`reused`: an already loaded scene was answered).
void BuildSceneInfo(flatbuffers::FlatBufferBuilder& b, const service::Session& session,
                    bool reused);
// A delta stream's values for one frame (net/delta_stream.h; SPEC.md "Delta frames").
struct DeltaPayload {
    bool keyframe = false;
    uint64_t baseFrame = 0;
    uint32_t vertices = 0;
    size_t rawBytes = 0;
    std::vector<uint8_t> data;  // zstd
    float tolerance = 0.0f;
};
// The Frame payload of `frame` in `channel` and `format`; with `delta`, its values instead
// (a keyframe names the primitives and their vertex counts, a delta neither).
void BuildFramePayload(flatbuffers::FlatBufferBuilder& b, const service::FrameData& frame,
                       service::Channel channel, protocol::fb::Format format,
                       const DeltaPayload* delta = nullptr);

}  // namespace penumbra::net
