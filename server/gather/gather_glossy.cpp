// The gather stage through glossy lobes: lobe rays from glossy hits, glints, and the
// punctual lights they see, combined by multiple importance sampling; and the punctual lights
// the short hits see (gather_stage.h).
#include <tbb/parallel_for.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstring>
#include <limits>

#include "base/check.h"
#include "base/image.h"
#include "base/pcg.h"
#include "gather/gather_detail.h"
#include "gather/gather_stage.h"
#include "rays/sampling.h"

namespace penumbra {

using namespace gather_detail;

glm::vec3 GatherStage::LobeDirection(size_t target, int ray, const Hit& h, float& cosine) const {
    const uint32_t tri = h.triangle & kIndex;
    const glm::vec3& n = rays_->Triangles()[tri].normal;
    const float exponent = rays_->MaterialOf(tri).phongExponent;
    // The lobe's axis: the mirror image of the direction back along the ray (wo = −d).
    const glm::vec3 wo = -Direction(target, ray);
    const glm::vec3 mirror = 2.0f * glm::dot(n, wo) * n - wo;
    // Phong lobe sampling, pdf (n + 1)/(2π) cosⁿθ_r.
    Pcg32 rng(settings_.seed, kLobeStream + target * settings_.gatherRays + ray);
    const float u1 = rng.Uniform(), u2 = rng.Uniform();
    const float c = std::pow(u1, 1.0f / (exponent + 1.0f));
    const float r = std::sqrt(std::max(0.0f, 1.0f - c * c)), phi = 2.0f * kPi * u2;
    glm::vec3 t, b;
    Basis(mirror, t, b);
    const glm::vec3 wi = glm::normalize(r * std::cos(phi) * t + r * std::sin(phi) * b + c * mirror);
    cosine = glm::dot(n, wi);
    return wi;
}

void GatherStage::TraceLobes(const Moved* moved) {
    if (!glossy_) {
        lobes_.assign(targets_.size(), {});
        seen_.assign(targets_.size(), {});
        return;
    }
    auto start = std::chrono::steady_clock::now();
    const int n = settings_.gatherRays, words = LightWords();
    const auto& tris = rays_->Triangles();
    const float inf = std::numeric_limits<float>::infinity();
    lobes_.resize(targets_.size());
    seen_.resize(targets_.size());
    std::atomic<size_t> traced{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        size_t count = 0;
        std::vector<LobeHit> lobes;
        std::vector<uint32_t> seen;
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const std::vector<LobeHit>& old = lobes_[t];
            const std::vector<uint32_t>& oldSeen = seen_[t];
            lobes.clear(), seen.clear();
            size_t k = 0;  // the first old entry at or after ray r
            for (int r = 0; r < n; ++r) {
                const Hit& h = hits_[t * n + r];
                while (k < old.size() && old[k].ray < r) ++k;
                if (!Front(h) || !rays_->MaterialOf(h.triangle & kIndex).Glossy()) continue;
                const uint32_t tri = h.triangle & kIndex;
                const glm::vec3 y = HitPoint(h) + rays_->Epsilon() * tris[tri].normal;
                const bool reuse = moved && k < old.size() && old[k].ray == r &&
                                   Same(old[k].from, h) && !moved->Touches(*rays_, tri);
                LobeHit e =
                    reuse ? old[k]
                          : LobeHit{
                                static_cast<uint16_t>(r), h, {kNone, 0, 0}, 0.0f, glm::vec3(0.0f)};
                // The lobe ray: kept where it passes by what moved.
                bool again = !reuse;
                if (reuse && e.hit.triangle == kEscaped) {
                    float c;
                    again = moved->Meets(y, LobeDirection(t, r, h, c), inf);
                } else if (reuse && e.hit.triangle != kNone) {
                    again = moved->Touches(*rays_, e.hit.triangle & kIndex) ||
                            moved->Meets(y, HitPoint(e.hit) - y, 1.0f);
                }
                if (again) {
                    float cosine = 0.0f;
                    const glm::vec3 wi = LobeDirection(t, r, h, cosine);
                    e.hit = {kNone, 0, 0};
                    e.weight = 0.0f;
                    e.sky = glm::vec3(0.0f);
                    if (cosine > 0.0f) {
                        const float exponent = rays_->MaterialOf(tri).phongExponent;
                        e.weight = (exponent + 2.0f) / (exponent + 1.0f) * cosine;
                        e.hit = Cast(y, wi);
                        ++count;
                        if (e.hit.triangle == kEscaped && scene_.environment.Active())
                            e.sky = scene_.environment.Radiance(wi);
                    }
                }
                // The punctual lights it sees: kept where their segments pass by what moved.
                const size_t at = seen.size();
                seen.resize(at + words, 0u);
                // (Pointers, not &v[i]: with no punctual light a lobe hit has no words, and
                // v[size()] is undefined.)
                count += See(y, tris[tri].normal, seen.data() + at,
                             reuse ? oldSeen.data() + k * words : nullptr, moved);
                lobes.push_back(e);
            }
            lobes_[t].assign(lobes.begin(), lobes.end());
            seen_[t].assign(seen.begin(), seen.end());
        }
        traced += count;
    });
    raysRetraced_ += moved ? traced.load() : 0;
    fresh_ = false;
    lightsFresh_ = false;
    pointDirect_.clear();
    msTrace_ += MsSince(start);
}

