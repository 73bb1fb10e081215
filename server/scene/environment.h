// The environment light: radiance arriving from infinity, from an equirectangular OpenEXR
// map or a constant colour, with an intensity scale and a rotation about +Y.
#pragma once

#include <glm/glm.hpp>
#include <memory>
#include <string>
#include <vector>

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
    float turbidity =
        0.0f;  // a clear sky's (scene/sun_sky.h ClearSky: it follows its sun); 0: not one

    bool Active() const;
    // A sky is given (a map or a non-zero colour), whatever its intensity: what decides back
    // occlusion `auto` when links are built.
    bool Present() const { return image || constant != glm::vec3(0.0f); }
    // Radiance (× intensity) arriving from direction `towardSky` (unit), bilinear in the map.
    glm::vec3 Radiance(const glm::vec3& towardSky) const;
    // The map's own value at `towardSky` without rotation or intensity (for tests and tools).
    glm::vec3 MapRadiance(const glm::vec3& towardMap) const;
};

// Directions towards the sky drawn in proportion to a map's brightness, for next-event
// estimation of a sky with a sun in it (a cosine-distributed ray meets an overhead sun 0.5°
// across once in ~46,000 rays). The density follows the map's own bilinear lookup
// (Environment::Radiance): over each cell between four pixel centres, the bilinear interpolation of
// the centres' luminance above the map's mean, the cell weighted by that integral times sin θ at
// its middle (its solid angle). A cell is drawn by its row's marginal and its column's conditional
// distribution, a point in it by the bilinear density (PBR 4th ed., SampleBilinear); over solid
// angle the density is p(u, v) / (2π² sin θ) (PBR 3rd ed., §14.2.4), so L·cosθ/pdf is nearly
// constant over a sun. The sky at or below its mean is left out (density 0): the receiver's own
// sampling (cosine or BRDF, which covers every direction) takes it better, and the two are to be
// joined by multiple importance sampling, which keeps the sum unbiased. Measured on a plane under a
// 0.5-nit sky with a 2° sun of 2,000 nits (one draw of each kind, relative deviation of E): the
// whole map drawn by pixel luminance 0.9 (one draw in two missed the sun); the mean left out, per
// pixel 0.5 (the sun's rim pixels are mostly dark); per bilinear cell, as here, 0.02–0.04. Follows
// the environment's rotation, ignores its intensity. Usable for a map with a part above its mean
// only: a constant sky is drawn best by the receiver's cosine. With `aboveMean` false the whole
// map is drawn by its luminance (SplitSky's sun, which is all above the mean).
class SkySampler {
  public:
    SkySampler() = default;  // not usable
    explicit SkySampler(const Environment& environment, bool aboveMean = true);
    bool Usable() const { return !rowCdf_.empty(); }
    // A direction towards the sky (world space) for a point u of the unit square, and its
    // density over solid angle (0 at a pole: draw nothing then).
    glm::vec3 Sample(const glm::vec2& u, float& pdf) const;
    // The density over solid angle of drawing `towardSky` (unit, world space).
    float Pdf(const glm::vec3& towardSky) const;

  private:
    // Cell (i, j) spans the pixel centres i … i + 1 (wrapping) and rows j − 1 … j (clamped):
    // the corners' values above the mean, (i, j−1), (i+1, j−1), (i, j), (i+1, j).
    glm::vec4 Corners(int i, int j) const;
    // The density over the unit square (u, v) at (s, t) inside cell (i, j).
    float CellPdf(int i, int j, float s, float t) const;

    int width_ = 0, height_ = 0;
    float rotation_ = 0.0f;
    std::vector<float> above_;      // per pixel: its luminance above the map's mean
    std::vector<float> rowCdf_;     // height_ + 2 entries, 0 … 1 (height_ + 1 rows of cells)
    std::vector<float> columnCdf_;  // per row of cells width_ + 1 entries, 0 … 1
    std::vector<float> rowWeight_;  // per row of cells: its share of the whole
};

// An environment map split where SkySampler splits it: `sun` holds each pixel's part above
// the map's mean luminance (the pixel scaled by (Y − mean)/Y), `rest` the remainder, so that
// sun + rest is the map under any lookup (both are bilinear in the pixels); both keep the
// map's intensity, rotation and source. `sampler` draws `sun` (exactly by its luminance).
// For a constant sky or a map without a part above its mean, `sun` is black (no image, no
// colour) and `rest` is the environment itself.
struct SkyParts {
    Environment sun, rest;
    SkySampler sampler;
    bool Split() const { return sampler.Usable(); }
};
SkyParts SplitSky(const Environment& environment);
// Whether SplitSky would split `environment` (a map with a pixel above its mean), without
// making the parts.
bool HasSun(const Environment& environment);

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
