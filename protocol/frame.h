// The Penumbra wire format (protocol/SPEC.md): a 16-byte header in front of every
// FlatBuffers payload, an incremental decoder and an encoder. Depends on nothing of the server.
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "penumbra_generated.h"

namespace penumbra::protocol {

// Header layout, all little-endian: magic "PNBR", framing version, flags (0), message
// type, payload length, request id.
inline constexpr uint8_t kMagic[4] = {'P', 'N', 'B', 'R'};
inline constexpr uint8_t kFramingVersion = 1;
inline constexpr size_t kHeaderBytes = 16;
// Message-set versions this build speaks (negotiated by Hello/Welcome).
inline constexpr uint16_t kMinProtocolVersion = 1;
inline constexpr uint16_t kMaxProtocolVersion = 1;
// Default limit on a payload's length; the server's --max-frame-bytes overrides it.
inline constexpr uint32_t kDefaultMaxPayloadBytes = 64u << 20;
// Hard ceiling on any limit (FlatBuffers addresses 2 GiB; the header's length is 32 bits).
inline constexpr uint32_t kMaxPayloadCeiling = 1u << 30;
// FlatBuffers verifier limits on nesting depth and table count per payload.
inline constexpr uint32_t kVerifierMaxDepth = 16;
inline constexpr uint32_t kVerifierMaxTables = 1u << 20;

enum class MessageType : uint16_t {
    kHello = 1,
    kWelcome = 2,
    kError = 3,
    kBye = 4,
    kOk = 5,
    kLoadScene = 10,
    kGetSceneInfo = 11,
    kSceneInfo = 12,
    kUnloadScene = 13,
    kSetTransform = 20,
    kSetLight = 21,
    kSetMaterial = 22,
    kEditAck = 23,
    kSetEnvironment = 24,
    kSetVertices = 25,
    kSubscribe = 30,
    kUnsubscribe = 31,
    kGetIrradiance = 32,
    kFrame = 33,
    kStep = 34,
    kProgress = 35,
    kGetStats = 40,
    kStats = 41,
};

// "Hello", "Frame", ...; "unknown" for a value outside the table.
const char* MessageName(MessageType type);
bool IsKnownType(uint16_t type);

struct Header {
    uint8_t version = kFramingVersion;
    uint8_t flags = 0;
    MessageType type = MessageType::kHello;
    uint32_t length = 0;
    uint32_t requestId = 0;
};

// One decoded message: its header and its verified payload bytes.
struct Message {
    Header header;
    std::vector<uint8_t> payload;

    template <typename T>
    const T* As() const {
        return flatbuffers::GetRoot<T>(payload.data());
    }
};

// Runs the FlatBuffers verifier for the table that `type` names.
bool VerifyPayload(MessageType type, const uint8_t* data, size_t size);

// Appends one frame (header + payload) to `out`.
void AppendFrame(std::vector<uint8_t>& out, MessageType type, uint32_t requestId,
                 std::span<const uint8_t> payload);
std::vector<uint8_t> EncodeFrame(MessageType type, uint32_t requestId,
                                 const flatbuffers::FlatBufferBuilder& builder);

// Incremental decoder: feed bytes as they arrive, then call Next() until it answers
// kNeedMore. After kError the stream is unusable (the peer gets the error, then the
// connection closes); error() names the code and the reason.
class Decoder {
  public:
    enum class Result { kNeedMore, kMessage, kError };

    explicit Decoder(uint32_t maxPayloadBytes = kDefaultMaxPayloadBytes);

    void Feed(const uint8_t* data, size_t size);
    Result Next(Message& out);

    fb::ErrorCode errorCode() const { return errorCode_; }
    const std::string& error() const { return error_; }
    // Request id of the frame that failed, when its header was readable (else 0).
    uint32_t errorRequestId() const { return errorRequestId_; }
    size_t buffered() const { return buffer_.size() - start_; }

  private:
    Result Fail(fb::ErrorCode code, std::string reason);

    uint32_t maxPayload_;
    std::vector<uint8_t> buffer_;
    size_t start_ = 0;  // first unconsumed byte
    fb::ErrorCode errorCode_ = fb::ErrorCode::None;
    std::string error_;
    uint32_t errorRequestId_ = 0;
};

// IEEE 754 half floats, for Format::Float16 irradiance.
uint16_t FloatToHalf(float value);
float HalfToFloat(uint16_t value);

}  // namespace penumbra::protocol
