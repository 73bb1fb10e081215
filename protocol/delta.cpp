// The delta payload's packing (SPEC.md, "Delta frames"): LEB128 runs, residuals zigzagged
// into two byte planes (low bytes, then high bytes: the high plane of small residuals is
// mostly zero, which zstd takes to almost nothing), the whole compressed with zstd.
#include "protocol/delta.h"

#include <zstd.h>

#include <string>

namespace penumbra::protocol {
namespace {

void PutVarint(std::vector<uint8_t>& out, uint64_t v) {
    while (v >= 0x80) {
        out.push_back(static_cast<uint8_t>(v | 0x80));
        v >>= 7;
    }
    out.push_back(static_cast<uint8_t>(v));
}

uint64_t GetVarint(const uint8_t*& p, const uint8_t* end) {
    uint64_t v = 0;
    for (int shift = 0; shift < 64; shift += 7) {
        if (p == end) throw DeltaError("delta payload: a run count ends early");
        const uint8_t byte = *p++;
        v |= uint64_t(byte & 0x7f) << shift;
        if (!(byte & 0x80)) return v;
    }
    throw DeltaError("delta payload: a run count is longer than 64 bits");
}

uint16_t ZigZag(uint16_t difference) {
    const int16_t d = static_cast<int16_t>(difference);
    return static_cast<uint16_t>((static_cast<uint16_t>(d) << 1) ^ static_cast<uint16_t>(d >> 15));
}

uint16_t UnZigZag(uint16_t z) { return static_cast<uint16_t>((z >> 1) ^ (0u - (z & 1u))); }

constexpr int kLevel = 3;  // zstd's default: a frame of the office in well under a millisecond

}  // namespace

std::vector<uint8_t> PackDelta(std::span<const DeltaRun> runs, std::span<const uint16_t> values,
                               std::span<const uint16_t> base) {
    std::vector<uint8_t> bytes;
    PutVarint(bytes, runs.size());
    size_t end = 0, n = 0;
    for (const DeltaRun& r : runs) {
        PutVarint(bytes, r.start - end);
        PutVarint(bytes, r.count);
        end = size_t(r.start) + r.count;
        n += r.count;
    }
    const size_t planes = bytes.size();
    bytes.resize(planes + 6 * n);
    uint8_t* low = bytes.data() + planes;
    uint8_t* high = low + 3 * n;
    uint16_t previous[3] = {0, 0, 0};
    size_t k = 0;
    for (const DeltaRun& r : runs)
        for (size_t v = r.start; v < size_t(r.start) + r.count; ++v)
            for (int c = 0; c < 3; ++c, ++k) {
                const uint16_t value = values[3 * v + c];
                const uint16_t predicted = base.empty() ? previous[c] : base[3 * v + c];
                previous[c] = value;
                const uint16_t z = ZigZag(static_cast<uint16_t>(value - predicted));
                low[k] = static_cast<uint8_t>(z);
                high[k] = static_cast<uint8_t>(z >> 8);
            }
    return bytes;
}

std::vector<uint8_t> EncodeDelta(std::span<const DeltaRun> runs, std::span<const uint16_t> values,
                                 std::span<const uint16_t> base, size_t& raw) {
    const std::vector<uint8_t> bytes = PackDelta(runs, values, base);
    raw = bytes.size();
    std::vector<uint8_t> packed(ZSTD_compressBound(bytes.size()));
    const size_t size =
        ZSTD_compress(packed.data(), packed.size(), bytes.data(), bytes.size(), kLevel);
    if (ZSTD_isError(size))
        throw DeltaError(std::string("zstd could not compress a frame: ") +
                         ZSTD_getErrorName(size));
    packed.resize(size);
    return packed;
}

void ApplyDelta(std::span<const uint8_t> data, size_t rawBytes, bool keyframe,
                std::vector<uint16_t>& values) {
    const size_t vertices = values.size() / 3;
    // The most a payload can hold: every vertex in a run of its own.
    if (rawBytes > 10 + 16 * vertices)
        throw DeltaError("delta payload: " + std::to_string(rawBytes) + " raw bytes for " +
                         std::to_string(vertices) + " vertices");
    if (ZSTD_getFrameContentSize(data.data(), data.size()) != rawBytes)
        throw DeltaError("delta payload: its zstd frame does not hold the raw size it names");
    std::vector<uint8_t> bytes(rawBytes);
    const size_t got = ZSTD_decompress(bytes.data(), bytes.size(), data.data(), data.size());
    if (ZSTD_isError(got) || got != rawBytes)
        throw DeltaError(std::string("delta payload: zstd: ") +
                         (ZSTD_isError(got) ? ZSTD_getErrorName(got) : "short"));
    const uint8_t* p = bytes.data();
    const uint8_t* end = p + bytes.size();
    const uint64_t count = GetVarint(p, end);
    if (count > vertices) throw DeltaError("delta payload: more runs than vertices");
    std::vector<DeltaRun> runs(count);
    uint64_t at = 0, n = 0;
    for (DeltaRun& r : runs) {
        at += GetVarint(p, end);
        const uint64_t length = GetVarint(p, end);
        if (at > vertices || length > vertices - at)
            throw DeltaError("delta payload: a run goes past the scene's " +
                             std::to_string(vertices) + " vertices");
        r = {static_cast<uint32_t>(at), static_cast<uint32_t>(length)};
        at += length;
        n += length;
    }
    if (keyframe && (count != 1 || runs[0].start != 0 || n != vertices))
        throw DeltaError("delta payload: a keyframe is one run over every vertex");
    if (size_t(end - p) != 6 * n)
        throw DeltaError("delta payload: " + std::to_string(end - p) + " value bytes for " +
                         std::to_string(n) + " vertices (6 each)");
    const uint8_t* low = p;
    const uint8_t* high = p + 3 * n;
    uint16_t previous[3] = {0, 0, 0};
    std::vector<uint16_t> out = values;
    size_t k = 0;
    for (const DeltaRun& r : runs)
        for (size_t v = r.start; v < size_t(r.start) + r.count; ++v)
            for (int c = 0; c < 3; ++c, ++k) {
                const uint16_t residual = UnZigZag(static_cast<uint16_t>(low[k] | high[k] << 8));
                const uint16_t predicted = keyframe ? previous[c] : out[3 * v + c];
                out[3 * v + c] = static_cast<uint16_t>(predicted + residual);
                previous[c] = out[3 * v + c];
            }
    values = std::move(out);
}

}  // namespace penumbra::protocol