void GatherStage::PlaceGlints() {
    glossyTriangles_.clear();
    glossyCdf_.clear();
    const auto& tris = rays_->Triangles();
    glintDensity_.assign(tris.size(), 0.0f);
    if (!glossy_ || scene_.lights.empty()) return;
    double total = 0.0;
    for (uint32_t i = 0; i < tris.size(); ++i) {
        const Material& m = rays_->MaterialOf(i);
        if (!m.Glossy()) continue;
        const double w = double(tris[i].area) * Luminance(m.specular);
        if (!(w > 0.0)) continue;
        total += w;
        glossyTriangles_.push_back(i);
        glossyCdf_.push_back(total);
    }
    // Area density of a glint at a point of triangle i: (w_i / total) / area_i.
    for (uint32_t i : glossyTriangles_)
        glintDensity_[i] = static_cast<float>(Luminance(rays_->MaterialOf(i).specular) / total);
}

float GatherStage::GlintDensity(uint32_t tri) const {
    return tri < glintDensity_.size() ? glintDensity_[tri] : 0.0f;
}

void GatherStage::TraceGlints(const Moved* moved) {
    if (glossyTriangles_.empty() || targets_.empty()) {
        glints_.assign(targets_.size(), {});
        glintSeen_.assign(targets_.size(), {});
        return;
    }
    auto start = std::chrono::steady_clock::now();
    const int count = GlintCount(), words = LightWords();
    const auto& tris = rays_->Triangles();
    const Surfels& surfels = inner_->GetSurfels();
    glints_.resize(targets_.size());
    glintSeen_.resize(targets_.size());
    std::atomic<size_t> traced{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        size_t rays = 0;
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const uint32_t i = targets_[t];
            const glm::vec3 x = points_[i] + rays_->Epsilon() * surfels.normals[i];
            std::vector<Glint>& glints = glints_[t];
            std::vector<uint32_t>& seen = glintSeen_[t];
            const bool all = !moved || moved->surfels[i] || glints.size() != size_t(count);
            if (all) {
                // Stratified over the cumulative weights, uniform on each triangle.
                glints.resize(count);
                Pcg32 rng(settings_.seed, kGlintStream + t);
                for (int k = 0; k < count; ++k) {
                    const double pick = (k + rng.Uniform()) / count * glossyCdf_.back();
                    const size_t j = std::min<size_t>(
                        std::upper_bound(glossyCdf_.begin(), glossyCdf_.end(), pick) -
                            glossyCdf_.begin(),
                        glossyCdf_.size() - 1);
                    const float r1 = std::sqrt(rng.Uniform()), r2 = rng.Uniform();
                    glints[k] = {glossyTriangles_[j], Quantise(r1 * (1.0f - r2)), Quantise(r1 * r2),
                                 0u};
                }
                seen.assign(size_t(count) * words, 0u);
            }
            for (int k = 0; k < count; ++k) {
                Glint& g = glints[k];
                const RayTriangle& tri = tris[g.triangle];
                const glm::vec3 y =
                    HitPoint(Hit{g.triangle, g.u, g.v}) + rays_->Epsilon() * tri.normal;
                const bool moves = !all && moved->Touches(*rays_, g.triangle);
                // Whether the target sees the glint's front.
                if (all || moves || moved->Meets(x, y - x, 1.0f)) {
                    const glm::vec3 d = y - x;
                    g.seen = glm::dot(surfels.normals[i], d) > 0.0f &&
                             glm::dot(tri.normal, d) < 0.0f && !rays_->Occluded(x, d);
                    ++rays;
                }
                uint32_t* bits = seen.data() + k * words;
                rays += See(y, tri.normal, bits, all || moves ? nullptr : bits, moved);
            }
        }
        traced += rays;
    });
    raysRetraced_ += moved ? traced.load() : 0;
    fresh_ = false;
    lightsFresh_ = false;
    pointDirect_.clear();
    msTrace_ += MsSince(start);
}

