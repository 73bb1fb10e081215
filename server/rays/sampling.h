// Sampling patterns of the gather stage (emitter direct light, final gather): a rotated R2
// sequence over the unit square and the cosine-distributed hemisphere.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <glm/glm.hpp>

#include "base/numeric.h"

namespace penumbra {

// The R2 sequence (Roberts 2018): point i at frac(s + i·(1/φ₂, 1/φ₂²)), φ₂ the plastic
// number; any run of consecutive points is spread evenly over the unit square. `s` rotates
// it (Cranley–Patterson), a rotation per point gives each point a pattern of its own.
inline glm::vec2 R2Point(const glm::vec2& s, int i) {
    constexpr double a = 0.7548776662466927, b = 0.5698402909980532;
    // v − ⌊v⌋ (the integer part by truncation, v ≥ 0) is fmod(v, 1) exactly, at a fraction of
    // its cost.
    const double x = s.x + i * a, y = s.y + i * b;
    return {static_cast<float>(x - static_cast<double>(static_cast<int64_t>(x))),
            static_cast<float>(y - static_cast<double>(static_cast<int64_t>(y)))};
}

// The orthonormal basis (t, s, n) of Duff et al. (2017) about the unit normal n.
inline void Basis(const glm::vec3& n, glm::vec3& t, glm::vec3& s) {
    const float sign = std::copysign(1.0f, n.z);
    const float p = -1.0f / (sign + n.z), q = n.x * n.y * p;
    t = glm::vec3(1.0f + sign * n.x * n.x * p, sign * q, -sign * n.x);
    s = glm::vec3(q, sign + n.y * n.y * p, -n.y);
}

// Shirley and Chiu's concentric map of u in the unit square to the unit disk, as a signed
// radius and an angle (r < 0: the point at angle phi + π).
inline void Concentric(const glm::vec2& u, float& r, float& phi) {
    const float a = 2.0f * u.x - 1.0f, b = 2.0f * u.y - 1.0f;
    r = 0.0f, phi = 0.0f;
    if (a == 0.0f && b == 0.0f) return;
    if (std::abs(a) > std::abs(b)) {
        r = a;
        phi = (kPi / 4.0f) * (b / a);
    } else {
        r = b;
        phi = (kPi / 2.0f) - (kPi / 4.0f) * (a / b);
    }
}

// Cosine-distributed direction about the unit normal n (pdf cosθ/π) for a point u of the unit
// square: the concentric map to the disk, lifted to the hemisphere (Malley's method), in the
// basis of Duff et al.
inline glm::vec3 CosineDirection(const glm::vec3& n, const glm::vec2& u) {
    float r, phi;
    Concentric(u, r, phi);
    const float x = r * std::cos(phi), y = r * std::sin(phi);
    const float z = std::sqrt(std::max(0.0f, 1.0f - x * x - y * y));
    glm::vec3 t, s;
    Basis(n, t, s);
    return glm::normalize(x * t + y * s + z * n);
}

// Which points u of the unit square CosineDirection(n, u) may map into a cone of directions
// (unit axis, sine of its half-angle): a test on u alone, a division and no trigonometry,
// so that a fixed pattern's rays can be turned away before anything about them is made or
// read. Conservative: every u whose direction lies in the cone passes (some others do too).
// By Malley's method a direction at angle θ from n lies at radius sin θ on the disk, so the
// cone's directions lie in a ring of radii and, when it leaves out n, a sector of angles.
class CosineCone {
  public:
    CosineCone() = default;  // takes every u
    CosineCone(const glm::vec3& n, const glm::vec3& axis, float sinHalf) {
        constexpr float kSlack = 1e-3f;  // widens the cone and the ring, for rounding
        const float sa = std::max(sinHalf, 0.0f) + kSlack;
        if (!(sa < 1.0f)) return;
        all_ = false;
        const float ca = std::sqrt(1.0f - sa * sa);
        // θ: the axis' angle from n; the cone spans θ − α … θ + α (α its half-angle).
        const float ct = std::clamp(glm::dot(axis, n), -1.0f, 1.0f);
        const float st = std::sqrt(1.0f - ct * ct);
        if (ct * ca + st * sa <= 0.0f) {  // cos(θ − α) ≤ 0: all of it below the horizon
            empty_ = true;
            return;
        }
        const bool pole = ct >= ca;  // θ ≤ α: the cone holds n
        rLo_ = pole ? 0.0f : st * ca - ct * sa - kSlack;
        rHi_ = ct * ca - st * sa <= 0.0f ? 2.0f : st * ca + ct * sa + kSlack;
        if (pole || !(sa < st)) return;  // the whole turn of angles
        wholeTurn_ = false;
        glm::vec3 t, s;
        Basis(n, t, s);
        phi_ = std::atan2(glm::dot(axis, s), glm::dot(axis, t));
        width_ = std::asin(sa / st) + kSlack;
    }
    bool Empty() const { return empty_; }
    bool MayContain(const glm::vec2& u) const {
        if (all_) return true;
        if (empty_) return false;
        // The concentric map's radius is the larger of |a|, |b|: the ring first, no division.
        const float ring = std::max(std::abs(2.0f * u.x - 1.0f), std::abs(2.0f * u.y - 1.0f));
        if (ring < rLo_ || ring > rHi_) return false;
        if (wholeTurn_) return true;
        float r, phi;
        Concentric(u, r, phi);
        if (r < 0.0f) phi += kPi;
        // phi in [−π/4, 7π/4], phi_ in [−π, π]: the difference into [−π, π].
        float d = phi - phi_;
        if (d > kPi) d -= 2.0f * kPi;
        if (d > kPi) d -= 2.0f * kPi;
        if (d < -kPi) d += 2.0f * kPi;
        return std::abs(d) <= width_;
    }

  private:
    bool all_ = true, empty_ = false, wholeTurn_ = true;
    float rLo_ = 0.0f, rHi_ = 2.0f, phi_ = 0.0f, width_ = 0.0f;
};

}  // namespace penumbra
