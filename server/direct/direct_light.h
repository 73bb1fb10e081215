// Direct light of punctual lights (Sec. 3.3, "Direct light initialization"): shadow maps
// of the scene from every light, then the shadowed direct irradiance E_d at every surfel.
// E_d initialises the incident light of the local pass and makes no antiradiance: the
// shadow map has already done the occlusion. Shared by every solver (docs/ARCHITECTURE.md).
//
// Shadow maps are float NDC depth per texel (Vulkan conventions: z in [0, 1], texel
// (x, y) = ((ndc + 1) / 2) · size). Point lights (and spots wider than 60°) get six cube
// faces, spots a perspective view, directional lights an orthographic view of the scene's
// bounding sphere. The CPU twin rasterises the same maps in software; the Vulkan back end
// (vulkan_direct.h) renders them with the raster pipeline.
//
// Filtering: the visibility of a surfel is the average over 16 taps spread over its own
// footprint (a disc of radius ½√area around its centroid, in its tangent plane), each a
// bilinear 2×2 depth comparison. A shadow edge thus falls off over one element, as the
// element's own irradiance would, instead of aliasing on the element grid.
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "gpu/layout.h"
#include "rays/ray_scene.h"
#include "scene/scene.h"
#include "scene/surfels.h"

namespace penumbra::direct {

inline constexpr int kDefaultMapSize = 1024;

// A map size for elements of `elementSize` in a scene of `diameter`: texels of a quarter
// element across an orthographic map of the whole scene (and finer on cube faces nearer
// than half the diameter), as a power of two in 256…2048. The 16-tap footprint filter
// averages over the element anyway; finer maps only cost time.
int AutoMapSize(float diameter, float elementSize);
// The map size a solver uses: `given` (SolverSettings::shadowMapSize) when positive, else
// AutoMapSize.
inline int MapSize(int given, float diameter, float elementSize) {
    return given > 0 ? given : AutoMapSize(diameter, elementSize);
}
inline constexpr int kTaps = 16;
// Spots with a wider outer cone than this get a cube map like a point light.
inline constexpr float kMaxSpotViewCone = 1.0471976f;  // 60°

// Layouts shared with shaders/direct.glsl.
struct GpuLight {
    glm::vec4 position;   // xyz; w = type (0 point, 1 spot, 2 directional)
    glm::vec4 direction;  // xyz (where the light travels); w = range (0: none)
    glm::vec4 radiant;    // colour × intensity (cd or lux); w unused
    glm::vec4 cone;       // x = cos outer, y = 1 / (cos inner − cos outer), z = first view,
                          // w = view count (1 or 6)
    // Cube lights (6 views): every face's projection, so a tap projects into its face
    // without loading the face's view: x = f / (f − n), y = n f / (f − n) (NDC depth =
    // x − y / depth), z = 1 / tan(half field of view), w = texel size per metre of depth.
    glm::vec4 cube;
};
struct GpuShadowView {
    glm::mat4 viewProj;
    glm::vec4 eye;      // xyz: light position (perspective) or a point behind the scene
    glm::vec4 forward;  // xyz: view axis; w = texel world size per metre of depth
                        // (perspective) or per texel (orthographic, then eye.w = 1)
};
struct GpuReceiver {
    glm::vec4 position;  // xyz; w = footprint radius
    glm::vec4 normal;    // xyz unit
    glm::vec4 centroid;  // xyz; centre of the footprint
};
static_assert(sizeof(GpuLight) == 80 && sizeof(GpuShadowView) == 96 && sizeof(GpuReceiver) == 48);
PENUMBRA_GPU_FIELD(GpuLight, position, 0);
PENUMBRA_GPU_FIELD(GpuLight, direction, 16);
PENUMBRA_GPU_FIELD(GpuLight, radiant, 32);
PENUMBRA_GPU_FIELD(GpuLight, cone, 48);
PENUMBRA_GPU_FIELD(GpuLight, cube, 64);
PENUMBRA_GPU_FIELD(GpuShadowView, viewProj, 0);
PENUMBRA_GPU_FIELD(GpuShadowView, eye, 64);
PENUMBRA_GPU_FIELD(GpuShadowView, forward, 80);
PENUMBRA_GPU_FIELD(GpuReceiver, position, 0);
PENUMBRA_GPU_FIELD(GpuReceiver, normal, 16);
PENUMBRA_GPU_FIELD(GpuReceiver, centroid, 32);

// A cube light's face `face` (0…5: +x, −x, +y, −y, +z, −z) projects world point q to
// NDC as that face's view matrix does, from the light's `cube` parameters (direct.comp
// has the same lines). False when q is not in front of the face.
bool CubeNdc(const GpuLight& light, int face, const glm::vec3& q, glm::vec3& ndc);

// The views to render for the scene's lights, and the lights as the shaders read them.
struct Plan {
    int mapSize = kDefaultMapSize;
    std::vector<GpuLight> lights;
    std::vector<GpuShadowView> views;

    size_t MapTexels() const { return views.size() * size_t(mapSize) * mapSize; }
};
Plan PlanShadows(const Scene& scene, int mapSize = kDefaultMapSize);

// The scene's triangles in world space, three vertices each: the shadow casters.
std::vector<glm::vec3> SceneTriangles(const Scene& scene);

// The triangles (three entries of `triangles` each) that may cover a texel of `viewProj`'s
// map, as the indices of their vertices: those with all three vertices beyond one plane of
// the clip volume (−w ≤ x, y ≤ w, 0 ≤ z ≤ w) are left out. A cube face sees about a sixth
// of a room; the shadow pass draws only these.
void ViewTriangles(const glm::mat4& viewProj, const std::vector<glm::vec3>& triangles,
                   std::vector<uint32_t>& indices);

// Receivers for `order` (surfel indices, e.g. hierarchy leaves), footprints from surfel areas:
// a disc of radius ½√area about the centroid, no wider than the surfel's own surface allows
// (its distance to the boundary edges of the refined triangles around it), so that no tap
// lies beyond where the surface ends (a wall's top under a roof, a floor at a wall).
std::vector<GpuReceiver> MakeReceivers(const Surfels& surfels, const std::vector<uint32_t>& order);

// CPU twin of the shadow pass: `maps` gets plan.MapTexels() depths (1 where nothing is).
void RasterShadowMaps(const Plan& plan, const std::vector<glm::vec3>& triangles,
                      std::vector<float>& maps);

// CPU twin of the direct pass: RGB irradiance (lux) per receiver, stride 4 (xyz + 0), and,
// when `perLight` is given, each light's share: perLight[(light · receivers + i) · 4 + c].
void DirectIrradiance(const Plan& plan, const float* maps,
                      const std::vector<GpuReceiver>& receivers, float* out,
                      float* perLight = nullptr);

// The direct pass with shadow rays instead of maps (the CPU back end's stage): each tap of
// the footprint, lifted off its surface by a tenth of the footprint's radius (a curved
// surface leaves its tangent plane by less), sends a ray to the light through `rays` (the
// scene's triangles): exact visibility, so that no surface lets light through where two
// meet or where it is thinner than a map's texel. The same outputs as DirectIrradiance.
void DirectIrradianceByRays(const Plan& plan, const RayScene& rays,
                            const std::vector<GpuReceiver>& receivers, float* out,
                            float* perLight = nullptr);

}  // namespace penumbra::direct
