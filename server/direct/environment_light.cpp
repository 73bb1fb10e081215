// Bin averages of the environment map.
#include "direct/environment_light.h"

#include <tbb/combinable.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <numbers>

namespace penumbra::direct {

std::vector<glm::vec3> EnvironmentBins(const Environment& env, const Directions& dirs) {
    const int bins = dirs.Count();
    std::vector<glm::vec3> row(bins, glm::vec3(0.0f));
    if (!env.Active()) return row;
    const bool perPixel = env.image && env.image->height >= kEnvironmentGrid;
    const int h = perPixel ? env.image->height : kEnvironmentGrid;
    const int w = perPixel ? env.image->width : 2 * kEnvironmentGrid;
    struct Sums {
        std::vector<glm::dvec3> radiance;
        std::vector<double> solidAngle;
    };
    tbb::combinable<Sums> sums([&] {
        return Sums{std::vector<glm::dvec3>(bins, glm::dvec3(0.0)), std::vector<double>(bins, 0.0)};
    });
    const double pi = std::numbers::pi;
    tbb::parallel_for(0, h, [&](int y) {
        Sums& s = sums.local();
        const float v = (y + 0.5f) / h;
        // Solid angle of one grid cell of this row: Δφ · (cos θ₀ − cos θ₁).
        const double dOmega = (2.0 * pi / w) * (std::cos(pi * y / h) - std::cos(pi * (y + 1) / h));
        for (int x = 0; x < w; ++x) {
            const float u = (x + 0.5f) / w;
            glm::vec3 mapDir = EquirectDirection(u, v);
            // World direction towards the sky: the map turned by `rotation` about +Y.
            float c = std::cos(env.rotation), sn = std::sin(env.rotation);
            glm::vec3 sky(c * mapDir.x + sn * mapDir.z, mapDir.y, -sn * mapDir.x + c * mapDir.z);
            glm::vec3 radiance = perPixel ? env.intensity * env.image->At(x, y) : env.Radiance(sky);
            uint32_t b = dirs.Lookup(-sky);  // the light travels away from the sky
            s.radiance[b] += dOmega * glm::dvec3(radiance);
            s.solidAngle[b] += dOmega;
        }
    });
    Sums total{std::vector<glm::dvec3>(bins, glm::dvec3(0.0)), std::vector<double>(bins, 0.0)};
    sums.combine_each([&](const Sums& s) {
        for (int b = 0; b < bins; ++b) {
            total.radiance[b] += s.radiance[b];
            total.solidAngle[b] += s.solidAngle[b];
        }
    });
    for (int b = 0; b < bins; ++b) {
        if (total.solidAngle[b] > 0.0)
            row[b] = glm::vec3(total.radiance[b] / total.solidAngle[b]);
        else  // a cell no grid point fell into: its centre's radiance
            row[b] = env.Radiance(-dirs.Direction(b));
    }
    return row;
}

}  // namespace penumbra::direct
