// A delta stream (protocol/SPEC.md, "Delta frames"): one session's channel at one tolerance.
// It keeps the baseline, the fp16 values that every subscriber holds which took each of its
// frames, and encodes each frame once for all of them: a delta from the frame before, and on
// demand a keyframe of the whole baseline for subscribers that are new or fell behind.
#pragma once

#include <cstdint>
#include <memory>
#include <vector>

#include "service/session.h"

namespace penumbra::net {

class DeltaStream {
  public:
    DeltaStream(service::Channel channel, float tolerance)
        : channel_(channel), tolerance_(tolerance) {}

    // The Frame message for a subscriber that holds frame `base` of this stream (0: none) and
    // is to get `frame`: its delta when it holds the frame the delta changes, else a keyframe.
    // A frame newer than the stream's newest advances it first (Advance).
    std::shared_ptr<const std::vector<uint8_t>> For(const service::FramePtr& frame, uint64_t base);

  private:
    // Takes `frame` into the baseline (a vertex whose value drifted past the tolerance gets
    // the frame's) and encodes its delta from the frame before.
    void Advance(const service::FramePtr& frame);
    // The whole baseline as of the newest frame, as a keyframe Frame message for `frame` (that
    // frame, or a replay of it), encoded once for each converged flag; for an older frame, a
    // keyframe of its own values.
    std::shared_ptr<const std::vector<uint8_t>> Keyframe(const service::FramePtr& frame);

    const service::Channel channel_;
    const float tolerance_;
    uint64_t frame_ = 0;
    std::vector<uint16_t> baseline_;  // fp16, 3 a vertex
    uint64_t from_ = 0;               // the frame delta_ changes (0: none)
    std::shared_ptr<const std::vector<uint8_t>> delta_;
    std::shared_ptr<const std::vector<uint8_t>> keyframes_[2];  // by converged flag
};

}  // namespace penumbra::net
