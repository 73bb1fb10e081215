// Tint maps: decoding, normalising by the mean, the mip chain, bilinear and triangle lookups.
// Used by the loader (scene/gltf_loader.cpp) and, through Scene's tints, by every solver.
#include "scene/texture.h"

#include <stb/stb_image.h>

#include <algorithm>
#include <cmath>

#include "base/check.h"
#include "scene/gltf_loader.h"

namespace penumbra {

namespace {

// Texel index along one axis of `n` texels for integer coordinate i, by the wrap mode.
int WrapIndex(int i, int n, Wrap mode) {
    switch (mode) {
        case Wrap::kClamp:
            return std::clamp(i, 0, n - 1);
        case Wrap::kMirror: {
            const int period = 2 * n;
            int k = i % period;
            if (k < 0) k += period;
            return k < n ? k : period - 1 - k;
        }
        case Wrap::kRepeat:
        default: {
            int k = i % n;
            return k < 0 ? k + n : k;
        }
    }
}

}  // namespace

TintMap::TintMap(int width, int height, std::vector<glm::vec3> linear, Wrap s, Wrap t)
    : s_(s), t_(t) {
    if (width <= 0 || height <= 0 ||
        linear.size() != static_cast<size_t>(width) * static_cast<size_t>(height))
        throw Error("a texture's size does not match its texels");
    glm::dvec3 sum(0.0);
    for (const glm::vec3& c : linear) sum += glm::dvec3(c);
    mean_ = glm::vec3(sum / static_cast<double>(linear.size()));
    glm::vec3 scale;
    for (int c = 0; c < 3; ++c) scale[c] = mean_[c] > 0.0f ? 1.0f / mean_[c] : 0.0f;
    for (glm::vec3& c : linear) c *= scale;
    std::vector<Level> levels;
    levels.push_back({width, height, std::move(linear)});
    // Box-filtered halvings down to one texel; an odd last row or column folds into the one
    // before it.
    while (levels.back().w > 1 || levels.back().h > 1) {
        const Level& a = levels.back();
        Level b;
        b.w = std::max(1, a.w / 2), b.h = std::max(1, a.h / 2);
        b.texels.assign(static_cast<size_t>(b.w) * b.h, glm::vec3(0.0f));
        std::vector<float> count(b.texels.size(), 0.0f);
        for (int y = 0; y < a.h; ++y)
            for (int x = 0; x < a.w; ++x) {
                const size_t j = static_cast<size_t>(std::min(y / 2, b.h - 1)) * b.w +
                                 static_cast<size_t>(std::min(x / 2, b.w - 1));
                b.texels[j] += a.texels[static_cast<size_t>(y) * a.w + x];
                count[j] += 1.0f;
            }
        for (size_t j = 0; j < b.texels.size(); ++j) b.texels[j] /= count[j];
        levels.push_back(std::move(b));
    }
    levels_ = std::make_shared<const std::vector<Level>>(std::move(levels));
}

glm::vec3 TintMap::Bilinear(const Level& level, const glm::vec2& uv) const {
    // Texel centres at (i + ½) / w.
    const float x = uv.x * static_cast<float>(level.w) - 0.5f;
    const float y = uv.y * static_cast<float>(level.h) - 0.5f;
    if (!std::isfinite(x) || !std::isfinite(y)) return glm::vec3(1.0f);
    const float fx = std::floor(x), fy = std::floor(y);
    // Brought near [0, n) before the conversion, so that a coordinate far outside [0, 1]
    // cannot overflow an int: by the period 2n (repeat and mirror) or clamped.
    auto near = [](float f, int n, Wrap mode) {
        if (mode == Wrap::kClamp) return static_cast<int>(std::clamp(f, -1.0f, float(n)));
        return static_cast<int>(std::fmod(static_cast<double>(f), 2.0 * n));
    };
    const int x0 = near(fx, level.w, s_), y0 = near(fy, level.h, t_);
    const float ax = x - fx, ay = y - fy;
    auto at = [&](int i, int j) {
        return level.texels[static_cast<size_t>(WrapIndex(j, level.h, t_)) * level.w +
                            static_cast<size_t>(WrapIndex(i, level.w, s_))];
    };
    return glm::mix(glm::mix(at(x0, y0), at(x0 + 1, y0), ax),
                    glm::mix(at(x0, y0 + 1), at(x0 + 1, y0 + 1), ax), ay);
}

glm::vec3 TintMap::At(const glm::vec2& uv) const { return Bilinear((*levels_)[0], Apply(uv)); }

TintMap TintMap::Transformed(const glm::mat3& uv) const {
    TintMap out = *this;
    out.uv_ = uv_ * uv;
    return out;
}

glm::vec3 TintMap::Over(const glm::vec2& ra, const glm::vec2& rb, const glm::vec2& rc) const {
    // The level at which the triangle covers about 16 texels, then the bilinear tints at the
    // centroids of its 4 × 4 subdivision into 16 triangles of equal area. An affine transform
    // maps the triangle to a triangle and its centroids to the image's.
    const glm::vec2 a = Apply(ra), b = Apply(rb), c = Apply(rc);
    const glm::vec2 e1 = b - a, e2 = c - a;
    const double texels =
        0.5 * std::abs(static_cast<double>(e1.x) * e2.y - static_cast<double>(e1.y) * e2.x) *
        (*levels_)[0].w * (*levels_)[0].h;
    if (!std::isfinite(texels)) return glm::vec3(1.0f);
    int level = texels > 16.0 ? static_cast<int>(std::floor(0.5 * std::log2(texels / 16.0))) : 0;
    level = std::min(level, static_cast<int>(levels_->size()) - 1);
    const Level& l = (*levels_)[level];
    constexpr int kSide = 4;
    glm::vec3 sum(0.0f);
    for (int i = 0; i < kSide; ++i)
        for (int j = 0; i + j < kSide; ++j) {
            // Upward sub-triangle (i, j), and the downward one beside it where there is one.
            const glm::vec2 up = a + (static_cast<float>(i) + 1.0f / 3.0f) / kSide * e1 +
                                 (static_cast<float>(j) + 1.0f / 3.0f) / kSide * e2;
            sum += Bilinear(l, up);
            if (i + j + 1 < kSide) {
                const glm::vec2 down = a + (static_cast<float>(i) + 2.0f / 3.0f) / kSide * e1 +
                                       (static_cast<float>(j) + 2.0f / 3.0f) / kSide * e2;
                sum += Bilinear(l, down);
            }
        }
    return sum / static_cast<float>(kSide * kSide);
}

bool EncodedImageSize(const std::vector<unsigned char>& encoded, int& width, int& height) {
    int channels = 0;
    return !encoded.empty() &&
           stbi_info_from_memory(encoded.data(), static_cast<int>(encoded.size()), &width, &height,
                                 &channels) != 0;
}

bool DecodeSrgbImage(const std::vector<unsigned char>& encoded, int& width, int& height,
                     std::vector<glm::vec3>& linear, const char*& why) {
    int channels = 0;
    unsigned char* rgb =
        encoded.empty() ? nullptr
                        : stbi_load_from_memory(encoded.data(), static_cast<int>(encoded.size()),
                                                &width, &height, &channels, 3);
    if (!rgb) {
        why = encoded.empty() ? "no data" : stbi_failure_reason();
        return false;
    }
    float table[256];
    for (int i = 0; i < 256; ++i) table[i] = SrgbToLinear(static_cast<float>(i) / 255.0f);
    const size_t pixels = static_cast<size_t>(width) * static_cast<size_t>(height);
    linear.resize(pixels);
    for (size_t i = 0; i < pixels; ++i)
        linear[i] = glm::vec3(table[rgb[3 * i]], table[rgb[3 * i + 1]], table[rgb[3 * i + 2]]);
    stbi_image_free(rgb);
    return true;
}

}  // namespace penumbra
