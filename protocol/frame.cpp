// Frame header codec, payload verification and the incremental decoder (SPEC.md, Framing).
#include "protocol/frame.h"

#include <cstring>
#include <glm/gtc/packing.hpp>

namespace penumbra::protocol {

namespace {

uint16_t Load16(const uint8_t* p) { return static_cast<uint16_t>(p[0] | p[1] << 8); }
uint32_t Load32(const uint8_t* p) {
    return uint32_t(p[0]) | uint32_t(p[1]) << 8 | uint32_t(p[2]) << 16 | uint32_t(p[3]) << 24;
}
void Store16(uint8_t* p, uint16_t v) {
    p[0] = uint8_t(v);
    p[1] = uint8_t(v >> 8);
}
void Store32(uint8_t* p, uint32_t v) {
    for (int i = 0; i < 4; ++i) p[i] = uint8_t(v >> (8 * i));
}

template <typename T>
bool Verify(const uint8_t* data, size_t size) {
    flatbuffers::Verifier verifier(data, size, kVerifierMaxDepth, kVerifierMaxTables);
    return verifier.VerifyBuffer<T>(nullptr);
}

}  // namespace

const char* MessageName(MessageType type) {
    switch (type) {
        case MessageType::kHello:
            return "Hello";
        case MessageType::kWelcome:
            return "Welcome";
        case MessageType::kError:
            return "Error";
        case MessageType::kBye:
            return "Bye";
        case MessageType::kOk:
            return "Ok";
        case MessageType::kLoadScene:
            return "LoadScene";
        case MessageType::kGetSceneInfo:
            return "GetSceneInfo";
        case MessageType::kSceneInfo:
            return "SceneInfo";
        case MessageType::kUnloadScene:
            return "UnloadScene";
        case MessageType::kSetTransform:
            return "SetTransform";
        case MessageType::kSetLight:
            return "SetLight";
        case MessageType::kSetMaterial:
            return "SetMaterial";
        case MessageType::kEditAck:
            return "EditAck";
        case MessageType::kSetEnvironment:
            return "SetEnvironment";
        case MessageType::kSetVertices:
            return "SetVertices";
        case MessageType::kSubscribe:
            return "Subscribe";
        case MessageType::kUnsubscribe:
            return "Unsubscribe";
        case MessageType::kGetIrradiance:
            return "GetIrradiance";
        case MessageType::kFrame:
            return "Frame";
        case MessageType::kStep:
            return "Step";
        case MessageType::kProgress:
            return "Progress";
        case MessageType::kGetStats:
            return "GetStats";
        case MessageType::kStats:
            return "Stats";
    }
    return "unknown";
}

bool IsKnownType(uint16_t type) {
    return std::strcmp(MessageName(static_cast<MessageType>(type)), "unknown") != 0;
}

bool VerifyPayload(MessageType type, const uint8_t* data, size_t size) {
    // An empty payload is not a FlatBuffer (the smallest is a root offset + a vtable).
    if (size < sizeof(flatbuffers::uoffset_t)) return false;
    switch (type) {
        case MessageType::kHello:
            return Verify<fb::Hello>(data, size);
        case MessageType::kWelcome:
            return Verify<fb::Welcome>(data, size);
        case MessageType::kError:
            return Verify<fb::Error>(data, size);
        case MessageType::kBye:
            return Verify<fb::Bye>(data, size);
        case MessageType::kOk:
            return Verify<fb::Ok>(data, size);
        case MessageType::kLoadScene:
            return Verify<fb::LoadScene>(data, size);
        case MessageType::kGetSceneInfo:
            return Verify<fb::GetSceneInfo>(data, size);
        case MessageType::kSceneInfo:
            return Verify<fb::SceneInfo>(data, size);
        case MessageType::kUnloadScene:
            return Verify<fb::UnloadScene>(data, size);
        case MessageType::kSetTransform:
            return Verify<fb::SetTransform>(data, size);
        case MessageType::kSetLight:
            return Verify<fb::SetLight>(data, size);
        case MessageType::kSetMaterial:
            return Verify<fb::SetMaterial>(data, size);
        case MessageType::kEditAck:
            return Verify<fb::EditAck>(data, size);
        case MessageType::kSetEnvironment:
            return Verify<fb::SetEnvironment>(data, size);
        case MessageType::kSetVertices:
            return Verify<fb::SetVertices>(data, size);
        case MessageType::kSubscribe:
            return Verify<fb::Subscribe>(data, size);
        case MessageType::kUnsubscribe:
            return Verify<fb::Unsubscribe>(data, size);
        case MessageType::kGetIrradiance:
            return Verify<fb::GetIrradiance>(data, size);
        case MessageType::kFrame:
            return Verify<fb::Frame>(data, size);
        case MessageType::kStep:
            return Verify<fb::Step>(data, size);
        case MessageType::kProgress:
            return Verify<fb::Progress>(data, size);
        case MessageType::kGetStats:
            return Verify<fb::GetStats>(data, size);
        case MessageType::kStats:
            return Verify<fb::Stats>(data, size);
    }
    return false;
}

void AppendFrame(std::vector<uint8_t>& out, MessageType type, uint32_t requestId,
                 std::span<const uint8_t> payload) {
    size_t at = out.size();
    out.resize(at + kHeaderBytes + payload.size());
    uint8_t* h = out.data() + at;
    std::memcpy(h, kMagic, 4);
    h[4] = kFramingVersion;
    h[5] = 0;
    Store16(h + 6, static_cast<uint16_t>(type));
    Store32(h + 8, static_cast<uint32_t>(payload.size()));
    Store32(h + 12, requestId);
    if (!payload.empty()) std::memcpy(h + kHeaderBytes, payload.data(), payload.size());
}

std::vector<uint8_t> EncodeFrame(MessageType type, uint32_t requestId,
                                 const flatbuffers::FlatBufferBuilder& builder) {
    std::vector<uint8_t> out;
    AppendFrame(out, type, requestId, {builder.GetBufferPointer(), builder.GetSize()});
    return out;
}

namespace {

// A FlatBuffer holding one table with no field set: what an empty payload decodes to.
const std::vector<uint8_t>& EmptyTable() {
    static const std::vector<uint8_t> bytes = [] {
        flatbuffers::FlatBufferBuilder b;
        b.Finish(flatbuffers::Offset<void>(b.EndTable(b.StartTable())));
        return std::vector<uint8_t>(b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize());
    }();
    return bytes;
}

}  // namespace

Decoder::Decoder(uint32_t maxPayloadBytes)
    : maxPayload_(maxPayloadBytes < kMaxPayloadCeiling ? maxPayloadBytes : kMaxPayloadCeiling) {}

void Decoder::Feed(const uint8_t* data, size_t size) {
    if (errorCode_ != fb::ErrorCode::None || size == 0) return;
    // Drop consumed bytes before growing, so the buffer holds at most one frame plus a read.
    if (start_ > 0 && start_ == buffer_.size()) {
        buffer_.clear();
        start_ = 0;
    } else if (start_ > (1u << 16) && start_ * 2 > buffer_.size()) {
        buffer_.erase(buffer_.begin(), buffer_.begin() + static_cast<std::ptrdiff_t>(start_));
        start_ = 0;
    }
    buffer_.insert(buffer_.end(), data, data + size);
}

Decoder::Result Decoder::Fail(fb::ErrorCode code, std::string reason) {
    errorCode_ = code;
    error_ = std::move(reason);
    return Result::kError;
}

Decoder::Result Decoder::Next(Message& out) {
    if (errorCode_ != fb::ErrorCode::None) return Result::kError;
    const size_t avail = buffer_.size() - start_;
    const uint8_t* h = buffer_.data() + start_;
    // Check what has arrived of the header byte by byte, so garbage fails at once
    // instead of waiting for 16 bytes.
    for (size_t i = 0; i < 4 && i < avail; ++i)
        if (h[i] != kMagic[i])
            return Fail(fb::ErrorCode::BadMagic, "frame does not start with the magic \"PNBR\"");
    if (avail >= 5 && h[4] != kFramingVersion)
        return Fail(fb::ErrorCode::BadVersion, "framing version " + std::to_string(h[4]) +
                                                   " is not supported (this server speaks " +
                                                   std::to_string(kFramingVersion) + ")");
    if (avail < kHeaderBytes) return Result::kNeedMore;

    Header header;
    header.version = h[4];
    header.flags = h[5];
    uint16_t type = Load16(h + 6);
    header.length = Load32(h + 8);
    header.requestId = Load32(h + 12);
    errorRequestId_ = header.requestId;
    if (header.flags != 0)
        return Fail(fb::ErrorCode::BadPayload,
                    "header flags must be 0, got " + std::to_string(header.flags));
    if (!IsKnownType(type))
        return Fail(fb::ErrorCode::UnknownType, "unknown message type " + std::to_string(type));
    header.type = static_cast<MessageType>(type);
    if (header.length > maxPayload_)
        return Fail(fb::ErrorCode::TooLarge, std::string(MessageName(header.type)) +
                                                 " payload of " + std::to_string(header.length) +
                                                 " bytes exceeds the limit of " +
                                                 std::to_string(maxPayload_));
    if (avail < kHeaderBytes + header.length) return Result::kNeedMore;

    // Verify the copy: a vector's storage is aligned as FlatBuffers expects, the stream
    // buffer at an arbitrary offset is not.
    const uint8_t* payload = h + kHeaderBytes;
    out.header = header;
    out.payload.assign(payload, payload + header.length);
    // An empty payload is the table with every field at its default (a client need not
    // build a FlatBuffer for Bye or GetStats).
    if (header.length == 0) out.payload = EmptyTable();
    start_ += kHeaderBytes + header.length;
    if (!VerifyPayload(header.type, out.payload.data(), out.payload.size()))
        return Fail(fb::ErrorCode::BadPayload, std::string(MessageName(header.type)) +
                                                   " payload failed FlatBuffers verification");
    errorRequestId_ = 0;
    return Result::kMessage;
}

uint16_t FloatToHalf(float value) {
    // IEEE round to nearest, ties to even, as numpy's float16 and JavaScript's Float16Array
    // convert (glm's packHalf1x16 rounds ties up): the half a delta stream's tolerance rule
    // compares is the one every client would compute.
    uint32_t bits;
    std::memcpy(&bits, &value, sizeof bits);
    const uint32_t sign = (bits >> 16) & 0x8000u;
    bits &= 0x7fffffffu;
    if (bits >= 0x47800000u)  // 2^16 and up, infinity, NaN
        return static_cast<uint16_t>(sign | (bits > 0x7f800000u ? 0x7e00u : 0x7c00u));
    if (bits < 0x38800000u) {
        // Below 2^-14, half's subnormals: adding 0.5 puts the value's bits where a half's
        // subnormal mantissa goes, rounded by the FPU (to nearest, ties to even).
        constexpr uint32_t kHalfBits = 126u << 23;  // 0.5f
        float f, half;
        std::memcpy(&f, &bits, sizeof f);
        std::memcpy(&half, &kHalfBits, sizeof half);
        f += half;
        uint32_t out;
        std::memcpy(&out, &f, sizeof out);
        return static_cast<uint16_t>(sign | (out - kHalfBits));
    }
    // Normal: rebias the exponent (127 → 15) and round the 13 bits that go, ties to even
    // (0xfff plus the lowest kept bit); a carry into the exponent is the right result.
    const uint32_t odd = (bits >> 13) & 1u;
    bits += (uint32_t(15 - 127) << 23) + 0xfffu + odd;
    return static_cast<uint16_t>(sign | (bits >> 13));
}
float HalfToFloat(uint16_t value) { return glm::unpackHalf1x16(value); }

}  // namespace penumbra::protocol
