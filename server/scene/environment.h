// The environment light: radiance arriving from infinity, from an equirectangular OpenEXR
// map or a constant colour, with an intensity scale and a rotation about +Y.
#pragma once

#include <glm/glm.hpp>
#include <memory>
#include <string>

#include "base/image.h"

namespace penumbra {

// Equirectangular mapping (as three.js, Blender and most HDRI sites have it for a Y-up scene):
// the image's centre column looks down −Z, the column at ¾ width looks down +X, the top row is
// straight up (+Y). For a direction d towards the sky: u = ½ + atan2(d.x, −d.z) / 2π,
// v = acos(d.y) / π, pixel (u·width, v·height).
struct Environment {
    std::string source;                  // the file, or "constant"
    std::shared_ptr<const Image> image;  // null for a constant sky
    glm::vec3 constant{0.0f};            // radiance of a constant sky (nits)
    float intensity = 1.0f;              // scales the map or the constant
    float rotation = 0.0f;               // radians about +Y (counter-clockwise seen from above)

    bool Active() const;
    // A sky is given (a map or a non-zero colour), whatever its intensity: what decides back
    // occlusion `auto` when links are built.
    bool Present() const { return image || constant != glm::vec3(0.0f); }
    // Radiance (× intensity) arriving from direction `towardSky` (unit), bilinear in the map.
    glm::vec3 Radiance(const glm::vec3& towardSky) const;
    // The map's own value at `towardSky` without rotation or intensity (for tests and tools).
    glm::vec3 MapRadiance(const glm::vec3& towardMap) const;
};

// Reads an equirectangular EXR; every pixel must be finite and non-negative. Throws
// penumbra::Error naming the file and, for a bad pixel, its position.
Environment LoadEnvironment(const std::string& path);
Environment ConstantEnvironment(const glm::vec3& radiance);
// Checks intensity and rotation (finite, intensity ≥ 0); throws penumbra::Error.
void ValidateEnvironment(const Environment& environment);

// The direction (towards the sky) at the centre of map pixel (x + ½, y + ½) scaled to u, v ∈
// [0, 1], and back.
glm::vec3 EquirectDirection(float u, float v);
glm::vec2 EquirectUv(const glm::vec3& towardSky);

}  // namespace penumbra
