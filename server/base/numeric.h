// Small numeric helpers every stage uses: π as a float, finiteness of vectors and matrices,
// and the milliseconds since a time point (the stages' timings).
#pragma once

#include <chrono>
#include <cmath>
#include <glm/glm.hpp>
#include <numbers>

namespace penumbra {

inline constexpr float kPi = std::numbers::pi_v<float>;

inline bool Finite(const glm::vec3& v) {
    return std::isfinite(v.x) && std::isfinite(v.y) && std::isfinite(v.z);
}

inline bool Finite(const glm::mat4& m) {
    for (int c = 0; c < 4; ++c)
        for (int r = 0; r < 4; ++r)
            if (!std::isfinite(m[c][r])) return false;
    return true;
}

inline double MsSince(std::chrono::steady_clock::time_point t) {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count();
}

}  // namespace penumbra
