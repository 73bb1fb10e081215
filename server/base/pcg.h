// A small random number generator with independent streams: PCG32 (O'Neill 2014). The
// reference path tracer and the gather stage give each vertex its own stream, so results
// do not depend on the thread count and a vertex sees the same samples every frame.
#pragma once

#include <cstdint>

namespace penumbra {

class Pcg32 {
  public:
    Pcg32(uint64_t seed, uint64_t stream) : inc_((stream << 1u) | 1u) {
        Next();
        state_ += seed;
        Next();
    }
    uint32_t Next() {
        uint64_t old = state_;
        state_ = old * 6364136223846793005ULL + inc_;
        uint32_t xorshifted = static_cast<uint32_t>(((old >> 18u) ^ old) >> 27u);
        uint32_t rot = static_cast<uint32_t>(old >> 59u);
        return (xorshifted >> rot) | (xorshifted << ((-rot) & 31));
    }
    // Uniform in [0, 1).
    float Uniform() { return static_cast<float>(Next() >> 8) * (1.0f / 16777216.0f); }

  private:
    uint64_t state_ = 0;
    uint64_t inc_;
};

}  // namespace penumbra
