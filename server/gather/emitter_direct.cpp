// Emitter direct light with shadow rays (emitter_direct.h).
#include "gather/emitter_direct.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>

#include "base/check.h"
#include "base/pcg.h"

namespace penumbra {
namespace {

// The R2 sequence (Roberts 2018): point i at frac(s + i·(1/φ₂, 1/φ₂²)), φ₂ the plastic
// number; any run of consecutive points is spread evenly over the unit square.
constexpr double kR2a = 0.7548776662466927, kR2b = 0.5698402909980532;

}  // namespace

std::vector<glm::vec3> EmitterIrradiance(const RayScene& rays, const std::vector<glm::vec3>& points,
                                         const std::vector<glm::vec3>& normals,
                                         const EmitterDirectSettings& settings) {
    if (settings.rays < 1) throw Error("emitter direct light needs at least one ray a point");
    if (points.size() != normals.size())
        throw Error("emitter direct light: " + std::to_string(points.size()) + " points and " +
                    std::to_string(normals.size()) + " normals");
    std::vector<glm::vec3> out(points.size(), glm::vec3(0.0f));
    if (rays.Emitters().empty()) return out;
    const int n = settings.rays;
    const auto& tris = rays.Triangles();
    const auto& materials = rays.GetScene().materials;
    const float eps = rays.Epsilon();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 16), [&](const auto& range) {
        for (size_t i = range.begin(); i != range.end(); ++i) {
            Pcg32 rng(settings.seed, i);
            // This point's rotation of the R2 sequence (Cranley–Patterson).
            const double sa = rng.Uniform(), sb = rng.Uniform();
            const glm::vec3 x = points[i], nx = normals[i];
            glm::vec3 sum(0.0f);
            for (int r = 0; r < n; ++r) {
                // Emitter by power, from the r-th of n strata of [0, 1): each emitter takes a
                // run of consecutive r, so its points below are consecutive R2 points.
                const float ut = (static_cast<float>(r) + rng.Uniform()) / n;
                const uint32_t ti = rays.Emitters()[rays.PickEmitter(ut)];
                const RayTriangle& t = tris[ti];
                // A point on it: the r-th R2 point, folded into the triangle.
                float a = static_cast<float>(std::fmod(sa + r * kR2a, 1.0));
                float b = static_cast<float>(std::fmod(sb + r * kR2b, 1.0));
                if (a + b > 1.0f) a = 1.0f - a, b = 1.0f - b;
                const glm::vec3 y = t.p0 + a * t.e1 + b * t.e2;
                const glm::vec3 d = y - x;
                const float dist2 = glm::dot(d, d);
                if (!(dist2 > 0.0f)) continue;
                const glm::vec3 w = d / std::sqrt(dist2);
                const float cx = glm::dot(nx, w), cy = -glm::dot(t.normal, w);
                if (cx <= 0.0f || cy <= 0.0f) continue;
                const glm::vec3 from = x + eps * nx, to = y + eps * t.normal;
                if (rays.Occluded(from, to - from)) continue;
                sum += materials[t.material].emission * (cx * cy / (dist2 * rays.AreaPdf(ti)));
            }
            out[i] = sum / static_cast<float>(n);
        }
    });
    return out;
}

}  // namespace penumbra
