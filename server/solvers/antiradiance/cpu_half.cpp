// The CPU back end's fp16 I_ex tables (cpu_walk.h). Built with F16C (and the AVX it
// implies), so nothing here may run before
// CpuBackend::HalfSupported() said yes.
//
// Rows hold I_ex over the node's area, times a power of two the back end picks per table:
// a node's I_ex grows with its area (from 10⁻⁴ m² for a 1 cm element to the whole scene
// at the root), I_ex / area is a cosine-weighted radiance whatever the node, so fp16's 11
// bits of mantissa hold every node's row to about 5·10⁻⁴ relative, and its range
// (6·10⁻⁵ … 65504, subnormals below) only has to hold the scene's range of radiance.
#include <immintrin.h>

#include <cstring>

#include "solvers/antiradiance/cpu_walk.h"

namespace penumbra::cpu::detail {
namespace {

constexpr float kHalfMax = 65504.0f;

struct HalfRows {
    using Elem = uint16_t;
    static constexpr bool kScaled = true;
    // Eight bytes from the bin's three halves: the fourth is the next bin's red (or the
    // table's pad after the last row), dropped.
    static Rgba Load(const uint16_t* p) {
        __m128 f = _mm_cvtph_ps(_mm_loadl_epi64(reinterpret_cast<const __m128i*>(p)));
        return Rgba(_mm_blend_ps(f, _mm_setzero_ps(), 0x8));
    }
    // Eight-byte stores at a six-byte stride, the last bin's as six bytes. Returns the
    // largest |value|; a row with a value past fp16's range (rare: the scale follows the
    // peak) is stored again, clamped to the range.
    template <class Value>
    static float Store(uint16_t* out, int bins, Value&& value) {
        const __m128 sign = _mm_set1_ps(-0.0f);
        // Two running maxima: one would chain every bin's store on the last one's max.
        __m128 peak[2] = {_mm_setzero_ps(), _mm_setzero_ps()};
        auto convert = [&](int b, bool clamp) {
            __m128 x = __m128(value(b));
            if (clamp) x = _mm_min_ps(_mm_max_ps(x, _mm_set1_ps(-kHalfMax)), _mm_set1_ps(kHalfMax));
            peak[b & 1] = _mm_max_ps(peak[b & 1], _mm_andnot_ps(sign, x));
            return _mm_cvtps_ph(x, _MM_FROUND_TO_NEAREST_INT);
        };
        auto store = [&](bool clamp) {
            int b = 0;
            for (; b + 2 < bins; b += 2) {
                _mm_storel_epi64(reinterpret_cast<__m128i*>(out + b * 3), convert(b, clamp));
                _mm_storel_epi64(reinterpret_cast<__m128i*>(out + b * 3 + 3),
                                 convert(b + 1, clamp));
            }
            for (; b + 1 < bins; ++b)
                _mm_storel_epi64(reinterpret_cast<__m128i*>(out + b * 3), convert(b, clamp));
            uint16_t last[8];
            _mm_storeu_si128(reinterpret_cast<__m128i*>(last), convert(bins - 1, clamp));
            std::memcpy(out + (bins - 1) * 3, last, 3 * sizeof(uint16_t));
            alignas(16) float p[4];
            _mm_store_ps(p, _mm_max_ps(peak[0], peak[1]));
            return std::max({p[0], p[1], p[2]});  // lane 3 is the dropped pad
        };
        const float result = store(false);
        if (!(result <= kHalfMax)) store(true);
        return result;
    }
    // dst = wa·a + wb·b, eight halves at a time.
    static void Sum(uint16_t* dst, const uint16_t* a, float wa, const uint16_t* b, float wb,
                    size_t n) {
        const __m256 va = _mm256_set1_ps(wa), vb = _mm256_set1_ps(wb);
        size_t k = 0;
        for (; k + 8 <= n; k += 8) {
            __m256 x = _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(a + k)));
            __m256 y = _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(b + k)));
            __m256 r = _mm256_add_ps(_mm256_mul_ps(va, x), _mm256_mul_ps(vb, y));
            _mm_storeu_si128(reinterpret_cast<__m128i*>(dst + k),
                             _mm256_cvtps_ph(r, _MM_FROUND_TO_NEAREST_INT));
        }
        for (; k < n; ++k)
            dst[k] =
                _cvtss_sh(wa * _cvtsh_ss(a[k]) + wb * _cvtsh_ss(b[k]), _MM_FROUND_TO_NEAREST_INT);
    }
};

}  // namespace

WalkResult HalfWalk(const AntiradianceModel& m, const uint32_t* leafIndex,
                    const WalkTables<uint16_t>& t, float* irradiance, LocalMode mode) {
    return FusedWalk<HalfRows>(m, leafIndex, t, irradiance, mode).Run();
}

float HalfEncode(const float* iex, size_t nodes, size_t row, const float* scale, uint16_t* out) {
    float peak = 0.0f;
    for (size_t n = 0; n < nodes; ++n)
        for (size_t k = 0; k < row; ++k) {
            float x = iex[n * row + k] * scale[n];
            peak = std::max(peak, std::abs(x));
            out[n * row + k] =
                _cvtss_sh(std::clamp(x, -kHalfMax, kHalfMax), _MM_FROUND_TO_NEAREST_INT);
        }
    return peak;
}

void HalfDecode(const uint16_t* rows, size_t nodes, size_t row, const float* scale, float* out) {
    for (size_t n = 0; n < nodes; ++n)
        for (size_t k = 0; k < row; ++k) out[n * row + k] = _cvtsh_ss(rows[n * row + k]) * scale[n];
}

}  // namespace penumbra::cpu::detail
