// Environment map loading, validation and lookup (equirectangular, bilinear).
#include "scene/environment.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "base/check.h"

namespace penumbra {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

glm::vec3 RotateY(const glm::vec3& d, float angle) {
    float c = std::cos(angle), s = std::sin(angle);
    return {c * d.x + s * d.z, d.y, -s * d.x + c * d.z};
}

}  // namespace

glm::vec3 EquirectDirection(float u, float v) {
    float phi = (u - 0.5f) * 2.0f * kPi;  // atan2(x, −z)
    float theta = v * kPi;                // from +Y
    float s = std::sin(theta);
    return {s * std::sin(phi), std::cos(theta), -s * std::cos(phi)};
}

glm::vec2 EquirectUv(const glm::vec3& d) {
    float u = 0.5f + std::atan2(d.x, -d.z) / (2.0f * kPi);
    float v = std::acos(std::clamp(d.y, -1.0f, 1.0f)) / kPi;
    return {u, v};
}

bool Environment::Active() const {
    if (!(intensity > 0.0f)) return false;
    if (image) return true;
    return constant.x > 0.0f || constant.y > 0.0f || constant.z > 0.0f;
}

glm::vec3 Environment::MapRadiance(const glm::vec3& d) const {
    if (!image) return constant;
    const Image& im = *image;
    glm::vec2 uv = EquirectUv(d);
    // Bilinear between pixel centres; wraps around in u, clamps at the poles.
    float x = uv.x * im.width - 0.5f, y = uv.y * im.height - 0.5f;
    float fx = std::floor(x), fy = std::floor(y);
    float tx = x - fx, ty = y - fy;
    int x0 = int(fx), y0 = int(fy);
    auto px = [&](int xi, int yi) {
        xi = ((xi % im.width) + im.width) % im.width;
        yi = std::clamp(yi, 0, im.height - 1);
        return im.At(xi, yi);
    };
    return (1 - ty) * ((1 - tx) * px(x0, y0) + tx * px(x0 + 1, y0)) +
           ty * ((1 - tx) * px(x0, y0 + 1) + tx * px(x0 + 1, y0 + 1));
}

glm::vec3 Environment::Radiance(const glm::vec3& towardSky) const {
    if (!(intensity > 0.0f)) return glm::vec3(0.0f);
    // The sky turns by `rotation`: look up the map at the direction turned back.
    return intensity * MapRadiance(RotateY(towardSky, -rotation));
}

Environment LoadEnvironment(const std::string& path) {
    Environment env;
    auto image = std::make_shared<Image>(ReadExr(path));
    for (int y = 0; y < image->height; ++y)
        for (int x = 0; x < image->width; ++x) {
            const glm::vec3& p = image->At(x, y);
            for (int c = 0; c < 3; ++c)
                if (!std::isfinite(p[c]) || p[c] < 0.0f)
                    throw Error(path + ": pixel (" + std::to_string(x) + ", " + std::to_string(y) +
                                ") has radiance " + std::to_string(p[c]) +
                                " (must be finite and non-negative)");
        }
    env.source = path;
    env.image = std::move(image);
    return env;
}

Environment ConstantEnvironment(const glm::vec3& radiance) {
    Environment env;
    for (int c = 0; c < 3; ++c)
        if (!std::isfinite(radiance[c]) || radiance[c] < 0.0f)
            throw Error("a constant sky needs finite, non-negative radiance");
    env.source = "constant";
    env.constant = radiance;
    return env;
}

void ValidateEnvironment(const Environment& env) {
    if (!std::isfinite(env.intensity) || env.intensity < 0.0f)
        throw Error("environment intensity must be a finite number ≥ 0");
    if (!std::isfinite(env.rotation)) throw Error("environment rotation must be finite");
}

}  // namespace penumbra
