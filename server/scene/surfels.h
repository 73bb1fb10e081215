// Surface samples: every triangle is refined until no edge exceeds the element size;
// the refined mesh's vertices are the surfels (docs/SOLVER.md).
#pragma once

#include <cstdint>
#include <glm/glm.hpp>
#include <vector>

#include "scene/scene.h"

namespace penumbra {

struct Surfels {
    std::vector<glm::vec3> positions;
    std::vector<glm::vec3> normals;  // unit
    std::vector<float> areas;        // one third of the adjacent refined triangles' area
    // Centroid of the surfel's hat function (its share of the adjacent triangles). Equal to
    // the position inside a surface; moved into the surface for vertices on its boundary,
    // where the position itself sees neighbouring surfaces only at grazing angles.
    std::vector<glm::vec3> centroids;
    std::vector<uint32_t> materials;
    // Per surfel (empty: the scene has no colour maps): its material's maps averaged over its
    // hat function (Tints): its albedo is the material's times albedoTints[i], its emission
    // the material's times emissionTints[i]. Fixed by the texture coordinates, so a move
    // keeps them.
    std::vector<glm::vec3> albedoTints, emissionTints;
    // Primitive p's input vertex i is surfel firstSurfel[p] + i (input vertices come first).
    std::vector<uint32_t> firstSurfel;
    std::vector<uint32_t> refinedTriangles;  // triangle list over surfel indices
    // Per surfel (empty: none): the surface occludes light arriving at either side, not only
    // at its front. Set for surfaces that do not close a solid (a wall of one-sided quads),
    // whose back can be reached by light, e.g. the sky (solvers/antiradiance/model.h).
    std::vector<uint8_t> twoSided;
    // Per surfel (empty: all static): its rigid motion group, 0 for static geometry, g > 0
    // for the surfaces of one dynamic node that move together (Sec. 3.3; the antiradiance
    // model's MotionGroup g − 1). The hierarchy keeps groups in subtrees of their own.
    std::vector<uint32_t> groups;
    // Per surfel (empty: no dynamic node): the centroid and normal in the own (mesh) space of
    // a dynamic node's primitive, computed from its own-space vertices only, so they are
    // bitwise the same at every pose (the hierarchy clusters moving groups by them).
    std::vector<glm::vec3> ownCentroids, ownNormals;

    size_t size() const { return positions.size(); }
    // Surfel i's diffuse albedo and emission under material m (its own or one it may get).
    glm::vec3 Albedo(const Material& m, size_t i) const {
        return albedoTints.empty() ? m.albedo : m.albedo * albedoTints[i];
    }
    glm::vec3 Emission(const Material& m, size_t i) const {
        return emissionTints.empty() ? m.emission : m.emission * emissionTints[i];
    }
    // Primitive p's surfels are [firstSurfel[p], End(p)).
    size_t End(size_t p) const { return p + 1 < firstSurfel.size() ? firstSurfel[p + 1] : size(); }
};

// Whether surfaces that do not close a solid occlude light arriving at their backs
// (Surfels::twoSided). `auto`: on when the scene has an environment, whose light reaches
// every back side; without one, light reaches a back only from inside the scene, which the
// antiradiance paper's front-side rule (Fig. 7) ignores at the cost of leaks through thin
// walls.
enum class BackOcclusion { kAuto, kOn, kOff };
// The rule of `choice` under the scene's sky: decided when the surfels are made, so a sky
// appearing or going under `auto` needs new surfels (BackOcclusionChanges).
bool BackOcclusionOn(BackOcclusion choice, const Environment& sky);
bool BackOcclusionChanges(BackOcclusion choice, const Environment& before,
                          const Environment& after);
// Marks the surfels of nodes that do not close a solid (ClosedNodes) as two-sided.
void MarkTwoSided(const Scene& scene, Surfels& surfels);

// Refines by longest-edge bisection until every edge is at most `elementSize`.
// Midpoints of shared edges are shared within a primitive, so its surface stays connected.
Surfels RefineScene(const Scene& scene, float elementSize);

}  // namespace penumbra
