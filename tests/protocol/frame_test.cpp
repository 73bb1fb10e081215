// Protocol framing: round trips of every message type through the incremental decoder, and
// raw-bytes tests for every decoder error path (SPEC.md, Errors).
#include "protocol/frame.h"

#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "protocol/delta.h"

namespace penumbra::protocol {
namespace {

using Result = Decoder::Result;

// Builds a minimal valid payload of `type` (every table accepts its defaults).
std::vector<uint8_t> Payload(MessageType type) {
    flatbuffers::FlatBufferBuilder b;
    switch (type) {
        case MessageType::kHello:
            b.Finish(fb::CreateHelloDirect(b, "test", 1, 1));
            break;
        case MessageType::kWelcome:
            b.Finish(fb::CreateWelcomeDirect(b, "srv", 1, 1024));
            break;
        case MessageType::kError:
            b.Finish(fb::CreateErrorDirect(b, fb::ErrorCode::NotFound, "no such node"));
            break;
        case MessageType::kBye:
            b.Finish(fb::CreateBye(b));
            break;
        case MessageType::kOk:
            b.Finish(fb::CreateOk(b, 7));
            break;
        case MessageType::kLoadScene:
            b.Finish(fb::CreateLoadSceneDirect(b, "cornell-box.gltf"));
            break;
        case MessageType::kGetSceneInfo:
            b.Finish(fb::CreateGetSceneInfoDirect(b, "s"));
            break;
        case MessageType::kSceneInfo:
            b.Finish(fb::CreateSceneInfoDirect(b, "s"));
            break;
        case MessageType::kUnloadScene:
            b.Finish(fb::CreateUnloadSceneDirect(b, "s"));
            break;
        case MessageType::kSetTransform: {
            std::vector<float> m(16, 0.0f);
            b.Finish(fb::CreateSetTransformDirect(b, "s", "block", &m));
            break;
        }
        case MessageType::kSetLight: {
            fb::Vec3 c(1, 0.5f, 0.25f);
            b.Finish(fb::CreateSetLightDirect(b, "s", "lamp", &c, 3.0f));
            break;
        }
        case MessageType::kSetMaterial: {
            fb::Vec3 a(0.5f, 0.5f, 0.5f);
            b.Finish(fb::CreateSetMaterialDirect(b, "s", "grey", &a));
            break;
        }
        case MessageType::kEditAck:
            b.Finish(fb::CreateEditAck(b, 42));
            break;
        case MessageType::kSetEnvironment: {
            fb::Vec3 c(0.5f, 0.6f, 1.0f);
            b.Finish(fb::CreateSetEnvironmentDirect(b, "s", nullptr, &c, false, 2.0f, 0.5f, true));
            break;
        }
        case MessageType::kSetVertices: {
            std::vector<float> p = {0, 0, 0, 1, 0, 0, 0, 1, 0};
            b.Finish(fb::CreateSetVerticesDirect(b, "s", "blob", &p));
            break;
        }
        case MessageType::kSubscribe:
            b.Finish(fb::CreateSubscribeDirect(b, "s", fb::Channel::Total, fb::Format::Float16));
            break;
        case MessageType::kUnsubscribe:
            b.Finish(fb::CreateUnsubscribeDirect(b, "s"));
            break;
        case MessageType::kGetIrradiance:
            b.Finish(fb::CreateGetIrradianceDirect(b, "s"));
            break;
        case MessageType::kFrame: {
            std::vector<float> rgb = {1, 2, 3};
            std::vector<flatbuffers::Offset<fb::PrimitiveIrradiance>> prims = {
                fb::CreatePrimitiveIrradianceDirect(b, "floor", 0, 0, &rgb)};
            b.Finish(fb::CreateFrameDirect(b, "s", 3, 2, 12, 4.5, 1.0, false, fb::Channel::Indirect,
                                           nullptr, &prims));
            break;
        }
        case MessageType::kStep:
            b.Finish(fb::CreateStepDirect(b, "s", 4));
            break;
        case MessageType::kProgress:
            b.Finish(fb::CreateProgressDirect(b, "links", 0.5, 2.0));
            break;
        case MessageType::kGetStats:
            b.Finish(fb::CreateGetStatsDirect(b, "s"));
            break;
        case MessageType::kStats:
            b.Finish(fb::CreateStatsDirect(b, "{}"));
            break;
    }
    return {b.GetBufferPointer(), b.GetBufferPointer() + b.GetSize()};
}

const MessageType kAllTypes[] = {
    MessageType::kHello,        MessageType::kWelcome,     MessageType::kError,
    MessageType::kBye,          MessageType::kOk,          MessageType::kLoadScene,
    MessageType::kGetSceneInfo, MessageType::kSceneInfo,   MessageType::kSetTransform,
    MessageType::kSetLight,     MessageType::kSetMaterial, MessageType::kEditAck,
    MessageType::kSubscribe,    MessageType::kUnsubscribe, MessageType::kGetIrradiance,
    MessageType::kFrame,        MessageType::kStep,        MessageType::kProgress,
    MessageType::kGetStats,     MessageType::kStats,       MessageType::kSetEnvironment,
    MessageType::kUnloadScene,  MessageType::kSetVertices,
};

TEST(Frame, EveryMessageRoundTripsByteByByte) {
    std::vector<uint8_t> stream;
    uint32_t id = 100;
    for (MessageType t : kAllTypes) AppendFrame(stream, t, id++, Payload(t));
    // Feed one byte at a time: the decoder must answer NeedMore until a frame is whole.
    Decoder d;
    std::vector<Message> got;
    for (uint8_t byte : stream) {
        d.Feed(&byte, 1);
        Message m;
        Result r;
        while ((r = d.Next(m)) == Result::kMessage) got.push_back(m);
        ASSERT_EQ(r, Result::kNeedMore) << d.error();
    }
    ASSERT_EQ(got.size(), std::size(kAllTypes));
    for (size_t i = 0; i < got.size(); ++i) {
        EXPECT_EQ(got[i].header.type, kAllTypes[i]) << MessageName(kAllTypes[i]);
        EXPECT_EQ(got[i].header.requestId, 100u + i);
        EXPECT_EQ(got[i].payload, Payload(kAllTypes[i]));
    }
    // Field values survive: spot-check the ones with content.
    EXPECT_EQ(got[2].As<fb::Error>()->code(), fb::ErrorCode::NotFound);
    EXPECT_STREQ(got[2].As<fb::Error>()->message()->c_str(), "no such node");
    EXPECT_EQ(got[9].As<fb::SetLight>()->intensity(), 3.0f);
    EXPECT_EQ(got[9].As<fb::SetLight>()->color()->y(), 0.5f);
    EXPECT_EQ(got[12].As<fb::Subscribe>()->format(), fb::Format::Float16);
    const fb::Frame* f = got[15].As<fb::Frame>();
    EXPECT_EQ(f->frame(), 3u);
    EXPECT_EQ(f->last_edit(), 2u);
    EXPECT_EQ(f->primitives()->Get(0)->f32()->Get(2), 3.0f);
}

TEST(Frame, ManyFramesInOneRead) {
    std::vector<uint8_t> stream;
    for (int i = 0; i < 50; ++i)
        AppendFrame(stream, MessageType::kOk, i, Payload(MessageType::kOk));
    Decoder d;
    d.Feed(stream.data(), stream.size());
    Message m;
    int n = 0;
    while (d.Next(m) == Result::kMessage) EXPECT_EQ(m.header.requestId, uint32_t(n++));
    EXPECT_EQ(n, 50);
    EXPECT_EQ(d.buffered(), 0u);
}

TEST(Frame, HeaderIsByteExact) {
    // SPEC.md's example: an Ok with frame = 7, request id 5.
    std::vector<uint8_t> f;
    AppendFrame(f, MessageType::kOk, 5, Payload(MessageType::kOk));
    ASSERT_GE(f.size(), kHeaderBytes);
    const uint8_t expect[12] = {'P', 'N', 'B', 'R', 1, 0, 5, 0, 0, 0, 0, 0};
    EXPECT_EQ(std::memcmp(f.data(), expect, 8), 0);
    EXPECT_EQ(f[8] | f[9] << 8 | f[10] << 16 | f[11] << 24, int(f.size() - kHeaderBytes));
    EXPECT_EQ(f[12], 5);
}

// --- Error paths, from raw bytes ----------------------------------------------------------

Result DecodeRaw(const std::vector<uint8_t>& bytes, Decoder& d) {
    d.Feed(bytes.data(), bytes.size());
    Message m;
    return d.Next(m);
}

std::vector<uint8_t> RawHeader(uint16_t type, uint32_t length, uint8_t version = 1,
                               uint8_t flags = 0, uint32_t id = 9) {
    return {'P',
            'N',
            'B',
            'R',
            version,
            flags,
            uint8_t(type),
            uint8_t(type >> 8),
            uint8_t(length),
            uint8_t(length >> 8),
            uint8_t(length >> 16),
            uint8_t(length >> 24),
            uint8_t(id),
            uint8_t(id >> 8),
            uint8_t(id >> 16),
            uint8_t(id >> 24)};
}

TEST(Decoder, WrongMagicFailsOnTheFirstByte) {
    Decoder d;
    EXPECT_EQ(DecodeRaw({'G'}, d), Result::kError);
    EXPECT_EQ(d.errorCode(), fb::ErrorCode::BadMagic);
    EXPECT_NE(d.error().find("PNBR"), std::string::npos) << d.error();
}

TEST(Decoder, HttpGarbageIsBadMagic) {
    Decoder d;
    std::string get = "GET / HTTP/1.1\r\n\r\n";
    EXPECT_EQ(DecodeRaw({get.begin(), get.end()}, d), Result::kError);
    EXPECT_EQ(d.errorCode(), fb::ErrorCode::BadMagic);
}

TEST(Decoder, WrongVersion) {
    Decoder d;
    EXPECT_EQ(DecodeRaw(RawHeader(5, 0, /*version=*/2), d), Result::kError);
    EXPECT_EQ(d.errorCode(), fb::ErrorCode::BadVersion);
    EXPECT_NE(d.error().find("version 2"), std::string::npos) << d.error();
}

TEST(Decoder, NonZeroFlags) {
    Decoder d;
    EXPECT_EQ(DecodeRaw(RawHeader(5, 0, 1, /*flags=*/1), d), Result::kError);
    EXPECT_EQ(d.errorCode(), fb::ErrorCode::BadPayload);
}

TEST(Decoder, UnknownType) {
    Decoder d;
    EXPECT_EQ(DecodeRaw(RawHeader(999, 0), d), Result::kError);
    EXPECT_EQ(d.errorCode(), fb::ErrorCode::UnknownType);
    EXPECT_EQ(d.errorRequestId(), 9u);
}

TEST(Decoder, OversizedIsRejectedFromTheHeaderAlone) {
    // The limit is checked before any payload byte arrives or is allocated.
    Decoder d(1024);
    EXPECT_EQ(DecodeRaw(RawHeader(10, 1025), d), Result::kError);
    EXPECT_EQ(d.errorCode(), fb::ErrorCode::TooLarge);
    EXPECT_NE(d.error().find("1025"), std::string::npos) << d.error();
    Decoder huge;
    EXPECT_EQ(DecodeRaw(RawHeader(10, 0xFFFFFFFFu), huge), Result::kError);
    EXPECT_EQ(huge.errorCode(), fb::ErrorCode::TooLarge);
}

TEST(Decoder, TruncatedFrameWaits) {
    std::vector<uint8_t> f;
    AppendFrame(f, MessageType::kHello, 1, Payload(MessageType::kHello));
    for (size_t cut : {size_t(3), size_t(15), f.size() - 1}) {
        Decoder d;
        std::vector<uint8_t> part(f.begin(), f.begin() + cut);
        EXPECT_EQ(DecodeRaw(part, d), Result::kNeedMore) << "cut at " << cut;
    }
}

TEST(Decoder, GarbagePayloadFailsVerification) {
    std::vector<uint8_t> f = RawHeader(1, 8);
    for (uint8_t b : {0xFF, 0xFF, 0xFF, 0x7F, 1, 2, 3, 4}) f.push_back(b);
    Decoder d;
    EXPECT_EQ(DecodeRaw(f, d), Result::kError);
    EXPECT_EQ(d.errorCode(), fb::ErrorCode::BadPayload);
    EXPECT_NE(d.error().find("Hello"), std::string::npos) << d.error();
}

// An empty payload is the table with every field at its default (SPEC.md, Framing): Bye,
// GetStats of every scene, a Step of 1 on the default scene.
TEST(Decoder, EmptyPayloadIsTheTableWithItsDefaults) {
    for (MessageType t : {MessageType::kBye, MessageType::kGetStats, MessageType::kStep}) {
        std::vector<uint8_t> f;
        AppendFrame(f, t, 7, {});
        Decoder d;
        Message m;
        d.Feed(f.data(), f.size());
        ASSERT_EQ(d.Next(m), Result::kMessage) << MessageName(t) << ": " << d.error();
        EXPECT_EQ(m.header.requestId, 7u);
        EXPECT_TRUE(VerifyPayload(t, m.payload.data(), m.payload.size()));
    }
    std::vector<uint8_t> f;
    AppendFrame(f, MessageType::kStep, 1, {});
    Decoder d;
    Message m;
    d.Feed(f.data(), f.size());
    ASSERT_EQ(d.Next(m), Result::kMessage);
    EXPECT_EQ(m.As<fb::Step>()->iterations(), 1);
    EXPECT_EQ(m.As<fb::Step>()->scene(), nullptr);
}

TEST(Decoder, PayloadOfAnotherTypeThatDoesNotVerify) {
    // A Frame's bytes labelled as Hello: the verifier of Hello reads field 1 (client) as a
    // string where Frame has a string too, so pick a mismatch: an EditAck (ulong at field 0)
    // read as Hello (string at field 0) points the string offset out of the buffer.
    flatbuffers::FlatBufferBuilder b;
    b.Finish(fb::CreateEditAck(b, 0xFFFFFFFFFFull));
    std::vector<uint8_t> f;
    AppendFrame(f, MessageType::kHello, 1, {b.GetBufferPointer(), b.GetSize()});
    Decoder d;
    EXPECT_EQ(DecodeRaw(f, d), Result::kError);
    EXPECT_EQ(d.errorCode(), fb::ErrorCode::BadPayload);
}

TEST(Decoder, StaysFailedAfterAnError) {
    Decoder d;
    EXPECT_EQ(DecodeRaw({'X'}, d), Result::kError);
    std::vector<uint8_t> ok;
    AppendFrame(ok, MessageType::kOk, 1, Payload(MessageType::kOk));
    EXPECT_EQ(DecodeRaw(ok, d), Result::kError);
}

// Every half value converts back to itself, and a float halfway between two halves goes to
// the even one (IEEE's rounding, as numpy's and JavaScript's).
TEST(Half, RoundsToNearestTiesToEven) {
    for (uint32_t h = 0; h < 0x10000; ++h) {
        if ((h & 0x7c00) == 0x7c00 && (h & 0x3ff)) continue;  // NaN
        const float f = HalfToFloat(uint16_t(h));
        ASSERT_EQ(FloatToHalf(f), h) << std::hex << h;
        if ((h & 0x7fff) >= 0x7bff) continue;  // the largest finite half and beyond
        const float next = HalfToFloat(uint16_t(h + 1));
        const float middle = (f + next) / 2;  // exact in float
        const uint32_t even = (h & 1) ? h + 1 : h;
        if ((h & 0x8000) == 0) {
            ASSERT_EQ(FloatToHalf(middle), even) << std::hex << h;
        }
    }
    EXPECT_EQ(FloatToHalf(65520.0f), 0x7c00);  // rounds to infinity
    EXPECT_EQ(FloatToHalf(65519.0f), 0x7bff);
}

TEST(Half, RoundTripsIrradianceValues) {
    for (float v : {0.0f, 1.0f, 0.3183f, 12.5f, 1000.0f}) {
        float back = HalfToFloat(FloatToHalf(v));
        EXPECT_NEAR(back, v, v * 1e-3f) << v;  // half has an 11-bit significand: 2^-11 ≈ 4.9e-4
    }
}

// SPEC.md "Delta frames", its example byte for byte: vertex 2 of 4 goes from (1, 0.5, 0.25)
// to (1, 0.5, 0.5).
TEST(Delta, PacksTheSpecExample) {
    std::vector<uint16_t> base(12, 0), next;
    for (int v = 0; v < 4; ++v) {
        base[3 * v] = 0x3c00;
        base[3 * v + 1] = 0x3800;
        base[3 * v + 2] = 0x3400;
    }
    next = base;
    next[3 * 2 + 2] = 0x3800;
    const DeltaRun run{2, 1};
    EXPECT_EQ(PackDelta({&run, 1}, next, base),
              (std::vector<uint8_t>{0x01, 0x02, 0x01, 0x00, 0x00, 0x00, 0x00, 0x00, 0x08}));
    size_t raw = 0;
    const std::vector<uint8_t> data = EncodeDelta({&run, 1}, next, base, raw);
    EXPECT_EQ(raw, 9u);
    std::vector<uint16_t> held = base;
    ApplyDelta(data, raw, false, held);
    EXPECT_EQ(held, next);
}

// Keyframes and deltas of random values (every bit pattern, wrapping residuals included)
// come back exactly; the runs pick scattered vertices.
TEST(Delta, KeyframesAndDeltasRoundTrip) {
    std::mt19937 rng(64);
    const size_t n = 1000;
    std::vector<uint16_t> values(3 * n);
    for (auto& v : values) v = static_cast<uint16_t>(rng());
    size_t raw = 0;
    const DeltaRun all{0, uint32_t(n)};
    std::vector<uint16_t> held(3 * n, 0);
    const std::vector<uint8_t> key = EncodeDelta({&all, 1}, values, {}, raw);
    ApplyDelta(key, raw, true, held);
    EXPECT_EQ(held, values);
    std::vector<DeltaRun> runs{{3, 5}, {10, 1}, {500, 100}, {999, 1}};
    std::vector<uint16_t> next = values;
    for (const auto& r : runs)
        for (size_t v = r.start; v < r.start + r.count; ++v)
            for (int c = 0; c < 3; ++c) next[3 * v + c] = static_cast<uint16_t>(rng());
    const std::vector<uint8_t> delta = EncodeDelta(runs, next, values, raw);
    ApplyDelta(delta, raw, false, held);
    EXPECT_EQ(held, next);
}

// A payload that does not fit what the client holds is refused and changes nothing.
TEST(Delta, MalformedPayloadsAreRefused) {
    std::vector<uint16_t> base(12, 0x3c00), held = base;
    const DeltaRun past{3, 2};  // vertices 3 and 4 of 4
    std::vector<uint16_t> bigger(15, 0x3800);
    size_t raw = 0;
    const auto data = EncodeDelta({&past, 1}, bigger, std::vector<uint16_t>(15, 0), raw);
    EXPECT_THROW(ApplyDelta(data, raw, false, held), DeltaError);
    EXPECT_EQ(held, base);
    const DeltaRun one{0, 1};
    const auto small = EncodeDelta({&one, 1}, base, base, raw);
    EXPECT_THROW(ApplyDelta(small, raw + 1, false, held), DeltaError);  // not its size
    EXPECT_THROW(ApplyDelta(small, raw, true, held), DeltaError);       // a keyframe of one vertex
    std::vector<uint8_t> noise(small.size(), 0x5a);
    EXPECT_THROW(ApplyDelta(noise, raw, false, held), DeltaError);
    EXPECT_EQ(held, base);
}

}  // namespace
}  // namespace penumbra::protocol
