// Emitter direct light with shadow rays (emitter_direct.h).
#include "gather/emitter_direct.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <limits>

#include "base/check.h"
#include "base/pcg.h"
#include "gather/sampling.h"

namespace penumbra {
namespace {

constexpr float kPi = 3.14159265358979f;

// The power heuristic (Veach 1997) for a sample drawn na times with pdf pa against nb with pb.
float Power(float na, float pa, float nb, float pb) {
    const float a = na * pa, b = nb * pb;
    return a * a / (a * a + b * b);
}

// Half the rays (none of a single one) sample the cosine-weighted hemisphere. A quarter gives
// the office 3.9 against 4.1% (its small ceiling lights favour light sampling) but the white
// furnace's worst vertex 1.4 against 0.7% (emitters all around favour cosine sampling).
int CosineRays(const EmitterDirectSettings& s) { return s.rays >= 2 ? s.rays / 2 : 0; }

}  // namespace

float EmitterHitWeight(const RayScene& rays, const EmitterDirectSettings& settings,
                       const glm::vec3& n, const glm::vec3& w, uint32_t triangle, float t) {
    const float pdfArea = rays.AreaPdf(triangle);
    if (!(pdfArea > 0.0f)) return 0.0f;
    const float cx = glm::dot(n, w), cy = -glm::dot(rays.Triangles()[triangle].normal, w);
    if (cx <= 0.0f || cy <= 0.0f) return 0.0f;
    const int own = CosineRays(settings), nl = settings.rays - own;
    const int nb = own + settings.extraCosineRays;
    return Power(nb, cx / kPi, nl, pdfArea * t * t / cy) * kPi / nb;
}

std::vector<glm::vec3> EmitterIrradiance(const RayScene& rays, const std::vector<glm::vec3>& points,
                                         const std::vector<glm::vec3>& normals,
                                         const EmitterDirectSettings& settings) {
    if (settings.rays < 1) throw Error("emitter direct light needs at least one ray a point");
    if (points.size() != normals.size())
        throw Error("emitter direct light: " + std::to_string(points.size()) + " points and " +
                    std::to_string(normals.size()) + " normals");
    std::vector<glm::vec3> out(points.size(), glm::vec3(0.0f));
    if (rays.Emitters().empty()) return out;
    const int own = CosineRays(settings), nl = settings.rays - own;
    const int nb = own + settings.extraCosineRays;
    const auto& tris = rays.Triangles();
    const auto& materials = rays.GetScene().materials;
    const float eps = rays.Epsilon();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 16), [&](const auto& range) {
        for (size_t i = range.begin(); i != range.end(); ++i) {
            Pcg32 rng(settings.seed, i);
            // This point's rotations of the R2 sequence (Cranley–Patterson): emitter points,
            // hemisphere directions.
            glm::vec2 sl, sb;
            sl.x = rng.Uniform(), sl.y = rng.Uniform();
            sb.x = rng.Uniform(), sb.y = rng.Uniform();
            const glm::vec3 x = points[i], nx = normals[i];
            const glm::vec3 from = x + eps * nx;
            glm::vec3 sum(0.0f);
            for (int r = 0; r < nl; ++r) {
                // Emitter by power, from the r-th of nl strata of [0, 1): each emitter takes a
                // run of consecutive r, so its points below are consecutive R2 points.
                const float ut = (static_cast<float>(r) + rng.Uniform()) / nl;
                const uint32_t ti = rays.Emitters()[rays.PickEmitter(ut)];
                const RayTriangle& t = tris[ti];
                // A point on it: the r-th R2 point, folded into the triangle.
                glm::vec2 ab = R2Point(sl, r);
                if (ab.x + ab.y > 1.0f) ab = glm::vec2(1.0f) - ab;
                const glm::vec3 y = t.p0 + ab.x * t.e1 + ab.y * t.e2;
                const glm::vec3 d = y - x;
                const float dist2 = glm::dot(d, d);
                if (!(dist2 > 0.0f)) continue;
                const glm::vec3 w = d / std::sqrt(dist2);
                const float cx = glm::dot(nx, w), cy = -glm::dot(t.normal, w);
                if (cx <= 0.0f || cy <= 0.0f) continue;
                const glm::vec3 to = y + eps * t.normal;
                if (rays.Occluded(from, to - from)) continue;
                const float pdfArea = rays.AreaPdf(ti);
                const float weight = Power(nl, pdfArea * dist2 / cy, nb, cx / kPi);
                sum += materials[t.material].emission * (weight * cx * cy / (dist2 * pdfArea * nl));
            }
            for (int r = 0; r < own; ++r) {
                const glm::vec3 w = CosineDirection(nx, R2Point(sb, r));
                const RayHit hit = rays.Intersect(from, w, std::numeric_limits<float>::infinity());
                if (!hit.hit || rays.AreaPdf(hit.triangle) <= 0.0f) continue;
                const RayTriangle& t = tris[hit.triangle];
                const float cx = glm::dot(nx, w), cy = -glm::dot(t.normal, w);
                if (cx <= 0.0f || cy <= 0.0f) continue;
                const float pdfLight = rays.AreaPdf(hit.triangle) * hit.t * hit.t / cy;
                const float weight = Power(nb, cx / kPi, nl, pdfLight);
                sum += materials[t.material].emission * (weight * kPi / nb);
            }
            out[i] = sum;
        }
    });
    return out;
}

}  // namespace penumbra
