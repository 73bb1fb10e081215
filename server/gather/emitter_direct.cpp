// Emitter direct light with shadow rays (emitter_direct.h).
#include "gather/emitter_direct.h"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
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
                       const glm::vec3& n, const glm::vec3& w, uint32_t triangle, float t,
                       int cosineRays) {
    const float pdfArea = rays.AreaPdf(triangle);
    if (!(pdfArea > 0.0f)) return 0.0f;
    const float cx = glm::dot(n, w), cy = -glm::dot(rays.Triangles()[triangle].normal, w);
    if (cx <= 0.0f || cy <= 0.0f) return 0.0f;
    const int nl = settings.rays - CosineRays(settings);
    const int nb = cosineRays >= 0 ? cosineRays : CosineRays(settings) + settings.extraCosineRays;
    return Power(nb, cx / kPi, nl, pdfArea * t * t / cy) * kPi / nb;
}

std::vector<glm::vec3> EmitterIrradiance(const RayScene& rays, const std::vector<glm::vec3>& points,
                                         const std::vector<glm::vec3>& normals,
                                         const EmitterDirectSettings& settings) {
    return EmitterDirect(settings).Trace(rays, points, normals);
}

EmitterDirect::EmitterDirect(const EmitterDirectSettings& settings) : settings_(settings) {
    if (settings.rays < 1) throw Error("emitter direct light needs at least one ray a point");
    cosineRays_ = CosineRays(settings);
    lightRays_ = settings.rays - cosineRays_;
    words_ = (lightRays_ + 63) / 64;
}

std::vector<glm::vec3> EmitterDirect::Trace(const RayScene& rays,
                                            const std::vector<glm::vec3>& points,
                                            const std::vector<glm::vec3>& normals,
                                            const std::vector<int>& extraCosine) {
    if (points.size() != normals.size() ||
        (!extraCosine.empty() && extraCosine.size() != points.size()))
        throw Error("emitter direct light: " + std::to_string(points.size()) + " points, " +
                    std::to_string(normals.size()) + " normals");
    extra_ = extraCosine.empty() ? std::vector<int>(points.size(), settings_.extraCosineRays)
                                 : extraCosine;
    slots_ = rays.EmitterPrimitives().size() <= kMaxSlots ? rays.EmitterPrimitives().size() : 0;
    coef_.assign(points.size() * slots_, 0.0f);
    blocked_.assign(points.size() * words_, 0);
    cosineT_.assign(points.size() * cosineRays_, std::numeric_limits<float>::infinity());
    cosineTri_.assign(points.size() * cosineRays_, ~0u);
    std::vector<glm::vec3> out(points.size(), glm::vec3(0.0f));
    if (rays.Emitters().empty()) return out;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 16), [&](const auto& range) {
        size_t traced = 0;
        for (size_t i = range.begin(); i != range.end(); ++i)
            out[i] = Shoot(rays, i, points[i], normals[i], nullptr, traced);
    });
    return out;
}

std::vector<glm::vec3> EmitterDirect::Retrace(const RayScene& rays,
                                              const std::vector<glm::vec3>& points,
                                              const std::vector<glm::vec3>& normals,
                                              const std::vector<uint8_t>& moved,
                                              const std::vector<Bounds>& boxes, size_t* traced) {
    PENUMBRA_CHECK_EQ(points.size(), extra_.size());
    PENUMBRA_CHECK_EQ(moved.size(), points.size());
    std::vector<glm::vec3> out(points.size(), glm::vec3(0.0f));
    std::atomic<size_t> total{0};
    if (!rays.Emitters().empty())
        tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 16), [&](const auto& range) {
            size_t n = 0;
            for (size_t i = range.begin(); i != range.end(); ++i)
                out[i] = Shoot(rays, i, points[i], normals[i], moved[i] ? nullptr : &boxes, n);
            total += n;
        });
    if (traced) *traced = total;
    return out;
}

