// `penumbra render`: the scene as a picture, rasterised headless with Vulkan. Each vertex is
// shaded on the host from the lighting (outgoing radiance L = ρ·E/π + L_e of a diffuse
// surface, or a heat-map colour for an error) and the raster interpolates it; the result is
// a linear float image, written as EXR, and tone-mapped to 8-bit sRGB for PNG.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <string>
#include <vector>

#include "base/image.h"
#include "output/irradiance_writer.h"
#include "scene/scene.h"
#include "scene/surfels.h"

namespace penumbra::render {

// Triangles with a colour and a normal per vertex, in world space.
struct Mesh {
    std::vector<glm::vec3> positions, normals, colors;
    std::vector<uint32_t> indices;
};

// Outgoing radiance of a diffuse surface, ρ·E/π + L_e, at every input vertex of every
// primitive, from per-primitive irradiance in the scene's primitive order.
Mesh ShadedInputMesh(const Scene& scene, const std::vector<std::vector<glm::vec3>>& irradiance);
// The same on the refined mesh (surfels and their triangles), from per-surfel irradiance:
// the solver's own resolution.
Mesh ShadedRefinedMesh(const Scene& scene, const Surfels& surfels,
                       const std::vector<glm::vec3>& irradiance);
// Per-primitive irradiance of `file` in the scene's primitive order (matched by node, mesh
// and primitive; vertex counts must agree). Throws penumbra::Error naming the mismatch.
std::vector<std::vector<glm::vec3>> IrradianceForScene(const Scene& scene,
                                                       const IrradianceFile& file);

// A heat map of |a − b| / max(|b|, floor · mean |b|) per vertex (the `compare` measure):
// 0 dark blue, `scale` and above red. `a` and `b` are per-primitive irradiance.
Mesh ErrorMesh(const Scene& scene, const std::vector<std::vector<glm::vec3>>& a,
               const std::vector<std::vector<glm::vec3>>& b, float scale, float floorFraction);
glm::vec3 HeatColor(float t);  // t in [0, 1]: blue → cyan → green → yellow → red

// A camera that sees the whole scene: from the −Z side of its bounding box, looking down +Z
// at its centre (the open side of a Cornell box), far enough for the bounding sphere to fit.
Camera FrameScene(const Scene& scene, float yfov = 0.6981317f /* 40° */);
// "ex,ey,ez,tx,ty,tz,fov" (metres, degrees): eye, target and vertical field of view.
// Throws penumbra::Error for anything else.
Camera ParseCamera(const std::string& text);

struct RenderSettings {
    int width = 800;
    int height = 600;
    bool lavapipe = false;  // the CPU Vulkan device even where a GPU exists
    bool validation = false;
};
struct RenderOutput {
    Image image;  // linear radiance, row 0 at the top
    std::string device;
    double ms = 0.0;  // upload, raster and readback
    std::vector<std::string> validationMessages;
};

// Rasterises `mesh` from `camera` (depth-tested; the back of a surface is black). Throws
// penumbra::Error when no Vulkan device can render.
RenderOutput Rasterize(const Mesh& mesh, const Camera& camera, const RenderSettings& settings);

// 8-bit sRGB for PNG: radiance × 2^exposure × auto, where auto maps the 99th percentile of
// the lit pixels' luminance to 1 (when `autoExposure`), clamped, then the sRGB curve.
std::vector<uint8_t> ToneMap(const Image& image, float exposure, bool autoExposure);

}  // namespace penumbra::render
