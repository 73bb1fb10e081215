// Environment map loading, validation and lookup (equirectangular, bilinear).
#include "scene/environment.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "base/check.h"
#include "base/numeric.h"

namespace penumbra {
namespace {

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

namespace {

// Where SkySampler and SplitSky split a map: its mean luminance over the sphere (pixels
// weighted by sin θ at their centres), with a margin that keeps a flat map's rounding from
// counting as a sun.
double SplitLevel(const Image& im) {
    double sphere = 0.0, sines = 0.0;
    for (int y = 0; y < im.height; ++y) {
        const double sine = std::sin((y + 0.5) * std::numbers::pi / im.height);
        for (int x = 0; x < im.width; ++x) sphere += Luminance(im.At(x, y)) * sine;
        sines += sine * im.width;
    }
    return sines > 0.0 ? 1.001 * sphere / sines : 0.0;
}

}  // namespace

SkySampler::SkySampler(const Environment& environment, bool aboveMean) {
    if (!environment.image || environment.image->Empty()) return;
    const Image& im = *environment.image;
    width_ = im.width, height_ = im.height, rotation_ = environment.rotation;
    const double floor = aboveMean ? SplitLevel(im) : 0.0;
    above_.resize(im.pixels.size());
    for (size_t i = 0; i < im.pixels.size(); ++i)
        above_[i] = static_cast<float>(std::max(0.0, Luminance(im.pixels[i]) - floor));
    // Cell weights: the integral of the bilinear lookup of above_ over the cell, times sin θ
    // at its middle.
    const int rows = height_ + 1;
    std::vector<double> weight(size_t(rows) * width_);
    std::vector<double> rowSum(rows, 0.0);
    for (int j = 0; j < rows; ++j) {
        const double lo = std::max(0.0, j - 0.5), hi = std::min(double(height_), j + 0.5);
        const double sine = std::sin(0.5 * (lo + hi) * std::numbers::pi / height_);
        for (int i = 0; i < width_; ++i) {
            const glm::vec4 c = Corners(i, j);
            const double w = 0.25 * (c.x + c.y + c.z + c.w) * (hi - lo) * sine;
            weight[size_t(j) * width_ + i] = w;
            rowSum[j] += w;
        }
    }
    double total = 0.0;
    for (double r : rowSum) total += r;
    if (!(total > 0.0)) {
        above_.clear();
        return;
    }
    rowCdf_.assign(rows + 1, 0.0f);
    rowWeight_.assign(rows, 0.0f);
    columnCdf_.assign(size_t(rows) * (width_ + 1), 0.0f);
    double acc = 0.0;
    for (int j = 0; j < rows; ++j) {
        acc += rowSum[j];
        rowCdf_[j + 1] = static_cast<float>(acc / total);
        rowWeight_[j] = static_cast<float>(rowSum[j] / total);
        float* cdf = &columnCdf_[size_t(j) * (width_ + 1)];
        double run = 0.0;
        for (int i = 0; i < width_; ++i) {
            run += weight[size_t(j) * width_ + i];
            // A dark row (never drawn) keeps a uniform distribution.
            cdf[i + 1] = rowSum[j] > 0.0 ? static_cast<float>(run / rowSum[j])
                                         : static_cast<float>(i + 1) / width_;
        }
        cdf[width_] = 1.0f;
    }
    rowCdf_[rows] = 1.0f;
}

glm::vec4 SkySampler::Corners(int i, int j) const {
    auto at = [&](int x, int y) {
        return above_[size_t(std::clamp(y, 0, height_ - 1)) * width_ + (x + width_) % width_];
    };
    return {at(i, j - 1), at(i + 1, j - 1), at(i, j), at(i + 1, j)};
}

namespace {

// The interval i of `cdf` (n + 1 increasing values from 0 to 1) that holds u, and where in it
// u lies (0 … 1): the same u always gives the same point, so a stratified u stays stratified.
int Invert(const float* cdf, int n, float u, float& within) {
    u = std::clamp(u, 0.0f, std::nextafter(1.0f, 0.0f));
    int i = static_cast<int>(std::upper_bound(cdf, cdf + n + 1, u) - cdf) - 1;
    i = std::clamp(i, 0, n - 1);
    const float width = cdf[i + 1] - cdf[i];
    within = width > 0.0f ? std::clamp((u - cdf[i]) / width, 0.0f, 1.0f) : 0.5f;
    return i;
}

// x in [0, 1] drawn with density ∝ (1 − x)·a + x·b (a, b ≥ 0) for u in [0, 1] (PBR 4th ed.,
// SampleLinear).
float SampleLinear(float u, float a, float b) {
    if (u == 0.0f && a == 0.0f) return 0.0f;
    if (!(std::abs(a - b) > 1e-6f * (a + b))) return u;
    const float x = u * (a + b) / (a + std::sqrt((1.0f - u) * a * a + u * b * b));
    return std::min(x, std::nextafter(1.0f, 0.0f));
}

float Bilinear(const glm::vec4& c, float s, float t) {
    return (1.0f - t) * ((1.0f - s) * c.x + s * c.y) + t * ((1.0f - s) * c.z + s * c.w);
}

}  // namespace

float SkySampler::CellPdf(int i, int j, float s, float t) const {
    const glm::vec4 c = Corners(i, j);
    const float mean = 0.25f * (c.x + c.y + c.z + c.w);
    if (!(mean > 0.0f)) return 0.0f;
    const float* cdf = &columnCdf_[size_t(j) * (width_ + 1)];
    const float lo = std::max(0.0f, j - 0.5f), hi = std::min(float(height_), j + 0.5f);
    // The cell's probability over its area in (u, v), shaped by the bilinear lookup.
    const float area = (1.0f / width_) * ((hi - lo) / height_);
    return rowWeight_[j] * (cdf[i + 1] - cdf[i]) / area * (Bilinear(c, s, t) / mean);
}

glm::vec3 SkySampler::Sample(const glm::vec2& u, float& pdf) const {
    pdf = 0.0f;
    if (!Usable()) return glm::vec3(0.0f, 1.0f, 0.0f);
    float fj, fi;
    const int j = Invert(rowCdf_.data(), height_ + 1, u.y, fj);
    const int i = Invert(&columnCdf_[size_t(j) * (width_ + 1)], width_, u.x, fi);
    // Inside the cell by the bilinear lookup: t by the rows' sums, s by the row at t.
    const glm::vec4 c = Corners(i, j);
    const float t = SampleLinear(fj, c.x + c.y, c.z + c.w);
    const float s = SampleLinear(fi, c.x + (c.z - c.x) * t, c.y + (c.w - c.y) * t);
    // Pixel coordinates (centres at + ½): the cell spans the centres i … i + 1, j − 1 … j
    // (the first and last row of cells are half cells at the poles, where the lookup is flat
    // in v).
    const float lo = std::max(0.0f, j - 0.5f), hi = std::min(float(height_), j + 0.5f);
    const float x = i + 0.5f + s, y = lo + (hi - lo) * t;
    const float v = std::clamp(y / height_, 0.0f, 1.0f);
    const float sine = std::sin(v * kPi);
    if (sine > 0.0f) pdf = CellPdf(i, j, s, t) / (2.0f * kPi * kPi * sine);
    float uu = x / width_;
    if (uu >= 1.0f) uu -= 1.0f;
    return RotateY(EquirectDirection(uu, v), rotation_);
}

float SkySampler::Pdf(const glm::vec3& towardSky) const {
    if (!Usable()) return 0.0f;
    const glm::vec3 d = RotateY(towardSky, -rotation_);
    const glm::vec2 uv = EquirectUv(d);
    const float sine = std::sqrt(std::max(0.0f, 1.0f - d.y * d.y));
    if (!(sine > 0.0f)) return 0.0f;
    // The cell the lookup reads (Environment::MapRadiance): x, y between pixel centres.
    const float x = uv.x * width_ - 0.5f, y = uv.y * height_ - 0.5f;
    const float fx = std::floor(x), fy = std::floor(y);
    const int i = ((static_cast<int>(fx) % width_) + width_) % width_;
    const int j = std::clamp(static_cast<int>(fy) + 1, 0, height_);
    const float s = std::clamp(x - fx, 0.0f, 1.0f);
    // In a half cell at a pole the lookup is flat in v, so t does not matter there.
    const float t = std::clamp(y - fy, 0.0f, 1.0f);
    return CellPdf(i, j, s, t) / (2.0f * kPi * kPi * sine);
}

bool HasSun(const Environment& environment) {
    if (!environment.image || environment.image->Empty()) return false;
    const double level = SplitLevel(*environment.image);
    for (const glm::vec3& p : environment.image->pixels)
        if (Luminance(p) > level) return true;
    return false;
}

SkyParts SplitSky(const Environment& environment) {
    SkyParts parts;
    parts.rest = environment;
    parts.sun = environment;
    parts.sun.image.reset();
    parts.sun.constant = glm::vec3(0.0f);
    if (!environment.image || environment.image->Empty()) return parts;
    const Image& im = *environment.image;
    const double level = SplitLevel(im);
    auto sun = std::make_shared<Image>(im.width, im.height);
    auto rest = std::make_shared<Image>(im.width, im.height);
    bool any = false;
    for (size_t i = 0; i < im.pixels.size(); ++i) {
        const float y = Luminance(im.pixels[i]);
        const float share = y > level ? static_cast<float>((y - level) / y) : 0.0f;
        sun->pixels[i] = share * im.pixels[i];
        rest->pixels[i] = im.pixels[i] - sun->pixels[i];
        any = any || share > 0.0f;
    }
    if (!any) return parts;
    Environment split = environment;
    split.image = std::move(sun);
    SkySampler sampler(split, false);
    if (!sampler.Usable()) return parts;
    parts.sun = std::move(split);
    parts.rest.image = std::move(rest);
    parts.sampler = std::move(sampler);
    return parts;
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
