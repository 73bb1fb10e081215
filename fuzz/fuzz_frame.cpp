// Fuzz target: the server's frame reader and request decoding. The input is a byte stream as
// a client would send it, fed to the incremental decoder in pieces (the first byte sets
// their size); each message that decodes is verified against its table and, for the
// requests the server reads into its own types, read as the server reads it (and a delta
// frame applied as a client applies it). Anything may be
// refused; nothing may crash, leak or hang.
#include <cstdint>
#include <filesystem>
#include <memory>

#include "net/messages.h"
#include "protocol/delta.h"
#include "protocol/frame.h"
#include "service/service.h"

using namespace penumbra;
namespace fb = protocol::fb;

namespace {

const service::Service& TheService() {
    static const auto service = std::make_unique<service::Service>(
        std::filesystem::temp_directory_path(), service::ServiceLimits{});
    return *service;
}

// What the server's request handlers read from a verified payload (net/requests.cpp).
void Read(const protocol::Message& m) {
    try {
        switch (m.header.type) {
            case protocol::MessageType::kLoadScene:
                net::ReadLoadScene(*m.As<fb::LoadScene>(), TheService());
                break;
            case protocol::MessageType::kSetTransform:
                net::ReadSetTransform(*m.As<fb::SetTransform>());
                break;
            case protocol::MessageType::kSetLight:
                net::ReadSetLight(*m.As<fb::SetLight>());
                break;
            case protocol::MessageType::kSetMaterial:
                net::ReadSetMaterial(*m.As<fb::SetMaterial>());
                break;
            case protocol::MessageType::kSetEnvironment:
                net::ReadSetEnvironment(*m.As<fb::SetEnvironment>());
                break;
            case protocol::MessageType::kSetVertices:
                net::ReadSetVertices(*m.As<fb::SetVertices>());
                break;
            case protocol::MessageType::kFrame: {
                // A delta stream's frame as a client applies it (client/client.cpp): what a
                // server sends is input too.
                const fb::DeltaIrradiance* d = m.As<fb::Frame>()->delta();
                if (d && d->data() && d->vertices() <= (1u << 16)) {
                    std::vector<uint16_t> held(size_t(d->vertices()) * 3, 0);
                    protocol::ApplyDelta({d->data()->data(), d->data()->size()}, d->raw_bytes(),
                                         d->keyframe(), held);
                }
                break;
            }
            default:
                break;
        }
    } catch (const protocol::DeltaError&) {
    } catch (const service::ServiceError&) {
        // A bad field, refused with its name: what the server answers.
    }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
    if (size == 0) return 0;
    const size_t piece = 1 + data[0] % 64;
    protocol::Decoder decoder(1u << 20);
    protocol::Message message;
    for (size_t at = 1; at < size; at += piece) {
        decoder.Feed(data + at, std::min(piece, size - at));
        for (;;) {
            const auto r = decoder.Next(message);
            if (r == protocol::Decoder::Result::kNeedMore) break;
            if (r == protocol::Decoder::Result::kError) return 0;  // the stream is closed
            if (protocol::VerifyPayload(message.header.type, message.payload.data(),
                                        message.payload.size()))
                Read(message);
        }
    }
    return 0;
}
