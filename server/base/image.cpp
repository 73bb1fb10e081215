// OpenEXR through the library's scanline API (Imf::InputFile with float slices) and PNG
// through stb_image_write.
#include "base/image.h"

#include <OpenEXR/ImfChannelList.h>
#include <OpenEXR/ImfFrameBuffer.h>
#include <OpenEXR/ImfHeader.h>
#include <OpenEXR/ImfInputFile.h>
#include <OpenEXR/ImfRgbaFile.h>
#include <stb/stb_image_write.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <exception>
#include <fstream>

#include "base/check.h"

namespace penumbra {

namespace {

// OpenEXR's own limit, checked when a header is read: without it a file of a few bytes that
// declares a wide data window has its line and compression buffers allocated (and zeroed)
// before the size check below runs. Set once at start; the fuzz target lowers it.
const bool kExrLimitsSet = [] {
    Imf::Header::setMaxImageSize(kMaxImageSide, kMaxImageSide);
    Imf::Header::setMaxTileSize(kMaxImageSide, kMaxImageSide);
    return true;
}();

}  // namespace

Image ReadExr(const std::string& path) {
    try {
        Imf::InputFile file(path.c_str());
        const Imath::Box2i dw = file.header().dataWindow();
        const long w = long(dw.max.x) - dw.min.x + 1, h = long(dw.max.y) - dw.min.y + 1;
        if (w <= 0 || h <= 0 || w > kMaxImageSide || h > kMaxImageSide || w * h > kMaxImagePixels)
            throw Error(path + ": image of " + std::to_string(w) + " × " + std::to_string(h) +
                        " pixels (each side must be 1…" + std::to_string(kMaxImageSide) +
                        ", all of them at most " + std::to_string(kMaxImagePixels) + ")");
        const Imf::ChannelList& channels = file.header().channels();
        const bool rgb =
            channels.findChannel("R") || channels.findChannel("G") || channels.findChannel("B");
        const bool grey = !rgb && channels.findChannel("Y");
        if (!rgb && !grey)
            throw Error(path + ": no R, G, B or Y channel (an environment map needs colour)");
        Image image{int(w), int(h)};
        // Read straight into the interleaved vec3 array: one slice per channel.
        float* base = &image.pixels[0].x;
        Imf::FrameBuffer fb;
        const size_t xs = sizeof(glm::vec3), ys = sizeof(glm::vec3) * size_t(w);
        const char* names[3] = {"R", "G", "B"};
        for (int c = 0; c < 3; ++c)
            fb.insert(grey ? "Y" : names[c],
                      Imf::Slice::Make(Imf::FLOAT, base + c, dw, xs, ys, 1, 1, 0.0));
        file.setFrameBuffer(fb);
        file.readPixels(dw.min.y, dw.max.y);
        return image;
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        throw Error(path + ": not a readable OpenEXR image (" + e.what() + ")");
    }
}

void WriteExr(const std::string& path, const Image& image) {
    PENUMBRA_CHECK_EQ(image.pixels.size(), size_t(image.width) * size_t(image.height));
    const float kHalfMax = 65504.0f;
    auto toHalf = [&](float v) {
        if (!std::isfinite(v)) return half(v > 0 ? kHalfMax : 0.0f);
        return half(std::clamp(v, -kHalfMax, kHalfMax));
    };
    std::vector<Imf::Rgba> px(image.pixels.size());
    for (size_t i = 0; i < px.size(); ++i) {
        const glm::vec3& p = image.pixels[i];
        px[i] = Imf::Rgba(toHalf(p.x), toHalf(p.y), toHalf(p.z), half(1.0f));
    }
    try {
        Imf::RgbaOutputFile file(path.c_str(), image.width, image.height, Imf::WRITE_RGB);
        file.setFrameBuffer(px.data(), 1, size_t(image.width));
        file.writePixels(image.height);
    } catch (const std::exception& e) {
        throw Error(path + ": cannot write OpenEXR (" + e.what() + ")");
    }
}

void WritePng(const std::string& path, int width, int height, const std::vector<uint8_t>& rgb) {
    PENUMBRA_CHECK_EQ(rgb.size(), size_t(width) * size_t(height) * 3);
    // Encoded in memory, then written and closed here: stb's own file writing does not check
    // its writes, so a full disk gave a truncated PNG and no error.
    std::vector<uint8_t> png;
    auto append = [](void* context, void* data, int size) {
        auto* out = static_cast<std::vector<uint8_t>*>(context);
        out->insert(out->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
    };
    if (!stbi_write_png_to_func(append, &png, width, height, 3, rgb.data(), width * 3))
        throw Error(path + ": cannot encode PNG");
    std::ofstream out(path, std::ios::binary | std::ios::trunc);
    if (!out) throw Error(path + ": cannot open for writing (" + std::strerror(errno) + ")");
    out.write(reinterpret_cast<const char*>(png.data()), static_cast<std::streamsize>(png.size()));
    out.close();
    if (!out) throw Error(path + ": cannot write PNG (" + std::strerror(errno) + ")");
}

float Luminance99(const std::vector<glm::vec3>& values) {
    std::vector<float> lum;
    for (const glm::vec3& p : values) {
        const float y = Luminance(p);
        if (y > 0.0f && std::isfinite(y)) lum.push_back(y);
    }
    if (lum.empty()) return 0.0f;
    const size_t k = std::min(lum.size() - 1, size_t(0.99 * double(lum.size())));
    std::nth_element(lum.begin(), lum.begin() + k, lum.end());
    return lum[k];
}

}  // namespace penumbra
