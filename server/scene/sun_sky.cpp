// A sun on a node of its own and Preetham et al.'s analytic clear sky (sun_sky.h).
#include "scene/sun_sky.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtx/quaternion.hpp>
#include <memory>
#include <numbers>

#include "base/check.h"

namespace penumbra {
namespace {

constexpr float kPi = std::numbers::pi_v<float>;

// The Perez et al. sky distribution (Preetham Eq. 3): relative luminance or chromaticity at
// zenith angle θ, γ from the sun.
struct Perez {
    float a, b, c, d, e;
    float operator()(float cosTheta, float gamma) const {
        const float cosGamma = std::cos(gamma);
        return (1.0f + a * std::exp(b / std::max(cosTheta, 1e-4f))) *
               (1.0f + c * std::exp(d * gamma) + e * cosGamma * cosGamma);
    }
};

// Preetham's appendix: the distribution coefficients of Y, x and y against turbidity T.
Perez LuminanceCoefficients(float t) {
    return {0.1787f * t - 1.4630f, -0.3554f * t + 0.4275f, -0.0227f * t + 5.3251f,
            0.1206f * t - 2.5771f, -0.0670f * t + 0.3703f};
}
Perez XCoefficients(float t) {
    return {-0.0193f * t - 0.2592f, -0.0665f * t + 0.0008f, -0.0004f * t + 0.2125f,
            -0.0641f * t - 0.8989f, -0.0033f * t + 0.0452f};
}
Perez YCoefficients(float t) {
    return {-0.0167f * t - 0.2608f, -0.0950f * t + 0.0092f, -0.0079f * t + 0.2102f,
            -0.0441f * t - 1.6537f, -0.0109f * t + 0.0529f};
}

// The zenith chromaticity fits: [T² T 1] · M · [θs³ θs² θs 1]ᵀ.
float ZenithChromaticity(const float m[3][4], float t, float thetaS) {
    const float tv[3] = {t * t, t, 1.0f};
    const float sv[4] = {thetaS * thetaS * thetaS, thetaS * thetaS, thetaS, 1.0f};
    float sum = 0.0f;
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 4; ++j) sum += tv[i] * m[i][j] * sv[j];
    return sum;
}
constexpr float kZenithX[3][4] = {{0.00166f, -0.00375f, 0.00209f, 0.0f},
                                  {-0.02903f, 0.06377f, -0.03202f, 0.00394f},
                                  {0.11693f, -0.21196f, 0.06052f, 0.25886f}};
constexpr float kZenithY[3][4] = {{0.00275f, -0.00610f, 0.00317f, 0.0f},
                                  {-0.04214f, 0.08970f, -0.04153f, 0.00516f},
                                  {0.15346f, -0.26756f, 0.06670f, 0.26688f}};

void ValidateTurbidity(float turbidity) {
    if (!(turbidity >= kMinTurbidity && turbidity <= kMaxTurbidity)) {
        char why[160];
        std::snprintf(why, sizeof why,
                      "sky turbidity must lie within %.1f … %.0f (3: a clear day), not %g",
                      kMinTurbidity, kMaxTurbidity, double(turbidity));
        throw Error(why);
    }
}

}  // namespace

glm::vec3 SunDirection(const SunPosition& sun) {
    const float az = glm::radians(sun.azimuth), el = glm::radians(sun.elevation);
    return glm::normalize(
        glm::vec3(std::sin(az) * std::cos(el), std::sin(el), -std::cos(az) * std::cos(el)));
}

void ValidateSunPosition(const SunPosition& sun) {
    if (!std::isfinite(sun.azimuth)) throw Error("sun azimuth must be a finite number of degrees");
    if (!(sun.elevation >= 0.0f && sun.elevation <= 90.0f))
        throw Error("sun elevation must lie within 0 … 90 degrees above the horizon");
}

glm::mat4 SunTransform(const SunPosition& sun) {
    return glm::mat4_cast(glm::rotation(glm::vec3(0.0f, 0.0f, -1.0f), -SunDirection(sun)));
}

SunPosition SunPositionOf(const PunctualLight& sun) {
    const glm::vec3 d = -sun.direction;
    return {glm::degrees(std::atan2(d.x, -d.z)),
            glm::degrees(std::asin(std::clamp(d.y, -1.0f, 1.0f)))};
}

