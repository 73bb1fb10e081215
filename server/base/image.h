// Linear RGB images and their files: OpenEXR in (environment maps) and out (renders),
// 8-bit PNG out. Rows are stored top to bottom.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <vector>

namespace penumbra {

struct Image {
    int width = 0;
    int height = 0;
    std::vector<glm::vec3> pixels;  // row-major, row 0 at the top

    Image() = default;
    Image(int w, int h) : width(w), height(h), pixels(size_t(w) * size_t(h), glm::vec3(0.0f)) {}
    glm::vec3& At(int x, int y) { return pixels[size_t(y) * size_t(width) + size_t(x)]; }
    const glm::vec3& At(int x, int y) const {
        return pixels[size_t(y) * size_t(width) + size_t(x)];
    }
    bool Empty() const { return pixels.empty(); }
};

// Rec. 709 luminance of linear RGB.
inline float Luminance(const glm::vec3& c) { return 0.2126f * c.x + 0.7152f * c.y + 0.0722f * c.z; }

// The luminance (Rec. 709) below which 99% of the positive, finite values lie: the scale an
// automatic exposure maps to 1. 0 when there is none.
float Luminance99(const std::vector<glm::vec3>& values);

// Largest image accepted from a file: each side, and all its pixels (a 16K equirectangular
// map is 16384 × 8192, 1.6 GB as floats). Checked from the header, before any pixel is
// allocated: a file of a few bytes can declare any size.
inline constexpr int kMaxImageSide = 16384;
inline constexpr long kMaxImagePixels = 16384L * 8192L;

// Reads the R, G, B channels of an OpenEXR file as linear floats (half or float storage;
// a luminance-only file gives grey). Throws penumbra::Error naming the file and the reason.
Image ReadExr(const std::string& path);
// Writes linear RGB as half-float OpenEXR (values beyond half's range are clamped).
// Throws penumbra::Error when the file cannot be written.
void WriteExr(const std::string& path, const Image& image);
// Writes 8-bit sRGB PNG from `rgb` (width × height × 3 bytes, top row first).
// Throws penumbra::Error when the file cannot be written.
void WritePng(const std::string& path, int width, int height, const std::vector<uint8_t>& rgb);

}  // namespace penumbra
