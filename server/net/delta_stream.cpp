// A delta stream's baseline and encodings (delta_stream.h; protocol/SPEC.md "Delta frames").
#include "net/delta_stream.h"

#include <algorithm>
#include <cmath>

#include "net/messages.h"
#include "protocol/delta.h"

namespace penumbra::net {
namespace {

namespace fb = protocol::fb;

// The frame's values in `channel`, every primitive's one after another (zeros where a
// channel has none).
std::vector<float> Flatten(const service::FrameData& frame, service::Channel channel) {
    std::vector<float> out;
    std::vector<glm::vec3> scratch;
    for (size_t p = 0; p < frame.irradiance.size(); ++p) {
        const size_t n = frame.irradiance[p].size();
        const glm::vec3* v = frame.Values(p, channel, scratch);
        for (size_t i = 0; i < n; ++i) {
            const glm::vec3 e = v ? v[i] : glm::vec3(0.0f);
            out.insert(out.end(), {e.x, e.y, e.z});
        }
    }
    return out;
}

std::shared_ptr<const std::vector<uint8_t>> Message(const service::FrameData& frame,
                                                    service::Channel channel,
                                                    const DeltaPayload& payload) {
    flatbuffers::FlatBufferBuilder b(1024 + payload.data.size());
    BuildFramePayload(b, frame, channel, fb::Format::Float16, &payload);
    return std::make_shared<const std::vector<uint8_t>>(
        protocol::EncodeFrame(protocol::MessageType::kFrame, 0, b));
}

// A keyframe of `values` (fp16, 3 a vertex).
DeltaPayload KeyframePayload(const std::vector<uint16_t>& values, float tolerance) {
    DeltaPayload d;
    d.keyframe = true;
    d.vertices = static_cast<uint32_t>(values.size() / 3);
    d.tolerance = tolerance;
    const protocol::DeltaRun all{0, d.vertices};
    d.data = protocol::EncodeDelta({&all, 1}, values, {}, d.rawBytes);
    return d;
}

}  // namespace

std::shared_ptr<const std::vector<uint8_t>> DeltaStream::For(const service::FramePtr& frame,
                                                             uint64_t base) {
    if (frame->frame > frame_) Advance(frame);
    if (frame->frame == frame_ && base != 0 && base == from_ && delta_) return delta_;
    return Keyframe(frame);
}

void DeltaStream::Advance(const service::FramePtr& frame) {
    const std::vector<float> values = Flatten(*frame, channel_);
    const size_t n = values.size();
    const bool fresh = baseline_.size() != n;  // the first frame (or a layout that changed)
    if (fresh) baseline_.assign(n, 0);
    // The rule (SPEC.md): a vertex is sent again when a channel differs from the baseline by
    // more than the tolerance times its value, or times a twentieth of the frame's mean for
    // values darker than that; at tolerance 0, when its fp16 value differs.
    double sum = 0.0;
    for (float v : values) sum += std::abs(v);
    const float floor = n ? static_cast<float>(0.05 * sum / double(n)) : 0.0f;
    std::vector<protocol::DeltaRun> runs;
    const std::vector<uint16_t> before = baseline_;
    for (size_t v = 0; v < n / 3; ++v) {
        bool send = fresh;
        for (int c = 0; c < 3 && !send; ++c) {
            const float e = values[3 * v + c];
            const uint16_t held = baseline_[3 * v + c];
            send = tolerance_ <= 0.0f ? protocol::FloatToHalf(e) != held
                                      : std::abs(e - protocol::HalfToFloat(held)) >
                                            tolerance_ * std::max(std::abs(e), floor);
        }
        if (!send) continue;
        for (int c = 0; c < 3; ++c) baseline_[3 * v + c] = protocol::FloatToHalf(values[3 * v + c]);
        if (!runs.empty() && runs.back().start + runs.back().count == v)
            ++runs.back().count;
        else
            runs.push_back({static_cast<uint32_t>(v), 1});
    }
    from_ = fresh ? 0 : frame_;
    frame_ = frame->frame;
    keyframes_[0] = keyframes_[1] = nullptr;
    delta_ = nullptr;
    if (from_ != 0) {
        DeltaPayload d;
        d.baseFrame = from_;
        d.vertices = static_cast<uint32_t>(n / 3);
        d.tolerance = tolerance_;
        d.data = protocol::EncodeDelta(runs, baseline_, before, d.rawBytes);
        delta_ = Message(*frame, channel_, d);
    }
}

std::shared_ptr<const std::vector<uint8_t>> DeltaStream::Keyframe(const service::FramePtr& frame) {
    if (frame->frame != frame_) {
        // Not the stream's newest (an older frame replayed): a keyframe of its own values.
        std::vector<uint16_t> own;
        for (float v : Flatten(*frame, channel_)) own.push_back(protocol::FloatToHalf(v));
        return Message(*frame, channel_, KeyframePayload(own, tolerance_));
    }
    auto& cached = keyframes_[frame->converged ? 1 : 0];
    if (!cached) cached = Message(*frame, channel_, KeyframePayload(baseline_, tolerance_));
    return cached;
}

}  // namespace penumbra::net
