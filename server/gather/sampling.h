// Sampling patterns of the gather stage (emitter direct light, final gather): a rotated R2
// sequence over the unit square and the cosine-distributed hemisphere.
#pragma once

#include <algorithm>
#include <cmath>
#include <glm/glm.hpp>

namespace penumbra {

// The R2 sequence (Roberts 2018): point i at frac(s + i·(1/φ₂, 1/φ₂²)), φ₂ the plastic
// number; any run of consecutive points is spread evenly over the unit square. `s` rotates
// it (Cranley–Patterson), a rotation per point gives each point a pattern of its own.
inline glm::vec2 R2Point(const glm::vec2& s, int i) {
    constexpr double a = 0.7548776662466927, b = 0.5698402909980532;
    return {static_cast<float>(std::fmod(s.x + i * a, 1.0)),
            static_cast<float>(std::fmod(s.y + i * b, 1.0))};
}

// Cosine-distributed direction about the unit normal n (pdf cosθ/π) for a point u of the unit
// square: Shirley and Chiu's concentric map to the disk, lifted to the hemisphere (Malley's
// method), in the orthonormal basis of Duff et al. (2017).
inline glm::vec3 CosineDirection(const glm::vec3& n, const glm::vec2& u) {
    constexpr float kPi = 3.14159265358979f;
    const float a = 2.0f * u.x - 1.0f, b = 2.0f * u.y - 1.0f;
    float r = 0.0f, phi = 0.0f;
    if (a != 0.0f || b != 0.0f) {
        if (std::abs(a) > std::abs(b)) {
            r = a;
            phi = (kPi / 4.0f) * (b / a);
        } else {
            r = b;
            phi = (kPi / 2.0f) - (kPi / 4.0f) * (a / b);
        }
    }
    const float x = r * std::cos(phi), y = r * std::sin(phi);
    const float z = std::sqrt(std::max(0.0f, 1.0f - x * x - y * y));
    const float sign = std::copysign(1.0f, n.z);
    const float p = -1.0f / (sign + n.z), q = n.x * n.y * p;
    const glm::vec3 t(1.0f + sign * n.x * n.x * p, sign * q, -sign * n.x);
    const glm::vec3 s(q, sign + n.y * n.y * p, -n.y);
    return glm::normalize(x * t + y * s + z * n);
}

}  // namespace penumbra