size_t GatherStage::See(const glm::vec3& y, const glm::vec3& n, uint32_t* bits, const uint32_t* old,
                        const Moved* moved, const std::vector<uint8_t>* which) const {
    size_t rays = 0;
    for (size_t l = 0; l < scene_.lights.size(); ++l) {
        const uint32_t bit = 1u << (l % 32);
        uint32_t& word = bits[l / 32];
        const LightArrival a = PunctualArrival(scene_.lights[l], y, n, diameter_);
        const bool again =
            !old || (which && (*which)[l]) || (moved && a.reaches && moved->Meets(y, a.span, 1.0f));
        if (!again) {
            word = (word & ~bit) | (old[l / 32] & bit);
            continue;
        }
        word &= ~bit;
        if (!a.reaches) continue;
        ++rays;
        if (!rays_->Occluded(y, a.span)) word |= bit;
    }
    return rays;
}

size_t GatherStage::SeeShort(const Moved* moved, const std::vector<uint8_t>& touched) {
    const int words = LightWords();
    shortSeen_.resize(targets_.size());
    std::atomic<size_t> traced{0};
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        size_t rays = 0;
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const size_t count = secondStart_[t + 1] - secondStart_[t];
            const bool all = !moved || touched[t] || shortSeen_[t].size() != count * words;
            rays += SeeShortOf(t, all, moved, nullptr);
        }
        traced += rays;
    });
    return traced.load();
}

size_t GatherStage::SeeShortOf(size_t t, bool fresh, const Moved* moved,
                               const std::vector<uint8_t>* which) {
    const int n = settings_.gatherRays, words = LightWords();
    std::vector<uint32_t>& seen = shortSeen_[t];
    if (fresh) seen.assign((secondStart_[t + 1] - secondStart_[t]) * words, 0u);
    size_t rays = 0, k = 0;
    for (int r = 0; r < n && words > 0; ++r) {
        const Hit& h = hits_[t * n + r];
        if (!Front(h) || !(h.triangle & kShort)) continue;
        const glm::vec3& ny = rays_->Triangles()[h.triangle & kIndex].normal;
        uint32_t* bits = seen.data() + k++ * words;
        rays += See(HitPoint(h) + rays_->Epsilon() * ny, ny, bits, fresh ? nullptr : bits, moved,
                    which);
    }
    return rays;
}

