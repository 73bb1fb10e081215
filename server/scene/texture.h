// Surface colour maps: a glTF base colour or emissive texture, decoded to linear colour,
// sampled at a texture coordinate and averaged over a triangle of them (docs/MATERIALS.md).
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <memory>
#include <vector>

namespace penumbra {

// glTF sampler wrap modes (REPEAT 10497, CLAMP_TO_EDGE 33071, MIRRORED_REPEAT 33648).
enum class Wrap : uint8_t { kRepeat, kClamp, kMirror };

// A texture as a tint: its linear texels divided by their mean, channel by channel, so that
// a material's colour, which holds its factor × the texture's mean (what is used wherever
// the map is not sampled), times the tint at a point is the colour at that point. A channel
// whose mean is 0 is 0 everywhere. Sampled bilinearly; averaged over a triangle of texture
// coordinates from a mip level (box-filtered halvings) at which it spans a few texels.
// Immutable once made, and cheap to copy: copies share the texels (a Scene, maps and all, is
// copied by every edit batch of the service).
class TintMap {
  public:
    // `linear`: width × height texels, row by row from the top (v = 0), linear colour.
    // Throws penumbra::Error for a size that does not match.
    TintMap(int width, int height, std::vector<glm::vec3> linear, Wrap s, Wrap t);

    // The texture's mean linear colour (what the tints are relative to).
    const glm::vec3& Mean() const { return mean_; }
    int Width() const { return (*levels_)[0].w; }
    int Height() const { return (*levels_)[0].h; }
    // The tint at texture coordinate `uv` (bilinear, the sampler's wrap modes).
    glm::vec3 At(const glm::vec2& uv) const;
    // The tint averaged over the triangle a, b, c of texture coordinates.
    glm::vec3 Over(const glm::vec2& a, const glm::vec2& b, const glm::vec2& c) const;
    // This map read through the affine texture-coordinate transform `uv` (a glTF textureInfo's
    // KHR_texture_transform: uv' = (uv × (u, v, 1)).xy, applied before this map's own), the
    // texels shared.
    TintMap Transformed(const glm::mat3& uv) const;

  private:
    struct Level {
        int w = 0, h = 0;
        std::vector<glm::vec3> texels;
    };
    glm::vec3 Bilinear(const Level& level, const glm::vec2& uv) const;

    glm::vec2 Apply(const glm::vec2& uv) const { return glm::vec2(uv_ * glm::vec3(uv, 1.0f)); }
    std::shared_ptr<const std::vector<Level>> levels_;
    glm::vec3 mean_{0.0f};
    Wrap s_, t_;
    glm::mat3 uv_{1.0f};  // Transformed
};

// An encoded image's width and height from its header (nothing decoded); false when stb_image
// cannot tell.
bool EncodedImageSize(const std::vector<unsigned char>& encoded, int& width, int& height);

// Decodes an 8-bit sRGB image (PNG, JPEG, ... as stb_image reads them) into linear texels.
// Returns false with stb's reason in `why` when it cannot.
bool DecodeSrgbImage(const std::vector<unsigned char>& encoded, int& width, int& height,
                     std::vector<glm::vec3>& linear, const char*& why);

}  // namespace penumbra