int AddSun(Scene& scene, const SunPosition& sun, float illuminance) {
    ValidateSunPosition(sun);
    if (!std::isfinite(illuminance) || illuminance < 0.0f)
        throw Error("sun illuminance must be a finite number of lux ≥ 0");
    if (FindNode(scene, kSunName) >= 0 || FindLight(scene, kSunName) >= 0)
        throw Error(std::string("the scene already has a node or light called '") + kSunName +
                    "': give its own sun in the file or leave out --sun");
    SceneNode node;
    node.name = kSunName;
    node.local = node.world = SunTransform(sun);
    scene.nodes.push_back(node);
    PunctualLight light;
    light.name = kSunName;
    light.node = int(scene.nodes.size()) - 1;
    light.type = LightType::kDirectional;
    light.color = glm::vec3(1.0f);
    light.intensity = illuminance;
    PlaceLight(light, node.world);
    scene.lights.push_back(light);
    return int(scene.lights.size()) - 1;
}

float ClearSkyZenithLuminance(const SunPosition& sun, float turbidity) {
    const float thetaS = glm::radians(90.0f - sun.elevation);
    const float chi = (4.0f / 9.0f - turbidity / 120.0f) * (kPi - 2.0f * thetaS);
    const float kcd =
        (4.0453f * turbidity - 4.9710f) * std::tan(chi) - 0.2155f * turbidity + 2.4192f;
    return 1000.0f * std::max(kcd, 0.0f);
}

Environment ClearSky(const SunPosition& sun, float turbidity, int width) {
    ValidateSunPosition(sun);
    ValidateTurbidity(turbidity);
    PENUMBRA_CHECK(width >= 4 && width % 2 == 0);
    const int height = width / 2;
    const glm::vec3 toSun = SunDirection(sun);
    const float thetaS = glm::radians(90.0f - sun.elevation);
    const Perez perezY = LuminanceCoefficients(turbidity), perezX = XCoefficients(turbidity),
                perezy = YCoefficients(turbidity);
    const float zenithY = ClearSkyZenithLuminance(sun, turbidity);
    const float zenithX = ZenithChromaticity(kZenithX, turbidity, thetaS);
    const float zenithy = ZenithChromaticity(kZenithY, turbidity, thetaS);
    // Eq. 3: each quantity is its zenith value times F(θ, γ) / F(0, θs).
    const float normY = perezY(1.0f, thetaS), normX = perezX(1.0f, thetaS),
                normy = perezy(1.0f, thetaS);
    auto image = std::make_shared<Image>(width, height);
    for (int y = 0; y < height; ++y)
        for (int x = 0; x < width; ++x) {
            const glm::vec3 d = EquirectDirection((x + 0.5f) / width, (y + 0.5f) / height);
            if (d.y <= 0.0f) continue;  // below the horizon: black
            const float gamma = std::acos(std::clamp(glm::dot(d, toSun), -1.0f, 1.0f));
            const float lum = zenithY * perezY(d.y, gamma) / normY;
            const float cx = zenithX * perezX(d.y, gamma) / normX;
            const float cy = zenithy * perezy(d.y, gamma) / normy;
            if (!(lum > 0.0f) || !(cy > 0.0f)) continue;
            const float bigX = cx / cy * lum, bigZ = (1.0f - cx - cy) / cy * lum;
            const glm::vec3 rgb(3.2406f * bigX - 1.5372f * lum - 0.4986f * bigZ,
                                -0.9689f * bigX + 1.8758f * lum + 0.0415f * bigZ,
                                0.0557f * bigX - 0.2040f * lum + 1.0570f * bigZ);
            image->At(x, y) = glm::max(rgb, glm::vec3(0.0f));
        }
    Environment env;
    char source[160];
    std::snprintf(source, sizeof source,
                  "clear sky (Preetham, turbidity %g, sun at azimuth %g°, elevation %g°)",
                  double(turbidity), double(sun.azimuth), double(sun.elevation));
    env.source = source;
    env.image = std::move(image);
    env.turbidity = turbidity;
    return env;
}

}  // namespace penumbra