glm::vec3 GatherStage::ShortDirect(size_t t, size_t k, const Hit& h) const {
    const int words = LightWords();
    glm::vec3 e(0.0f);
    if (words == 0) return e;
    const uint32_t* bits = shortSeen_[t].data() + k * words;
    const glm::vec3& ny = rays_->Triangles()[h.triangle & kIndex].normal;
    const glm::vec3 y = HitPoint(h);
    for (size_t l = 0; l < scene_.lights.size(); ++l) {
        if (!(bits[l / 32] & (1u << (l % 32)))) continue;
        const LightArrival a = PunctualArrival(scene_.lights[l], y, ny, diameter_);
        if (a.reaches) e += a.irradiance;
    }
    return e;
}

void GatherStage::SeeLights(const std::vector<uint8_t>& which) {
    if (targets_.empty()) return;
    const int n = settings_.gatherRays, words = LightWords();
    const auto& tris = rays_->Triangles();
    // Every light when `which` is empty (their count changed: the words are laid out anew).
    const std::vector<uint8_t>* marked = which.empty() ? nullptr : &which;
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 16), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            SeeShortOf(t, !marked, nullptr, marked);  // the short hits' view
            if (!glossy_) continue;
            std::vector<uint32_t>& seen = seen_[t];
            if (!marked) seen.assign(lobes_[t].size() * words, 0u);
            for (size_t k = 0; k < lobes_[t].size(); ++k) {
                const Hit& h = hits_[t * n + lobes_[t][k].ray];
                const glm::vec3& ny = tris[h.triangle & kIndex].normal;
                uint32_t* bits = seen.data() + k * words;
                See(HitPoint(h) + rays_->Epsilon() * ny, ny, bits, marked ? bits : nullptr, nullptr,
                    marked);
            }
            if (t >= glints_.size()) continue;
            std::vector<uint32_t>& glintSeen = glintSeen_[t];
            if (!marked) glintSeen.assign(glints_[t].size() * words, 0u);
            for (size_t k = 0; k < glints_[t].size(); ++k) {
                const Glint& g = glints_[t][k];
                const glm::vec3& ny = tris[g.triangle].normal;
                uint32_t* bits = glintSeen.data() + k * words;
                See(HitPoint(Hit{g.triangle, g.u, g.v}) + rays_->Epsilon() * ny, ny, bits,
                    marked ? bits : nullptr, nullptr, marked);
            }
        }
    });
    fresh_ = false;
    lightsFresh_ = false;
    pointDirect_.clear();
}

void GatherStage::Relit(const std::vector<PunctualLight>& before) {
    // The punctual lights that moved or turned: the lobe hits' view of them is traced again
    // (every light when their count changed). Colour, intensity, cone and range are re-read.
    const std::vector<PunctualLight>& now = scene_.lights;
    std::vector<uint8_t> placed(now.size(), 0);
    bool any = now.size() != before.size();
    for (size_t l = 0; l < now.size() && l < before.size(); ++l) {
        placed[l] = now[l].type != before[l].type || now[l].position != before[l].position ||
                    now[l].direction != before[l].direction;
        any = any || placed[l];
    }
    if (any) SeeLights(now.size() != before.size() ? std::vector<uint8_t>() : placed);
    if (now.empty() != before.empty() && !targets_.empty()) {  // glints wanted, or not
        PlaceGlints();
        TraceGlints();
    }
}

glm::vec3 GatherStage::LobeLight(size_t entry, uint32_t tri, const glm::vec3& wo,
                                 const glm::vec3& y, const std::vector<uint32_t>& seen) const {
    const glm::vec3& ny = rays_->Triangles()[tri].normal;
    const Material& mat = rays_->MaterialOf(tri);
    const glm::vec3 mirror = 2.0f * glm::dot(ny, wo) * ny - wo;
    const float norm = (mat.phongExponent + 2.0f) / (2.0f * kPi);
    const int words = LightWords();
    glm::vec3 sum(0.0f);
    for (size_t l = 0; l < scene_.lights.size(); ++l) {
        if (!(seen[entry * words + l / 32] & (1u << (l % 32)))) continue;
        const LightArrival a = PunctualArrival(scene_.lights[l], y, ny, diameter_);
        const float c = glm::dot(mirror, a.toLight);
        if (a.reaches && c > 0.0f) sum += a.irradiance * (norm * std::pow(c, mat.phongExponent));
    }
    return sum;
}