bool EmitterDirect::Reevaluate(const RayScene& rays, std::vector<glm::vec3>& out) const {
    if (slots_ == 0 || rays.EmitterPrimitives().size() != slots_) return false;
    std::vector<glm::vec3> le(slots_);
    for (size_t k = 0; k < slots_; ++k) {
        const Scene& scene = rays.GetScene();
        le[k] = scene.materials[scene.primitives[rays.EmitterPrimitives()[k]].material].emission;
    }
    out.assign(extra_.size(), glm::vec3(0.0f));
    for (size_t i = 0; i < out.size(); ++i)
        for (size_t k = 0; k < slots_; ++k) out[i] += le[k] * coef_[i * slots_ + k];
    return true;
}

glm::vec3 EmitterDirect::Shoot(const RayScene& rays, size_t i, const glm::vec3& x,
                               const glm::vec3& nx, const std::vector<Bounds>* boxes,
                               size_t& traced) {
    const auto& tris = rays.Triangles();
    const float eps = rays.Epsilon();
    const int nl = lightRays_, own = cosineRays_, nb = own + extra_[i];
    // Each contribution is L_e of its triangle times a coefficient, kept per emitting
    // primitive (Reevaluate).
    float* coef = slots_ ? coef_.data() + i * slots_ : nullptr;
    if (coef) std::fill(coef, coef + slots_, 0.0f);
    glm::vec3 sum(0.0f);
    auto add = [&](uint32_t tri, float c) {
        sum += rays.MaterialOf(tri).emission * c;
        if (coef) coef[rays.EmitterSlot(tris[tri].primitive)] += c;
    };
    auto meets = [&](const glm::vec3& o, const glm::vec3& d, float tmax) {
        if (!boxes) return true;
        for (const Bounds& b : *boxes)
            if (b.Meets(o, d, tmax)) return true;
        return false;
    };
    Pcg32 rng(settings_.seed, i);
    // This point's rotations of the R2 sequence (Cranley–Patterson): emitter points,
    // hemisphere directions.
    glm::vec2 sl, sb;
    sl.x = rng.Uniform(), sl.y = rng.Uniform();
    sb.x = rng.Uniform(), sb.y = rng.Uniform();
    const glm::vec3 from = x + eps * nx;
    uint64_t* bits = blocked_.data() + i * words_;
    for (int r = 0; r < nl; ++r) {
        // Emitter by power, from the r-th of nl strata of [0, 1): each emitter takes a run of
        // consecutive r, so its points below are consecutive R2 points.
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
        const glm::vec3 span = y + eps * t.normal - from;
        const uint64_t bit = uint64_t(1) << (r % 64);
        if (meets(from, span, 1.0f)) {
            ++traced;
            if (rays.Occluded(from, span))
                bits[r / 64] |= bit;
            else
                bits[r / 64] &= ~bit;
        }
        if (bits[r / 64] & bit) continue;
        const float pdfArea = rays.AreaPdf(ti);
        const float weight = Power(nl, pdfArea * dist2 / cy, nb, cx / kPi);
        add(ti, weight * cx * cy / (dist2 * pdfArea * nl));
    }
    for (int r = 0; r < own; ++r) {
        const glm::vec3 w = CosineDirection(nx, R2Point(sb, r));
        float& dist = cosineT_[i * own + r];
        uint32_t& tri = cosineTri_[i * own + r];
        if (meets(from, w, dist)) {
            ++traced;
            const RayHit hit = rays.Intersect(from, w, std::numeric_limits<float>::infinity());
            dist = hit.hit ? hit.t : std::numeric_limits<float>::infinity();
            tri = hit.hit ? hit.triangle : ~0u;
        }
        if (tri == ~0u || !(rays.AreaPdf(tri) > 0.0f)) continue;
        add(tri, EmitterHitWeight(rays, settings_, nx, w, tri, dist, nb));
    }
    return sum;
}

}  // namespace penumbra
