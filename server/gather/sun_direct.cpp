// A map's sun at points with shadow rays (sun_direct.h).
#include "gather/sun_direct.h"

#include <tbb/parallel_for.h>

#include <atomic>

#include "base/check.h"
#include "base/pcg.h"
#include "rays/sampling.h"

namespace penumbra {
namespace {

constexpr uint64_t kSunStream = 0xbb67ae8584caa73bull;  // apart from the gather's streams

}  // namespace

SunDirect::SunDirect(int rays, uint64_t seed) : rays_(rays), words_((rays + 63) / 64), seed_(seed) {
    if (rays < 1) throw Error("the sun's direct light needs at least one ray a point");
}

glm::vec3 SunDirect::Direction(const SkyParts& sky, size_t i, int k, float& pdf) const {
    Pcg32 rng(seed_, kSunStream + i);
    glm::vec2 rotation;
    rotation.x = rng.Uniform(), rotation.y = rng.Uniform();
    return sky.sampler.Sample(R2Point(rotation, k), pdf);
}

glm::vec3 SunDirect::Sum(const SkyParts& sky, size_t i, const glm::vec3& n) const {
    glm::vec3 e(0.0f);
    const uint64_t* bits = &seen_[i * words_];
    for (int k = 0; k < rays_; ++k) {
        if (!(bits[k / 64] >> (k % 64) & 1u)) continue;
        float pdf;
        const glm::vec3 w = Direction(sky, i, k, pdf);
        glm::vec3 through(1.0f);
        if (!passed_.empty())
            for (const auto& [ray, t] : passed_[i])
                if (ray == k) through = t;
        e += through * sky.sun.Radiance(w) * (glm::dot(n, w) / pdf);
    }
    return e / float(rays_);
}

std::vector<glm::vec3> SunDirect::Trace(const RayScene& rays, const SkyParts& sky,
                                        const std::vector<glm::vec3>& points,
                                        const std::vector<glm::vec3>& normals, float reach) {
    return Retrace(rays, sky, points, normals, reach, std::vector<uint8_t>(points.size(), 1), {});
}

std::vector<glm::vec3> SunDirect::Retrace(const RayScene& rays, const SkyParts& sky,
                                          const std::vector<glm::vec3>& points,
                                          const std::vector<glm::vec3>& normals, float reach,
                                          const std::vector<uint8_t>& moved,
                                          const std::vector<Bounds>& boxes, size_t* traced) {
    PENUMBRA_CHECK_EQ(points.size(), normals.size());
    PENUMBRA_CHECK_EQ(points.size(), moved.size());
    if (seen_.size() != points.size() * words_) seen_.assign(points.size() * words_, 0);
    PENUMBRA_CHECK_LE(rays_, 65536);
    if (!rays.Passing())
        passed_.clear();
    else if (passed_.size() != points.size())
        passed_.assign(points.size(), {});
    std::vector<glm::vec3> e(points.size(), glm::vec3(0.0f));
    if (!sky.Split()) {
        std::fill(seen_.begin(), seen_.end(), 0);
        return e;
    }
    std::atomic<size_t> count{0};
    const float lift = rays.Epsilon();
    tbb::parallel_for(tbb::blocked_range<size_t>(0, points.size(), 64), [&](const auto& range) {
        size_t mine = 0;
        for (size_t i = range.begin(); i != range.end(); ++i) {
            const glm::vec3& n = normals[i];
            const glm::vec3 from = points[i] + lift * n;
            uint64_t* bits = &seen_[i * words_];
            for (int k = 0; k < rays_; ++k) {
                float pdf;
                const glm::vec3 w = Direction(sky, i, k, pdf);
                const glm::vec3 span = w * reach;
                const uint64_t bit = uint64_t{1} << (k % 64);
                if (!moved[i]) {
                    bool meets = false;
                    for (const Bounds& b : boxes) meets = meets || b.Meets(from, span, 1.0f);
                    if (!meets) continue;  // its bit holds
                }
                bits[k / 64] &= ~bit;
                if (!passed_.empty())
                    std::erase_if(passed_[i], [k](const auto& p) { return p.first == k; });
                if (!(pdf > 0.0f) || glm::dot(n, w) <= 0.0f) continue;
                ++mine;
                if (passed_.empty()) {
                    if (!rays.Occluded(from, span)) bits[k / 64] |= bit;
                    continue;
                }
                const glm::vec3 through = rays.Transmittance(from, span);
                if (through == glm::vec3(0.0f)) continue;
                bits[k / 64] |= bit;
                if (through != glm::vec3(1.0f)) passed_[i].emplace_back(uint16_t(k), through);
            }
            e[i] = Sum(sky, i, n);
        }
        count += mine;
    });
    if (traced) *traced = count.load();
    return e;
}

std::vector<glm::vec3> SunDirect::Reevaluate(const SkyParts& sky,
                                             const std::vector<glm::vec3>& normals) const {
    std::vector<glm::vec3> e(normals.size(), glm::vec3(0.0f));
    if (!sky.Split() || seen_.size() != normals.size() * words_) return e;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, normals.size(), 256), [&](const auto& range) {
        for (size_t i = range.begin(); i != range.end(); ++i) e[i] = Sum(sky, i, normals[i]);
    });
    return e;
}

}  // namespace penumbra