void GatherStage::LobeLights() {
    const int n = settings_.gatherRays;
    const auto& tris = rays_->Triangles();
    const Surfels& s = inner_->GetSurfels();
    lobeLight_.assign(targets_.size(), glm::vec3(0.0f));
    lightsFresh_ = true;
    if (scene_.lights.empty() || !glossy_) return;
    const float glints = static_cast<float>(GlintCount());
    tbb::parallel_for(tbb::blocked_range<size_t>(0, targets_.size(), 64), [&](const auto& range) {
        for (size_t t = range.begin(); t != range.end(); ++t) {
            const glm::vec3& normal = s.normals[targets_[t]];
            const glm::vec3 x = points_[targets_[t]] + rays_->Epsilon() * normal;
            // The gather rays' glossy hits y: F0 (n + 2)/(2π) cosⁿθ_r · E_l(y) over the lights
            // y sees, weighed against the glints drawing the same point (power heuristic).
            glm::vec3 sum(0.0f);
            const std::vector<LobeHit>& lobes = lobes_[t];
            for (size_t q = 0; q < lobes.size(); ++q) {
                const Hit& h = hits_[t * n + lobes[q].ray];
                const uint32_t tri = h.triangle & kIndex;
                const glm::vec3& ny = tris[tri].normal;
                const glm::vec3 y = HitPoint(h) + rays_->Epsilon() * ny;
                const glm::vec3 d = Direction(t, lobes[q].ray);
                float weight = 1.0f;
                if (!glints_.empty() && !glints_[t].empty()) {
                    const glm::vec3 span = y - x;
                    const float dist2 = glm::dot(span, span), cy = -glm::dot(ny, d);
                    const float cosine = n * glm::dot(normal, d) / kPi;
                    const float area = cy > 0.0f ? glints * GlintDensity(tri) * dist2 / cy : 0.0f;
                    weight = cosine * cosine / (cosine * cosine + area * area);
                }
                sum +=
                    rays_->MaterialOf(tri).specular * LobeLight(q, tri, -d, y, seen_[t]) * weight;
            }
            // The glints the target sees: w_a · L · cosθ_x / (K p_a), p_a the glints' density
            // as a solid angle, L the punctual lights through the glint's lobe.
            glm::vec3 glinted(0.0f);
            for (size_t k = 0; t < glints_.size() && k < glints_[t].size(); ++k) {
                const Glint& g = glints_[t][k];
                if (!g.seen) continue;
                const glm::vec3& ny = tris[g.triangle].normal;
                const glm::vec3 y = HitPoint(Hit{g.triangle, g.u, g.v}) + rays_->Epsilon() * ny;
                const glm::vec3 span = y - x;
                const float dist2 = glm::dot(span, span);
                const glm::vec3 w = span / std::sqrt(dist2);
                const float cx = glm::dot(normal, w), cy = -glm::dot(ny, w);
                if (!(cx > 0.0f && cy > 0.0f && dist2 > 0.0f)) continue;
                const float density = GlintDensity(g.triangle) * dist2 / cy;
                const float area = glints * density, cosine = n * cx / kPi;
                const float weight = area * area / (area * area + cosine * cosine);
                const glm::vec3 light = LobeLight(k, g.triangle, -w, y, glintSeen_[t]);
                glinted += rays_->MaterialOf(g.triangle).specular * light *
                           (weight * cx / (glints * density));
            }
            lobeLight_[t] = sum * (kPi / n) + glinted;
        }
    });
}

}  // namespace penumbra
