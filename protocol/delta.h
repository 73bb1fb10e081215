// Delta frames (SPEC.md, "Delta frames"): a subscriber's irradiance as fp16 values, sent whole
// (a keyframe) or only for the vertices that drifted past its tolerance since what it last
// received, the runs and values packed and zstd-compressed. Shared by the server (encoding,
// once per frame and tolerance) and the client library (decoding into its own copy).
#pragma once

#include <cstddef>
#include <cstdint>
#include <span>
#include <stdexcept>
#include <vector>

namespace penumbra::protocol {

// DeltaIrradiance.encoding: the only one so far.
inline constexpr uint8_t kDeltaZstd = 1;

// Vertices [start, start + count) of the scene's vertices in layout order.
struct DeltaRun {
    uint32_t start = 0, count = 0;
};

// The vertices of `values` (fp16 bit patterns, 3 a vertex) that `runs` names, packed as the
// payload's raw bytes (SPEC.md): for a keyframe (`base` empty, one run over every vertex) each
// value is predicted from the vertex before it, for a delta from `base`, the baseline the
// subscriber holds.
std::vector<uint8_t> PackDelta(std::span<const DeltaRun> runs, std::span<const uint16_t> values,
                               std::span<const uint16_t> base);
// PackDelta's bytes compressed with zstd, as DeltaIrradiance.data; `raw` gets their size
// before compression (DeltaIrradiance.raw_bytes).
std::vector<uint8_t> EncodeDelta(std::span<const DeltaRun> runs, std::span<const uint16_t> values,
                                 std::span<const uint16_t> base, size_t& raw);

class DeltaError : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

// Applies one payload (`rawBytes` once decompressed) to `values` (3 a vertex, the scene's
// vertex count): a keyframe writes every value, a delta the vertices of its runs. Throws
// DeltaError for anything malformed (sizes, runs past the end, bad compression), leaving
// `values` as it was.
void ApplyDelta(std::span<const uint8_t> data, size_t rawBytes, bool keyframe,
                std::vector<uint16_t>& values);

}  // namespace penumbra::protocol
